"""GET /v1/jobs/{id} from the job's snapshot: no SQL a request, fresh within the hub's tick, cancel
visible at once, behind the access control; the access log without query strings."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import event

from finaldrive.service import status_cache
from finaldrive.service.api.lookups import load_job
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from finaldrive.service.schemas import JobOut
from finaldrive.service.services import Services
from finaldrive.service.status_cache import Snapshot, StatusCache
from tests.service.processes import Server
from tests.service.svc_helpers import SWEEP, ToyTask, running_scheduler

#: How long after the store changed a GET may still show the old state: the hub's tick (0.1 s here),
#: its read and the rebuild, with room for a busy 2-core machine.
LAG_S = 1.5


def snapshot_settings(tmp_path: Path, **update: Any) -> Settings:
    values = {"events_poll_seconds": 0.1, "status_cache_seconds": 0.25, **update}
    return Settings(db_url=f"sqlite:///{tmp_path / 's.db'}", executor="serial", allowed_hosts=["testserver"],
                    **values)


def services_of(client: TestClient) -> Services:
    services: Services = client.app.state.services  # type: ignore[attr-defined]
    return services


def store_state(client: TestClient, job_id: int) -> JobOut:
    """The job as the store has it now (the route's model, built without the snapshot)."""
    return load_job(services_of(client), job_id)


def wait_for(predicate: Callable[[], bool], timeout: float = 20.0) -> float:
    """Poll until ``predicate()``; the time it became true."""
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.005)
    return time.monotonic()


@pytest.fixture
def statements(tmp_path: Path) -> Iterator[tuple[TestClient, list[str]]]:
    """A service whose hub ticks once a minute (only its first tick falls in a test), and the SQL
    statements its store executes from the moment the list is cleared."""
    with TestClient(create_app(snapshot_settings(tmp_path, events_poll_seconds=60))) as client:
        executed: list[str] = []
        event.listen(services_of(client).db.engine, "before_cursor_execute",
                     lambda _conn, _cursor, sql, *_: executed.append(sql))
        yield client, executed


def test_a_polled_status_executes_no_sql(statements: tuple[TestClient, list[str]]) -> None:
    client, executed = statements
    job_id = client.post("/v1/jobs", json=SWEEP).json()["id"]
    first = client.get(f"/v1/jobs/{job_id}")
    assert first.status_code == 200 and first.headers["content-type"] == "application/json"
    assert JobOut.model_validate_json(first.content) == store_state(client, job_id)
    wait_for(lambda: client.app.state.events.reads >= 1)  # type: ignore[attr-defined]  # its first tick
    time.sleep(0.2)
    executed.clear()
    bodies = {client.get(f"/v1/jobs/{job_id}").content for _ in range(300)}
    assert executed == [] and bodies == {first.content}
    assert client.get("/v1/jobs/99").status_code == client.get("/v1/jobs/99").status_code == 404


def test_cancel_is_visible_at_once(statements: tuple[TestClient, list[str]]) -> None:
    client, _ = statements
    job_id = client.post("/v1/jobs", json=SWEEP).json()["id"]
    assert client.get(f"/v1/jobs/{job_id}").json()["state"] == "queued"
    assert client.post(f"/v1/jobs/{job_id}/cancel").json()["state"] == "cancelled"
    after = client.get(f"/v1/jobs/{job_id}")  # the hub sleeps for a minute: only the invalidation helps
    assert after.json()["state"] == "cancelled"
    assert JobOut.model_validate_json(after.content) == store_state(client, job_id)


def test_progress_is_visible_within_the_hubs_tick(tmp_path: Path) -> None:
    settings = snapshot_settings(tmp_path)
    fake = ToyTask(delay=0.01)
    fake.gate.clear()
    with TestClient(create_app(settings)) as client, running_scheduler(settings, fake):
        job_id = client.post("/v1/jobs", json=SWEEP).json()["id"]
        path = f"/v1/jobs/{job_id}"
        assert client.get(path).json()["state"] in ("queued", "running")  # the snapshot is made

        running = wait_for(lambda: store_state(client, job_id).state == "running")
        assert wait_for(lambda: client.get(path).json()["state"] == "running") - running < LAG_S

        fake.gate.set()
        progress = wait_for(lambda: store_state(client, job_id).done > 0)
        assert wait_for(lambda: client.get(path).json()["done"] > 0) - progress < LAG_S

        end = wait_for(lambda: store_state(client, job_id).state == "succeeded")
        assert wait_for(lambda: client.get(path).json()["state"] == "succeeded") - end < LAG_S
        final = client.get(path)
        assert JobOut.model_validate_json(final.content) == store_state(client, job_id)
        assert final.json()["done"] == final.json()["total"] == 24


