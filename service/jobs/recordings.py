"""The recording producer: one background thread that writes requested .rrd files.

A recording's spec is concrete when stored (the job's best already resolved to a design),
so producing it needs no other table. Files go to ``<data_dir>/recordings/<id>.rrd`` and
only that relative name is stored. Rerun is imported inside the thread, never at import
time, and the process never forks after it (the process executor spawns its workers).
Recordings left queued or running by a stopped service are produced at the next start.
"""

from __future__ import annotations

import logging
import queue
import threading
from pathlib import Path
from typing import Any

from sqlalchemy.engine import make_url

from finaldrive.service.config import Settings
from finaldrive.service.db.engine import Database
from finaldrive.service.db.repository import set_recording, unfinished_recording_ids

log = logging.getLogger(__name__)

RECORDINGS_SUBDIR = "recordings"


def data_dir(settings: Settings) -> Path:
    """``settings.data_dir``, else ``finaldrive-data`` beside the SQLite file, else ./finaldrive-data."""
    if settings.data_dir is not None:
        return Path(settings.data_dir)
    url = make_url(settings.db_url)
    if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
        return Path(url.database).parent / "finaldrive-data"
    return Path("finaldrive-data")


def recording_file(directory: Path, recording_id: int) -> Path:
    return directory / RECORDINGS_SUBDIR / f"{recording_id}.rrd"


def produce(spec: dict[str, Any], path: Path) -> None:
    """Simulate the spec's designs and write the recording to ``path`` (atomically)."""
    from finaldrive.engine import Design, SimSettings, load_vehicle_dict, resolve_roads
    from finaldrive.service.recording import record

    road = resolve_roads(spec["road"])[0].road
    designs = [(d["label"], Design.from_deg(d["a2_deg"], d["l2"], d["rws"])) for d in spec["designs"]]
    base = SimSettings(method=spec["method"], dt=spec["dt"])
    vehicle = load_vehicle_dict(spec["vehicle"]) if spec.get("vehicle") else None
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".part")
    record(tmp, designs, road, duration=spec["duration"], fps=spec["fps"], base=base, vehicle=vehicle,
           recording_id=f"recording-{path.stem}")
    tmp.replace(path)


class RecordingProducer:
    def __init__(self, db: Database, directory: Path) -> None:
        self._db = db
        self._data_dir = directory
        self._queue: queue.Queue[int | None] = queue.Queue()
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()

    def start(self) -> None:
        with self._db.read() as session:
            for recording_id in unfinished_recording_ids(session):
                self._queue.put(recording_id)
        self._thread = threading.Thread(target=self._loop, name="finaldrive-recordings", daemon=True)
        self._thread.start()

    def submit(self, recording_id: int) -> None:
        self._queue.put(recording_id)

    def stop(self, timeout: float = 10.0) -> None:
        """Stop after the recording in progress; queued ones are produced at the next start."""
        self._stopping.set()
        self._queue.put(None)
        if self._thread is not None:
            self._thread.join(timeout)

    def _loop(self) -> None:
        from finaldrive.service.db.models import Recording

        while (recording_id := self._queue.get()) is not None and not self._stopping.is_set():
            with self._db.write() as session:
                row = session.get(Recording, recording_id)
                spec = None if row is None else dict(row.spec)
                if spec is not None:
                    set_recording(session, recording_id, "running")
            if spec is None:
                continue
            path = recording_file(self._data_dir, recording_id)
            try:
                produce(spec, path)
            except Exception as exc:  # a failed simulation or a bug: the recording fails, the service goes on
                log.warning("recording %s failed: %s", recording_id, exc)
                with self._db.write() as session:
                    set_recording(session, recording_id, "failed", error=f"{type(exc).__name__}: {exc}")
                continue
            with self._db.write() as session:
                set_recording(session, recording_id, "succeeded", path=path.name)
