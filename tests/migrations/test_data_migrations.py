"""Migrations that rewrite data: stored rows come out right on SQLite and on a real PostgreSQL.

v0.2.0.b derives the indexed cache hash from each stored key; v0.2.0.c renames the design columns
with their units (a2 converted from radians to degrees) and rewrites stored grid specs and
recording requests in the new names; v0.2.0.e moves each DE generation's record out of its stored
state; v0.3.0.e indexes stored evaluations in the index tables of levels, and v0.3.0.f counts
their levels; from v0.3.0.g states are stored without the population and fitness their rows hold.
Downgrading restores the earlier rows.
"""

from __future__ import annotations

import json
import math
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sqlalchemy as sa
from alembic import command

from finaldrive.engine import parse_grid
from finaldrive.engine.optimize import DifferentialEvolution, plain_json, without_population
from finaldrive.service.db.migrate import alembic_config

KEY = "ab" * 32
A2_RAD = 1.2345


@pytest.fixture(params=["sqlite", "postgresql"])
def url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'm.db'}"
    return str(request.getfixturevalue("postgres").new_database())


def _filler(column: sa.Column[Any]) -> Any:
    """A value for a NOT NULL column the test does not care about."""
    kind = column.type
    if isinstance(kind, sa.Boolean):
        return False
    if isinstance(kind, sa.Integer):
        return 0
    if isinstance(kind, sa.Float):
        return 0.0
    if isinstance(kind, sa.DateTime):
        return datetime(2026, 1, 1)
    if isinstance(kind, sa.JSON):
        return {}
    return "x"


def _insert(conn: sa.Connection, table: str, **values: Any) -> None:
    t = sa.Table(table, sa.MetaData(), autoload_with=conn)
    row = {c.name: _filler(c) for c in t.columns
           if not c.nullable and not c.primary_key and c.server_default is None}
    conn.execute(t.insert().values({**row, **values}))


def _rows(conn: sa.Connection, table: str) -> list[dict[str, Any]]:
    t = sa.Table(table, sa.MetaData(), autoload_with=conn)
    return [dict(r._mapping) for r in conn.execute(sa.select(t))]


def test_cache_hash_and_units_rewrite_stored_rows(url: str) -> None:
    config = alembic_config(url)
    command.upgrade(config, "v0.2.0.a")
    engine = sa.create_engine(url)
    spec = {"kind": "sweep", "roads": ["flat"], "grid": f"a2={A2_RAD}|0.5,l2=0:0.1:0.05,rws=0.09"}
    with engine.begin() as conn:
        _insert(conn, "jobs", id=1, kind="sweep", state="succeeded", spec=spec)
        _insert(conn, "evaluations", job_id=1, a2=A2_RAD, l2=0.05, rws=0.09, cache_key=KEY, status="ok")
        _insert(conn, "recordings", job_id=1, status="succeeded",
                spec={"road": "flat", "designs": [{"a2_deg": 10.0, "l2": 0.05, "rws": 0.09, "label": "a"}]})
    engine.dispose()

    command.upgrade(config, "head")
    engine = sa.create_engine(url)
    with engine.connect() as conn:
        (evaluation,) = _rows(conn, "evaluations")
        (job,) = _rows(conn, "jobs")
        (recording,) = _rows(conn, "recordings")
    engine.dispose()
    assert evaluation["cache_hash"] == int(KEY[:15], 16)  # the key's first 60 bits, the hash of keys then
    assert evaluation["a2_deg"] == pytest.approx(math.degrees(A2_RAD), rel=1e-14)
    assert (evaluation["l2_m"], evaluation["rws_m"]) == (0.05, 0.09)
    assert "a2" not in evaluation and "l2" not in evaluation
    assert job["spec"]["grid"].startswith("a2_deg=")
    old = [[A2_RAD, l2, 0.09] for l2 in (0.0, 0.05, 0.1)] + [[0.5, l2, 0.09] for l2 in (0.0, 0.05, 0.1)]
    np.testing.assert_allclose(parse_grid(job["spec"]["grid"]), old, rtol=1e-14, atol=0)
    assert recording["spec"]["designs"] == [{"a2_deg": 10.0, "l2_m": 0.05, "rws_m": 0.09, "label": "a"}]

    command.downgrade(config, "v0.2.0.a")
    engine = sa.create_engine(url)
    with engine.connect() as conn:
        (evaluation,) = _rows(conn, "evaluations")
        (recording,) = _rows(conn, "recordings")
    engine.dispose()
    assert evaluation["a2"] == pytest.approx(A2_RAD, rel=1e-14)
    assert "cache_hash" not in evaluation
    assert recording["spec"]["designs"][0]["l2"] == 0.05


