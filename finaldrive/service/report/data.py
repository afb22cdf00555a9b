"""A stored paper-study, read from the database or from a running service, as plain arrays.

Both sources give the same :class:`StudyData` (evaluations sorted by their slot
``(road, step, candidate)``, times as naive UTC), so a report does not depend on where it
was read from, nor on the order in which a resumed study stored its rows.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import httpx

#: Evaluation columns kept for the report (float arrays; ``ok`` and ``cached`` as bool).
COLUMNS = ("road_index", "step", "candidate", "a2_deg", "l2_m", "rws_m", "distance_m", "squat_ratio",
           "slack_m", "fitness_m", "wall_s")


class StudyNotFound(LookupError):
    """No such job, or not a paper-study."""


@dataclass(frozen=True)
class StudyData:
    """One paper-study job: its record, roads and evaluations."""

    job_id: int
    state: str
    spec: dict[str, Any]
    total: int
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    roads: list[tuple[str, str]]            # (name, spec) in road-index order
    evals: dict[str, np.ndarray]           # COLUMNS + "ok", "cached", "a2" (a2_deg in rad)

    @property
    def wall_s(self) -> float | None:
        if self.started_at is None or self.finished_at is None:
            return None
        return (self.finished_at - self.started_at).total_seconds()


def _arrays(rows: list[tuple[Any, ...]]) -> dict[str, np.ndarray]:
    """Rows of COLUMNS + (status, cached), sorted by slot, as arrays (None -> NaN)."""
    rows = sorted(rows, key=lambda r: (r[0], r[1], r[2]))
    n_num = len(COLUMNS)
    out = {
        name: np.array([np.nan if r[i] is None else r[i] for r in rows], dtype=float).reshape(-1)
        for i, name in enumerate(COLUMNS)
    }
    for name in ("road_index", "step", "candidate"):
        out[name] = out[name].astype(int)
    out["a2"] = np.radians(out["a2_deg"])  # designs as the engine takes them
    out["ok"] = np.array([r[n_num] == "ok" for r in rows], dtype=bool)
    out["cached"] = np.array([bool(r[n_num + 1]) for r in rows], dtype=bool)
    return out


def _check_kind(job_id: int, kind: str) -> None:
    if kind != "paper-study":
        raise StudyNotFound(f"job {job_id} is a {kind!r} job, not a paper-study")


def from_database(url: str, job_id: int) -> StudyData:
    """Read a study from the results store at ``url`` (read only)."""
    from sqlalchemy import select
    from sqlalchemy.exc import OperationalError

    from finaldrive.service.db.engine import Database
    from finaldrive.service.db.models import Evaluation, Job, JobRoad

    if url.startswith("sqlite:///") and not Path(url.removeprefix("sqlite:///")).is_file():
        raise StudyNotFound(f"no database file at {url}")
    db = Database(url)
    try:
        with db.read() as session:
            job = session.get(Job, job_id)
            if job is None:
                raise StudyNotFound(f"job {job_id} does not exist in {url}")
            _check_kind(job_id, job.kind)
            roads = session.execute(
                select(JobRoad.name, JobRoad.spec).where(JobRoad.job_id == job_id).order_by(JobRoad.road_index)
            ).all()
            cols = [getattr(Evaluation, c) for c in COLUMNS] + [Evaluation.status, Evaluation.cached]
            rows = session.execute(select(*cols).where(Evaluation.job_id == job_id)).all()
            return StudyData(
                job_id=job.id, state=job.state, spec=dict(job.spec), total=job.total,
                created_at=job.created_at, started_at=job.started_at, finished_at=job.finished_at,
                roads=[(n, s) for n, s in roads], evals=_arrays([tuple(r) for r in rows]),
            )
    except OperationalError as exc:
        raise StudyNotFound(f"cannot read the study from {url}: {exc.orig}") from None
    finally:
        db.dispose()


def from_server(base_url: str, job_id: int, *, client: httpx.Client | None = None) -> StudyData:
    """Read a study through the REST API of a running service (or through ``client``)."""
    import httpx

    from finaldrive.service.client import auth_headers

    own = client is None
    client = client or httpx.Client(base_url=base_url.rstrip("/"), timeout=60.0, headers=auth_headers())
    try:
        response = client.get(f"/v1/jobs/{job_id}")
        if response.status_code == 404:
            raise StudyNotFound(f"job {job_id} does not exist on {base_url}")
        response.raise_for_status()
        job = response.json()
        _check_kind(job_id, job["kind"])
        rows: list[tuple[Any, ...]] = []
        cursor: str | None = None
        while True:
            params: dict[str, Any] = {"limit": 10_000, **({"cursor": cursor} if cursor else {})}
            page = client.get(f"/v1/jobs/{job_id}/evaluations", params=params)
            page.raise_for_status()
            body = page.json()
            rows.extend((*tuple(e[c] for c in COLUMNS), e["status"], e["cached"]) for e in body["items"])
            cursor = body["next_cursor"]
            if cursor is None:
                break
    finally:
        if own:
            client.close()
    return StudyData(
        job_id=job["id"], state=job["state"], spec=job["spec"], total=job["total"],
        created_at=_naive(job["created_at"]) or datetime.min, started_at=_naive(job["started_at"]),
        finished_at=_naive(job["finished_at"]),
        roads=[(r["name"], r["spec"]) for r in sorted(job["roads"], key=lambda r: r["index"])],
        evals=_arrays(rows),
    )


def _naive(text: str | None) -> datetime | None:
    """An ISO time from the API as naive UTC (what the store holds)."""
    if text is None:
        return None
    t = datetime.fromisoformat(text.replace("Z", "+00:00"))
    return t.astimezone(UTC).replace(tzinfo=None) if t.tzinfo else t
