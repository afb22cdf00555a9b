"""What each kind of job evaluates, as generators of evaluation requests.

A driver yields :class:`EvalRequest` s; the runner evaluates each one (streaming batches
to ``on_batch``) and then asks the driver for the next. The study's runs
(finaldrive.engine.study) decide what to evaluate; drivers add the store: they resume
from it and write results themselves, all in the runner's thread:

- a sweep run: every (road, grid row) not yet stored, in chunks; each batch is committed as
  it arrives (a paper-study's sweep is stored with ``step = PAPER_SWEEP_STEP``);
- a DE run: each generation on its roads, then the generation's evaluations and the
  optimiser state are committed together; a resumed run continues from its last stored
  generation.

Cache hits (and duplicates within a request) are stored with ``cached=True`` and are
never sent to the executor.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass

import numpy as np

from finaldrive.engine import BatchResult, DERun, Request, Road, SweepRun, fitness_values
from finaldrive.service.db.engine import Database
from finaldrive.service.db.models import EvalStatus, Evaluation
from finaldrive.service.db.repository import (
    EvalRow,
    add_evaluations,
    add_generation,
    cached_evaluations,
    last_generations,
    stored_slots,
)
from finaldrive.service.jobs.cache import context_prefix, design_keys
from finaldrive.service.jobs.plan import JobPlan

Sink = Callable[[list[EvalRow]], None]


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
        return context_prefix(p.study.roads[road_index].road, p.settings, p.vehicle, self.engine_version)


def make_driver(ctx: JobContext) -> Driver:
    """The job's runs, resumed from the store, one after another."""
    study = ctx.plan.study
    with ctx.db.read() as session:
        sweep_done = stored_slots(session, ctx.job_id, step=study.sweep_step) if study.designs is not None else None
        last = last_generations(session, ctx.job_id)
    runs = study.runs(sweep_done=sweep_done, de_states={i: (g.state, g.generation) for i, g in last.items()})
    for run in runs:
        if isinstance(run, SweepRun):
            yield from _sweep(ctx, run)
        else:
            yield from _de(ctx, run)


def _sweep(ctx: JobContext, run: SweepRun) -> Driver:
    def commit(rows: list[EvalRow]) -> None:
        with ctx.db.write() as session:
            add_evaluations(session, ctx.job_id, rows)

    for request in run.take():
        for start in range(0, len(request), ctx.sweep_chunk):
            yield from evaluate_rows(ctx, request.part(np.arange(start, min(len(request), start + ctx.sweep_chunk))),
                                     commit)


def _de(ctx: JobContext, run: DERun) -> Driver:
    while not run.done:
        rows: list[EvalRow] = []
        requests = run.take()
        for request in requests:
            yield from evaluate_rows(ctx, request, rows.extend)
        for request in requests:
            fitness = np.full(len(request), np.nan)
            position = {int(c): i for i, c in enumerate(request.candidates)}
            for row in rows:
                if row.road_index == request.road and row.fitness_m is not None:
                    fitness[position[row.candidate]] = row.fitness_m
            run.tell(request.road, request.step, request.candidates, fitness)
        de = run.de
        with ctx.db.write() as session:
            add_evaluations(session, ctx.job_id, rows)
            add_generation(
                session, ctx.job_id, run=run.index, generation=run.generation, state=de.state(),
                population=de.population.tolist(), fitness=_nullable(de.fitness),
                best_f=_nullable([de.best_f])[0], n_evals=de.n_evals,
            )


def evaluate_rows(ctx: JobContext, request: Request, sink: Sink) -> Driver:
    """Store cache hits at once; request the rest (once per distinct design) and store them."""
    road_index, step, candidates, designs = request.road, request.step, request.candidates, request.designs
    prefix = ctx.prefix(road_index)
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
        fitness = fitness_values(batch)
        out: list[EvalRow] = []
        for j, pos in enumerate(np.asarray(rows, dtype=int)):
            i = int(todo[pos])
            for n, target in enumerate([i, *copies.get(keys[i], [])]):
                out.append(_row_from_result(
                    batch, fitness, j, road_index, step, int(candidates[target]), designs[target], keys[i], n > 0
                ))
        sink(out)

    yield EvalRequest(ctx.plan.study.roads[road_index].road, designs[todo], on_batch)


def _row_from_result(
    batch: BatchResult, fitness_values: np.ndarray, j: int, road_index: int, step: int, candidate: int,
    design: np.ndarray, key: str, cached: bool,
) -> EvalRow:
    fitness = float(fitness_values[j])
    ok = math.isfinite(fitness)
    reason = batch.reason[j]
    if not ok and not reason:
        reason = f"non-finite fitness ({batch.fitness_m[j]})"
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