def _old_states(seed: int, max_iter: int) -> list[dict[str, Any]]:
    """A DE run's state after each tell, as the schema before v0.2.0.e stored it (with its history)."""
    de = DifferentialEvolution([0.0, 0.0], [1.0, 1.0], pop_size=6, max_iter=max_iter, seed=seed)
    states = []
    while not de.done:
        rows = de.ask()
        values = -((rows - 0.3) ** 2).sum(axis=1)
        values[0] = np.nan  # a failed evaluation in every generation: n_failed 1, the mean of the rest
        de.tell(values)
        states.append(json.loads(json.dumps(de.state())))
    return states


def test_generation_records_come_out_of_the_stored_states(url: str) -> None:
    """v0.2.0.e: each old row's state held the whole history; its own record goes to its columns,
    the state keeps the rest, and downgrading puts every state's history back as it was. Two jobs'
    rows interleaved, more of them than the migration reads at a time."""
    runs = {1: _old_states(3, 60), 2: _old_states(4, 60)}
    config = alembic_config(url)
    command.upgrade(config, "v0.2.0.d")
    engine = sa.create_engine(url)
    with engine.begin() as conn:
        for job_id in (1, 2, 3):
            _insert(conn, "jobs", id=job_id, kind="de", state="succeeded", spec={})
        for g in range(1, 62):
            for job_id, states in runs.items():
                state = states[g - 1]
                _insert(conn, "generations", job_id=job_id, run=0, generation=g, state=state,
                        best_fitness_m=state["history"][-1]["best_f"], n_evals=state["n_evals"])
        bare = {k: v for k, v in runs[1][0].items() if k != "history"}  # a state with no history: left as it is
        _insert(conn, "generations", job_id=3, run=0, generation=1, state=bare, best_fitness_m=1.0, n_evals=6)
    engine.dispose()

    def generations() -> dict[int, list[dict[str, Any]]]:
        engine = sa.create_engine(url)
        with engine.connect() as conn:
            rows = sorted(_rows(conn, "generations"), key=lambda r: (r["job_id"], r["generation"]))
        engine.dispose()
        return {job_id: [r for r in rows if r["job_id"] == job_id] for job_id in (1, 2, 3)}

    command.upgrade(config, "head")
    upgraded = generations()
    for job_id, states in runs.items():
        for row, state in zip(upgraded[job_id], states, strict=True):
            record = state["history"][-1]
            assert (row["mean_fitness_m"], row["n_failed"]) == (record["mean_f"], 1)
            assert row["state"] == {k: v for k, v in state.items() if k != "history"}
    ((bare_row),) = upgraded[3]
    assert bare_row["state"] == bare and (bare_row["mean_fitness_m"], bare_row["n_failed"]) == (None, 0)
    resumed = DifferentialEvolution.from_state(upgraded[1][2]["state"])
    assert resumed.history == [] and resumed.generation == 2

    command.downgrade(config, "v0.2.0.d")
    downgraded = generations()
    for job_id, states in runs.items():
        assert [row["state"] for row in downgraded[job_id]] == states
    assert "n_failed" not in downgraded[1][0]


