"""/best computed in the database: the same near-optimal sets as the engine's, in bounded memory and time."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import text
from sqlalchemy.orm import Session

from bench.bench_best import app_client, build_job, concurrent, peak_growth, timed_get
from finaldrive.engine import aggregate, near_optimal
from finaldrive.service.db.engine import Database
from finaldrive.service.db.levels import add_entries
from finaldrive.service.db.migrate import upgrade
from finaldrive.service.db.summaries import add_explored, aggregate_sharpness, recount_explored, road_sharpness


def _store(url: str, a2: np.ndarray, l2: np.ndarray, rws: np.ndarray, fitness: list[np.ndarray]) -> Database:
    """Job 1 with each design on each road (NaN fitness: a failed evaluation, stored as the writer does)."""
    upgrade(url)
    db = Database(url)
    with db.engine.begin() as conn:
        conn.execute(text("INSERT INTO jobs (id, kind, state, spec, request_hash, total, n_done, n_failed, n_cached, "
                          "completed_at_resume, created_at) VALUES (1, 'robust-de', 'succeeded', '{}', 'x', 0, 0, 0, "
                          "0, 0, '2026-01-01')"))
        conn.execute(text("INSERT INTO evaluations (job_id, road_index, step, candidate, a2_deg, l2_m, rws_m, "
                          "distance_m, fitness_m, status, reason, wall_s, cached, cache_key, cache_hash, transient, "
                          "created_at) "
                          "VALUES (1, :road, 0, :i, :a2, :l2, :rws, :d, :f, :status, '', 0, FALSE, 'k', 0, FALSE, "
                          "'2026-01-01')"),
                     [{"road": road, "i": i, "a2": float(a2[i]), "l2": float(l2[i]), "rws": float(rws[i]),
                       "d": float(f[i]) + 1, "f": float(f[i]), "status": "failed" if np.isnan(f[i]) else "ok"}
                      for road, f in enumerate(fitness) for i in range(len(a2))])
    with Session(db.engine) as session, session.begin():
        recount_explored(session, 1)  # the writer keeps them with each store (test below)
        add_entries(session, 1)
    return db


def _same(got: dict[str, object], expected: dict[str, object]) -> None:
    assert got.keys() == expected.keys()
    for key, value in expected.items():
        if isinstance(value, dict) and key in ("ranges", "explored"):
            assert got[key].keys() == value.keys(), key  # type: ignore[attr-defined]
            for name, pair in value.items():
                assert np.allclose(got[key][name], pair, rtol=0, atol=1e-9, equal_nan=True), (key, name)  # type: ignore[index]
        elif isinstance(value, float):
            assert got[key] == pytest.approx(value, rel=1e-12, nan_ok=True), key
        else:
            assert got[key] == value, key


@pytest.mark.parametrize("angles", ["continuous", "grid", "narrow"])
def test_near_optimal_sets_match_the_engine(store_url: str, angles: str) -> None:
    """Random designs (a2 over a turn, a grid with ties, or a narrow arc across 0), failures, designs on
    the pivot: every tolerance, each road and the robust aggregates, as engine near_optimal says."""
    rng = np.random.default_rng(len(angles))
    n = 2000
    a2 = {"continuous": rng.uniform(-180, 180, n), "grid": np.resize(np.arange(-90.0, 90.0, 10.0), n),
          "narrow": rng.uniform(-20, 15, n)}[angles]
    l2, rws = rng.choice([0.0, 0.05, 0.1, 0.15], n), rng.choice([0.08, 0.09], n)
    fitness = []
    for road in range(2):  # a function of the design (a design evaluated twice has one fitness)
        f = 20 - np.abs(np.sin(np.radians(a2 - 40 * road))) - l2 + 1e-3 * np.sin(1000 * a2 + 77 * l2 + 13 * rws)
        fitness.append(np.where(np.sin(3 * a2 + 5 * l2 + road) > 0.95, np.nan, f))
    db = _store(store_url, a2, l2, rws, fitness)
    designs = np.column_stack([np.radians(a2), l2, rws])
    _, unique = np.unique(np.column_stack([a2, l2, rws]), axis=0, return_index=True)
    with Session(db.engine) as session:
        for pct in (0.1, 2.0, 50.0):
            for road in range(2):
                _same(road_sharpness(session, 1, road, pct),
                      near_optimal(designs, fitness[road], fitness[road] + 1, pct))
            for objective in ("mean", "worst"):
                score = aggregate(np.vstack([f[unique] for f in fitness]), objective)
                _same(aggregate_sharpness(session, 1, 2, objective, pct),
                      near_optimal(designs[unique], score, tolerance_pct=pct))
        assert road_sharpness(session, 1, 7, 0.1) == near_optimal(np.zeros((0, 3)), np.zeros(0))
    db.dispose()


def test_explored_ranges_kept_store_by_store_equal_their_recount(store_url: str) -> None:
    """road_explored merged over several stores (as the writer does) holds exactly what a count of the
    evaluations gives: counts, and a2 bucket edges to the last bit (the same operations as the SQL)."""
    rng = np.random.default_rng(5)
    n = 3000
    a2 = np.concatenate([rng.uniform(-720, 720, n - 6), [0.0, -0.0, -1e-13, -1e-14, 359.9999999999, 1e-300]])
    l2 = np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0, 0.2, n))
    rws, f = rng.uniform(0.05, 0.2, n), 20 - rng.random(n)
    db = _store(store_url, a2, l2, rws, [f, f[::-1].copy()])
    with Session(db.engine) as session:
        recounted = session.execute(text("SELECT * FROM road_explored ORDER BY road_index, bucket")).all()
    with Session(db.engine) as session, session.begin():
        session.execute(text("DELETE FROM road_explored"))
        for part in np.array_split(np.arange(n), 7):
            both = np.r_[part, part]   # both roads in one call, as the writer's batches hold them
            add_explored(session, 1, np.repeat([0, 1], len(part)), a2[both], l2[both], rws[both],
                         np.r_[f[part], f[::-1][part]])
    with Session(db.engine) as session:
        merged = session.execute(text("SELECT * FROM road_explored ORDER BY road_index, bucket")).all()
    assert len(recounted) > 300 and merged == recounted
    assert [str(v) for row in merged for v in row] == [str(v) for row in recounted for v in row]  # -0.0 too
    db.dispose()


def test_best_of_a_large_job_is_bounded(tmp_path: Path) -> None:
    """10^5 evaluations (bench/bench_best.py measures 10^6): one answer < 1 s with < 50 MB more resident
    memory; 10 at once from one client: answered or told to retry (429), memory stays bounded."""
    path = tmp_path / "best.db"
    job = build_job(path, 100_000, 1)
    url = f"/v1/jobs/{job}/best"
    with app_client(path) as client:
        client.get("/v1/health")
        with peak_growth() as growth:
            status, seconds = timed_get(client, url, {})
            assert status == 200 and seconds < 1.0 and growth() < 50
        with peak_growth() as growth:
            answers = concurrent(client, url, {}, 10)
            assert {code for code, _ in answers} <= {200, 429}
            assert growth() < 50
        near = client.get(url).json()["sharpness"][0]
        assert near["evaluated"] == 100_000 and 0 < near["count"] < 1000
