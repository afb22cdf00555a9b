"""The recording producer: a thread of a scheduler process that makes requested .rrd files.

A recording's spec is concrete when stored (the job's best resolved to a design, a measured
road to its points), so producing it needs no other table. The finished file is stored in the database with the
recording (about 1 MB for two geometries over 3.5 s), so a scheduler on any machine can produce
it and the API serves it from the store. Rerun is imported inside the thread, never at import
time, and the process never forks after it (the process executor spawns its workers).
"""

from __future__ import annotations

import logging
import tempfile
import threading
from pathlib import Path
from typing import Any

from sqlalchemy.exc import SQLAlchemyError

from finaldrive.service.db.engine import Database
from finaldrive.service.db.leases import claim_recording
from finaldrive.service.db.repository import finish_recording

log = logging.getLogger(__name__)


def produce(spec: dict[str, Any], path: Path) -> None:
    """Simulate the spec's designs and write the recording to ``path``."""
    from finaldrive.engine import Design, Road, SimSettings, load_vehicle_dict, resolve_roads
    from finaldrive.service.media.recording import record

    if spec.get("profile"):  # a measured road: its points are in the spec
        xs, ys = spec["profile"]
        road = Road.from_points(xs, ys, name=spec["road"].split(":", 1)[1].strip())
    else:
        road = resolve_roads(spec["road"])[0].road
    designs = [(d["label"], Design.from_deg(d["a2_deg"], d["l2_m"], d["rws_m"])) for d in spec["designs"]]
    base = SimSettings(method=spec["method"], dt=spec["dt"])
    vehicle = load_vehicle_dict(spec["vehicle"]) if spec.get("vehicle") else None
    record(path, designs, road, duration=spec["duration"], fps=spec["fps"], base=base, vehicle=vehicle,
           recording_id=f"recording-{path.stem}")


class RecordingProducer:
    """Produces queued recordings in a thread of the scheduler process, one at a time.

    A recording is claimed under a lease like a job (a producer that dies leaves it to another
    scheduler once the lease lapses); the scheduler's heartbeat renews it while it is produced.
    """

    def __init__(self, db: Database, owner: str, *, lease_s: float, poll_s: float = 0.5) -> None:
        self._db = db
        self._owner = owner
        self._lease_s = lease_s
        self._poll_s = poll_s
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._loop, name="finaldrive-recordings", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 10.0) -> None:
        """Stop after the recording in progress; the others stay queued for the next start."""
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def _loop(self) -> None:
        while not self._stopping.is_set():
            try:
                with self._db.write() as session:
                    row = claim_recording(session, self._owner, lease_s=self._lease_s)
                    claimed = None if row is None else (row.id, dict(row.spec))
            except SQLAlchemyError as exc:
                log.warning("recordings: the store is unavailable: %s", " ".join(str(exc).split())[:300])
                claimed = None
            if claimed is None:
                self._stopping.wait(self._poll_s)
                continue
            self._produce(*claimed)

    def _produce(self, recording_id: int, spec: dict[str, Any]) -> None:
        with tempfile.TemporaryDirectory(prefix="finaldrive-recording-") as tmp:
            path = Path(tmp) / f"{recording_id}.rrd"
            try:
                produce(spec, path)
                outcome: dict[str, Any] = {"status": "succeeded", "content": path.read_bytes()}
            except Exception as exc:  # a failed simulation or a bug: this recording fails, the producer goes on
                log.warning("recording %s failed: %s", recording_id, exc)
                outcome = {"status": "failed", "error": f"{type(exc).__name__}: {exc}"}
        while not self._stopping.is_set():
            try:
                with self._db.write() as session:
                    finish_recording(session, recording_id, self._owner, **outcome)
                return
            except SQLAlchemyError:
                self._stopping.wait(1.0)  # the store is unavailable: the file waits, retry