def test_stored_evaluations_are_indexed_at_the_last_level(url: str) -> None:
    """v0.3.0.e: each stored evaluation gets its result-cache entry and each successful one its fitness
    entry, at its last level (3); v0.3.0.f counts each level from 1 on (level 4 now the last);
    downgrading puts level 4's entries back on level 3, then brings the indexes back."""
    config = alembic_config(url)
    command.upgrade(config, "v0.3.0.d")
    engine = sa.create_engine(url)
    stored = [(0, 0, "ok", 19.5), (0, 1, "failed", None), (1, 0, "ok", 18.25), (1, 1, "ok", 19.5)]
    with engine.begin() as conn:
        _insert(conn, "jobs", id=1, kind="sweep", state="succeeded", spec={})
        for road, candidate, status, fitness in stored:
            _insert(conn, "evaluations", job_id=1, road_index=road, step=0, candidate=candidate, status=status,
                    fitness_m=fitness, cache_key=f"{road}{candidate}" * 32, cache_hash=10 * road + candidate)
    engine.dispose()
    command.upgrade(config, "head")
    engine = sa.create_engine(url)
    with engine.connect() as conn:
        cache = sorted(tuple(r.values()) for r in _rows(conn, "cache_index"))
        fitness = sorted(tuple(r.values()) for r in _rows(conn, "fitness_index"))
        indexes = {i["name"] for i in sa.inspect(conn).get_indexes("evaluations")}
        sizes = {(r["index_table"], r["level"]): r["entries"] for r in _rows(conn, "index_levels")}
    assert cache == [(3, 10 * r + c, 1, r, 0, c) for r, c, _, _ in stored]
    assert fitness == sorted((3, 1, r, f, 0, c) for r, c, s, f in stored if s == "ok")
    assert not indexes & {"ix_evaluations_cache_hash", "ix_evaluations_job_road_fitness"}
    assert sizes == {(table, level): {"cache_index": 4, "fitness_index": 3}[table] if level == 3 else 0
                     for table in ("cache_index", "fitness_index") for level in (1, 2, 3, 4)}
    with engine.begin() as conn:  # entries moved on to the new last level
        conn.execute(sa.text("UPDATE cache_index SET level = 4 WHERE cache_hash < 10"))
        conn.execute(sa.text("UPDATE fitness_index SET level = 4 WHERE road_index = 1"))
    command.downgrade(config, "v0.3.0.e")
    with engine.connect() as conn:
        assert sorted(tuple(r.values()) for r in _rows(conn, "cache_index")) == cache
        assert sorted(tuple(r.values()) for r in _rows(conn, "fitness_index")) == fitness
        assert "index_levels" not in sa.inspect(conn).get_table_names()
    command.downgrade(config, "v0.3.0.d")
    with engine.connect() as conn:
        tables = set(sa.inspect(conn).get_table_names())
        indexes = {i["name"] for i in sa.inspect(conn).get_indexes("evaluations")}
    engine.dispose()
    assert not tables & {"cache_index", "fitness_index"}
    assert {"ix_evaluations_cache_hash", "ix_evaluations_job_road_fitness"} <= indexes


def test_a_downgrade_puts_the_population_back_into_the_stored_states(url: str) -> None:
    """v0.3.0.g: a state stored without its population and fitness (the row's columns hold them) is
    whole again after a downgrade, and restores the optimiser exactly; a state stored whole before is
    left as it is, and upgrading rewrites nothing."""
    de = DifferentialEvolution([0.0, 0.0], [1.0, 1.0], pop_size=6, max_iter=5, seed=7)
    for _ in range(2):
        rows = de.ask()
        values = -((rows - 0.3) ** 2).sum(axis=1)
        values[0] = np.nan  # a failed design: its fitness stored as null
        de.tell(values)
    whole = plain_json(de.state(history=False))
    population, fitness = plain_json(de.population), plain_json(de.fitness)
    config = alembic_config(url)
    command.upgrade(config, "head")
    engine = sa.create_engine(url)
    with engine.begin() as conn:
        _insert(conn, "jobs", id=1, kind="de", state="interrupted", spec={})
        _insert(conn, "generations", job_id=1, run=0, generation=2, state=without_population(whole),
                population=population, fitness_m=fitness, best_fitness_m=de.best_f, n_evals=de.n_evals)
        _insert(conn, "generations", job_id=1, run=1, generation=2, state=whole, population=population,
                fitness_m=fitness, best_fitness_m=de.best_f, n_evals=de.n_evals)
    command.downgrade(config, "v0.3.0.f")
    with engine.connect() as conn:
        states = [r["state"] for r in sorted(_rows(conn, "generations"), key=lambda r: r["run"])]
    assert states == [whole, whole] and "population" not in without_population(whole)
    resumed = DifferentialEvolution.from_state(states[0])
    assert np.array_equal(resumed.population, de.population) and np.array_equal(resumed.ask(), de.ask())
    command.upgrade(config, "head")
    with engine.connect() as conn:
        assert [r["state"] for r in sorted(_rows(conn, "generations"), key=lambda r: r["run"])] == states
    engine.dispose()
