"""Event streams: one shared store read a tick, caps per client and in total, subscribers removed on disconnect."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from finaldrive.service.api.event_hub import EventHub
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from tests.service.asgi_stream import AsgiStream
from tests.service.svc_helpers import SWEEP, ToyTask, running_scheduler, wait_done


def hub(client: TestClient) -> EventHub:
    events: EventHub = client.app.state.events  # type: ignore[attr-defined]
    return events


def wait_until(predicate: object, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():  # type: ignore[operator]
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


@pytest.fixture
def slow_job(settings: Settings) -> Iterator[tuple[TestClient, ToyTask, int]]:
    """A service whose job 1 waits at the gate (running, no progress) until the test opens it."""
    fake = ToyTask(delay=0.01)
    fake.gate.clear()
    capped = settings.model_copy(update={"max_streams_per_client": 4, "max_streams": 6})
    with TestClient(create_app(capped)) as c, running_scheduler(capped, fake):
        job_id = c.post("/v1/jobs", json=SWEEP).json()["id"]
        wait_until(lambda: c.get(f"/v1/jobs/{job_id}").json()["state"] == "running")
        yield c, fake, job_id
        fake.gate.set()


def events(text: str, name: str) -> list[object]:
    """The data of every ``name`` event in a stream's text."""
    blocks = [b for b in text.split("\n\n") if f"event: {name}" in b]
    return [json.loads(line[len("data: "):]) for b in blocks for line in b.splitlines() if line.startswith("data: ")]


def test_streams_share_one_store_read_a_tick(slow_job: tuple[TestClient, ToyTask, int]) -> None:
    client, fake, job_id = slow_job
    streams = [AsgiStream(client, f"/v1/jobs/{job_id}/events", client_host=f"10.0.0.{i}") for i in range(5)]
    streams.append(AsgiStream(client, "/v1/events", client_host="10.0.0.9"))
    assert all(s.started() == 200 for s in streams)
    wait_until(lambda: hub(client).streams == 6)
    events_hub = hub(client)
    ticks_before, reads_before = time.monotonic(), events_hub.reads
    time.sleep(0.5)
    reads = events_hub.reads - reads_before
    ticks = (time.monotonic() - ticks_before) / events_hub.poll_s
    assert 1 <= reads <= ticks + 1, (reads, ticks)  # one read a tick for the six streams, not six
    fake.gate.set()
    for s in streams[:5]:
        s.wait_for("event: end")
    jobs = streams[5].wait_for('"succeeded"')
    first, *_ = events(jobs, "jobs")
    assert first == [{"id": job_id, "kind": "sweep", "state": "running", "done": 0, "failed": 0, "total": 24,
                      "progress": 0.0}]
    assert events(jobs, "jobs")[-1][0]["progress"] == 1.0  # type: ignore[index]
    for s in streams:
        s.close()
    assert hub(client).streams == 0


def test_a_job_stream_sends_progress_then_end(slow_job: tuple[TestClient, ToyTask, int]) -> None:
    client, fake, job_id = slow_job
    stream = AsgiStream(client, f"/v1/jobs/{job_id}/events")
    assert stream.started() == 200 and stream.headers["content-type"].startswith("text/event-stream")
    fake.gate.set()
    text = stream.wait_for("event: end")
    progress = events(text, "progress")
    assert progress[0] == {"state": "running", "done": 0, "failed": 0, "total": 24}
    assert progress[-1] == events(text, "end")[0] == {"state": "succeeded", "done": 24, "failed": 0, "total": 24}
    stream.close()
    assert hub(client).streams == 0
    assert client.get("/v1/jobs/99/events").status_code == 404


def test_stream_caps_answer_429_and_disconnects_free_them(slow_job: tuple[TestClient, ToyTask, int]) -> None:
    client, _, job_id = slow_job
    mine = [AsgiStream(client, "/v1/events") for _ in range(4)]
    assert [s.started() for s in mine] == [200] * 4
    refused = AsgiStream(client, f"/v1/jobs/{job_id}/events")
    assert refused.started() == 429 and refused.headers["retry-after"] == "5"
    assert refused.ended.wait(5) and json.loads(refused.text)["type"] == "urn:finaldrive:problem:too-many-streams"
    others = [AsgiStream(client, "/v1/events", client_host="10.1.1.1") for _ in range(2)]
    assert [s.started() for s in others] == [200, 200]
    total = AsgiStream(client, "/v1/events", client_host="10.2.2.2")
    assert total.started() == 429 and total.ended.wait(5) and "FINALDRIVE_MAX_STREAMS " in total.text
    assert hub(client).streams == 6
    for s in [*mine, *others]:
        s.close()
    assert hub(client).streams == 0
    again = AsgiStream(client, "/v1/events")
    assert again.started() == 200
    again.close()
    assert hub(client).streams == 0


def test_a_finished_job_streams_its_end_at_once(client: TestClient) -> None:
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    body = client.get(f"/v1/jobs/{job['id']}/events").text
    assert events(body, "progress") == events(body, "end") == [
        {"state": "succeeded", "done": 24, "failed": 0, "total": 24}]
    assert hub(client).streams == 0
