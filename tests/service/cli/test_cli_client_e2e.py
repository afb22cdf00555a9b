"""End to end: a real uvicorn process (serial executor, tmp SQLite, a token), driven by the CLI client."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from finaldrive.service.cli import main
from finaldrive.service.cli.common import stop_process
from finaldrive.service.cli.remote import EXIT_HTTP, EXIT_JOB_NOT_SUCCEEDED, EXIT_UNREACHABLE
from finaldrive.service.machine import free_port
from finaldrive.service.media.recording import frame_count
from tests.service.processes import console_script

pytestmark = pytest.mark.slow  # starts servers or subprocesses

TOKEN = "e2e-secret"


@pytest.fixture
def server(tmp_path: Path) -> Iterator[str]:
    port = free_port()
    env = {**os.environ, "FINALDRIVE_API_TOKEN": TOKEN, "FINALDRIVE_DATA_DIR": str(tmp_path / "data")}
    cmd = [sys.executable, "-m", "finaldrive.service.cli", "serve", "--port", str(port), "--db",
           f"sqlite:///{tmp_path / 'e2e.db'}", "--executor", "serial"]
    log = (tmp_path / "server.log").open("wb")
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            assert proc.poll() is None, (tmp_path / "server.log").read_text()
            try:
                if httpx.get(f"{url}/v1/health", headers={"Authorization": f"Bearer {TOKEN}"}).status_code == 200:
                    break
            except httpx.TransportError:
                assert time.monotonic() < deadline, "server did not start"
                time.sleep(0.1)
        yield url
    finally:
        stop_process(proc, 15)
        log.close()


def test_submit_follow_results_record_plot(server: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("FINALDRIVE_API_TOKEN", TOKEN)
    s = ["--server", server]
    assert main(["submit", "sweep", "--road", "sine:0.04:3", "--grid", "a2_deg=0:270:90,l2_m=0.02|0.15,rws_m=0.093",
                 "--duration", "0.5", "--follow", *s]) == 0
    out = capsys.readouterr()
    assert "job 1: sweep on 1 road(s), 8 evaluations, succeeded" in out.out
    assert "8/8" in out.err  # the progress bar

    results = tmp_path / "r.csv"
    assert main(["results", "1", "--csv", str(results), *s]) == 0
    rows = list(csv.DictReader(results.open()))
    assert len(rows) == 8 and {r["status"] for r in rows} == {"ok"}

    rrd = tmp_path / "best-vs-g2.rrd"
    argv = ["record", "--job-id", "1", "--compare", "270,0.15,0.15", "--duration", "0.4", "--out", str(rrd), *s]
    assert main(argv) == 0
    assert frame_count(rrd, "/world/g1/swingarm") == frame_count(rrd, "/world/g2/swingarm") == 21
    exe = console_script("rerun")
    subprocess.run([exe, "analytics", "disable"], capture_output=True, check=False)
    assert subprocess.run([exe, "rrd", "verify", str(rrd)], capture_output=True, timeout=60).returncode == 0

    png = tmp_path / "map.png"
    assert main(["plot", "1", "--kind", "sweep-map", "--out", str(png), *s]) == 0
    assert png.read_bytes().startswith(b"\x89PNG")

    # a job cancelled while followed: its own exit code
    assert main(["submit", "de", "--road", "flat", "--np", "6", "--iters", "3000", "--duration", "0.5", *s]) == 0
    assert main(["cancel", "2", *s]) == 0
    capsys.readouterr()
    assert main(["status", "2", "--follow", *s]) == EXIT_JOB_NOT_SUCCEEDED

    # an unknown job and a bad token: HTTP errors, one line each
    assert main(["status", "999", *s]) == EXIT_HTTP
    monkeypatch.setenv("FINALDRIVE_API_TOKEN", "wrong")
    assert main(["cancel", "1", *s]) == EXIT_HTTP
    err = capsys.readouterr().err.splitlines()
    assert err[-2:] == ["finaldrive: error: HTTP 404: job 999 does not exist",
                        "finaldrive: error: HTTP 401: a valid token is required: the header `Authorization: Bearer "
                        "<token>` (any method) or the dashboard's session cookie `finaldrive_token` (set by `POST "
                        "/v1/session`; writes only from the dashboard's own pages); the token is the server's "
                        "FINALDRIVE_API_TOKEN; the client sends $FINALDRIVE_API_TOKEN, which here is set, but to "
                        "another value"]
    assert main(["status", "1", *s]) == EXIT_HTTP  # reads need the token too


def test_stopped_server(capsys: pytest.CaptureFixture[str]) -> None:
    url = f"http://127.0.0.1:{free_port()}"  # nothing listens there
    assert main(["jobs", "--server", url]) == EXIT_UNREACHABLE
    assert capsys.readouterr().err.count("\n") == 1