def test_the_snapshot_is_served_behind_the_access_control(tmp_path: Path) -> None:
    with TestClient(create_app(snapshot_settings(tmp_path, api_token="s3cret"))) as client:
        signed = {"Authorization": "Bearer s3cret"}
        job_id = client.post("/v1/jobs", json=SWEEP, headers=signed).json()["id"]
        assert client.get(f"/v1/jobs/{job_id}", headers=signed).status_code == 200  # the snapshot is made
        assert services_of(client).status_cache.get(job_id) is not None
        assert client.get(f"/v1/jobs/{job_id}").status_code == 401
        assert client.get(f"/v1/jobs/{job_id}", headers={"Authorization": "Bearer wrong"}).status_code == 401
        assert client.get(f"/v1/jobs/{job_id}", headers={**signed, "Host": "evil.example"}).status_code == 400


def test_loads_share_a_build_and_an_invalidation_discards_an_older_one() -> None:
    async def scenario() -> None:
        cache = StatusCache(max_age=1.0)
        started, release = threading.Event(), threading.Event()
        builds: list[bytes] = []

        def old_build() -> Snapshot:
            builds.append(b"old")
            started.set()
            release.wait(10)
            return Snapshot(b"old", version=1, final=False)

        waiting = [asyncio.create_task(cache.load(1, old_build)) for _ in range(20)]
        await anyio.to_thread.run_sync(started.wait)
        cache.invalidate(1)  # a cancel committed while the build read the store
        fresh = await cache.load(1, lambda: Snapshot(b"new", version=2, final=False))
        release.set()
        assert {getattr(await task, "body", None) for task in waiting} == {b"old"}  # asked before the cancel
        assert builds == [b"old"] and fresh is not None and cache.get(1) == b"new"

    asyncio.run(scenario())


def test_snapshots_unconfirmed_idle_or_over_the_cap_are_not_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    cache = StatusCache(max_age=1.0)
    cache.store({1: Snapshot(b"running", version=1, final=False), 2: Snapshot(b"done", version=2, final=True)}, 0)
    assert cache.watched() == [1] and cache.outdated({1: 1}, running=()) == []
    cache._entries[1].checked -= status_cache.STALE_S + 1  # the hub has not confirmed it (store down)
    cache._entries[2].checked -= status_cache.STALE_S + 1
    assert cache.get(1) is None and cache.get(2) == b"done"  # a finished job's body is final
    assert cache.outdated({1: 3}, running=()) == [1]  # the job changed: rebuilt at this tick
    cache._entries[1].read -= status_cache.IDLE_S + 1
    assert cache.watched() == [] and cache.get(1) is None  # nobody reads it: dropped
    monkeypatch.setattr(status_cache, "MAX_ENTRIES", 10)
    cache.store({i: Snapshot(b"x", version=i, final=True) for i in range(10, 25)}, 0)
    assert len(cache._entries) <= 10
    off = StatusCache(max_age=0)  # FINALDRIVE_STATUS_CACHE_SECONDS=0: every GET reads the store
    off.store({1: Snapshot(b"x", version=1, final=True)}, 0)
    assert off.get(1) is None


def test_the_access_log_has_no_query_strings(tmp_path: Path) -> None:
    """``finaldrive serve``'s access log shows the path of a request with ``?token=``, never the token."""
    log = tmp_path / "server.log"
    server = Server(f"sqlite:///{tmp_path / 'log.db'}", log, "--no-scheduler",
                    env={"FINALDRIVE_API_TOKEN": "s3cret-token"}).start()
    try:
        anonymous = {"Authorization": ""}
        assert server.client.get("/v1/health?token=s3cret-token&x=1", headers=anonymous).status_code == 401
        assert server.client.get("/v1/jobs?token=s3cret-token").status_code == 200
        assert server.client.get("/v1/jobs/7?token=s3cret-token").status_code == 404
        wait_for(lambda: '"GET /v1/jobs/7 HTTP/1.1" 404' in log.read_text(), timeout=10)
    finally:
        server.terminate()
    text = log.read_text()
    assert '"GET /v1/health HTTP/1.1" 401' in text and '"GET /v1/jobs HTTP/1.1" 200' in text
    assert "s3cret" not in text and "token=" not in text
