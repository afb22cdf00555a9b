"""What each kind of job evaluates, as generators of evaluation requests.

A driver yields :class:`EvalRequest` s; the runner evaluates each one (streaming batches
to ``on_batch``) and then asks the driver for the next. Drivers read the store to resume
and write results themselves, all in the runner's thread:

- sweep: every (road, grid row) not yet stored, in chunks; each batch is committed as it
  arrives.
- de / robust-de: ask -> evaluate (robust: on every road, scored by ``aggregate``) ->
  tell; the generation's evaluations and the optimiser state are committed together, and
  a resumed run continues from its last stored generation.
- paper-study: the sweep (stored with ``step = SWEEP_STEP``, so its slots never meet the
  DE's generations) on every road, then the DE on each road; one job, one progress count.

Cache hits (and duplicates within a request) are stored with ``cached=True`` and are
never sent to the executor.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass

import numpy as np

from engine.api import STATUS_OK, BatchResult
from engine.model.road import Road
from engine.optimize.de import DifferentialEvolution
from engine.study.robust import aggregate
from service.db.engine import Database
from service.db.models import EvalStatus, Evaluation
from service.db.repository import (
    EvalRow,
    add_evaluations,
    add_generation,
    cached_evaluations,
    last_generations,
    stored_slots,
)
from service.jobs.cache import context_prefix, design_keys
from service.jobs.plan import JobPlan

Sink = Callable[[list[EvalRow]], None]

#: ``step`` of a paper-study's sweep evaluations (DE generations are 0, 1, ...).
SWEEP_STEP = -1


@dataclass(frozen=True)
class EvalRequest:
    """Designs to simulate on one road; results go to ``on_batch(rows, batch)``."""

    road: Road
    designs: np.ndarray
    on_batch: Callable[[np.ndarray, BatchResult], None]


Driver = Generator[EvalRequest, None, None]


@dataclass(frozen=True)
class JobContext:
    job_id: int
    plan: JobPlan
    db: Database
    engine_version: str
    sweep_chunk: int

    def prefix(self, road_index: int) -> str:
        p = self.plan
        return context_prefix(p.roads[road_index].road, p.settings, p.vehicle, self.engine_version)


def make_driver(ctx: JobContext) -> Driver:
    if ctx.plan.kind == "sweep":
        return sweep_driver(ctx)
    if ctx.plan.kind == "paper-study":
        return paper_study_driver(ctx)
    return de_driver(ctx)


def paper_study_driver(ctx: JobContext) -> Driver:
    yield from sweep_driver(ctx, step=SWEEP_STEP)
    yield from de_driver(ctx)


def sweep_driver(ctx: JobContext, step: int = 0) -> Driver:
    designs = ctx.plan.designs
    assert designs is not None
    with ctx.db.read() as session:
        done = stored_slots(session, ctx.job_id, step=step)

    def commit(rows: list[EvalRow]) -> None:
        with ctx.db.write() as session:
            add_evaluations(session, ctx.job_id, rows)

    for r in range(len(ctx.plan.roads)):
        prefix = ctx.prefix(r)
        missing = np.array([c for c in range(len(designs)) if (r, c) not in done], dtype=int)
        for start in range(0, len(missing), ctx.sweep_chunk):
            candidates = missing[start:start + ctx.sweep_chunk]
            yield from evaluate_rows(ctx, r, step, candidates, designs[candidates], prefix, commit)


def de_driver(ctx: JobContext) -> Driver:
    plan = ctx.plan
    with ctx.db.read() as session:
        last = last_generations(session, ctx.job_id)
    for run in range(plan.n_runs):
        stored = last.get(run)
        if stored is not None:
            de, generation = DifferentialEvolution.from_state(stored.state), stored.generation
        else:
            de, generation = plan.new_optimiser(run), 0
        road_indices = list(range(len(plan.roads))) if plan.kind == "robust-de" else [run]
        prefixes = {r: ctx.prefix(r) for r in road_indices}
        while not de.done:
            x = de.ask()
            rows: list[EvalRow] = []
            for r in road_indices:
                yield from evaluate_rows(ctx, r, generation, np.arange(len(x)), x, prefixes[r], rows.extend)
            table = np.full((len(road_indices), len(x)), np.nan)
            position = {r: i for i, r in enumerate(road_indices)}
            for row in rows:
                if row.fitness_m is not None:
                    table[position[row.road_index], row.candidate] = row.fitness_m
            de.tell(aggregate(table, plan.aggregate) if plan.kind == "robust-de" else table[0])
            generation += 1
            with ctx.db.write() as session:
                add_evaluations(session, ctx.job_id, rows)
                add_generation(
                    session, ctx.job_id, run=run, generation=generation, state=de.state(),
                    population=de.population.tolist(), fitness=_nullable(de.fitness),
                    best_f=_nullable([de.best_f])[0], n_evals=de.n_evals,
                )


def evaluate_rows(
    ctx: JobContext, road_index: int, step: int, candidates: np.ndarray, designs: np.ndarray,
    prefix: str, sink: Sink,
) -> Driver:
    """Store cache hits at once; request the rest (once per distinct design) and store them."""
    keys = design_keys(prefix, designs)
    with ctx.db.read() as session:
        hits = cached_evaluations(session, keys)
    from_cache = [
        _row_from_cache(hits[k], road_index, step, int(c), designs[i], k)
        for i, (c, k) in enumerate(zip(candidates, keys, strict=True)) if k in hits
    ]
    if from_cache:
        sink(from_cache)
    first: dict[str, int] = {}
    copies: dict[str, list[int]] = {}
    for i, k in enumerate(keys):
        if k in hits:
            continue
        if k in first:
            copies.setdefault(k, []).append(i)
        else:
            first[k] = i
    if not first:
        return
    todo = np.fromiter(first.values(), dtype=int)

    def on_batch(rows: np.ndarray, batch: BatchResult) -> None:
        out: list[EvalRow] = []
        for j, pos in enumerate(np.asarray(rows, dtype=int)):
            i = int(todo[pos])
            for n, target in enumerate([i, *copies.get(keys[i], [])]):
                out.append(_row_from_result(
                    batch, j, road_index, step, int(candidates[target]), designs[target], keys[i], n > 0
                ))
        sink(out)

    yield EvalRequest(ctx.plan.roads[road_index].road, designs[todo], on_batch)


def _row_from_result(
    batch: BatchResult, j: int, road_index: int, step: int, candidate: int,
    design: np.ndarray, key: str, cached: bool,
) -> EvalRow:
    fitness = float(batch.fitness_m[j])
    status, reason = batch.status[j], batch.reason[j]
    if status == STATUS_OK and not math.isfinite(fitness):
        status, reason = EvalStatus.failed.value, f"non-finite fitness ({fitness})"
    ok = status == STATUS_OK
    return EvalRow(
        road_index=road_index, step=step, candidate=candidate,
        a2=float(design[0]), l2=float(design[1]), rws=float(design[2]),
        distance_m=_finite(batch.distance_m[j]), squat_ratio=_finite(batch.squat_ratio[j]),
        slack_m=_finite(batch.slack_m[j]), fitness_m=fitness if ok else None,
        chain_length_m=_finite(batch.chain_length_m[j]),
        status=EvalStatus.ok.value if ok else EvalStatus.failed.value,
        reason=reason, wall_s=0.0 if cached else float(batch.wall_s[j]), cached=cached, cache_key=key,
    )


def _row_from_cache(
    hit: Evaluation, road_index: int, step: int, candidate: int, design: np.ndarray, key: str
) -> EvalRow:
    return EvalRow(
        road_index=road_index, step=step, candidate=candidate,
        a2=float(design[0]), l2=float(design[1]), rws=float(design[2]),
        distance_m=hit.distance_m, squat_ratio=hit.squat_ratio, slack_m=hit.slack_m,
        fitness_m=hit.fitness_m, chain_length_m=hit.chain_length_m, status=hit.status,
        reason=hit.reason, wall_s=0.0, cached=True, cache_key=key,
    )


def _finite(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _nullable(values: Sequence[float] | np.ndarray) -> list[float | None]:
    return [float(v) if math.isfinite(v) else None for v in values]
