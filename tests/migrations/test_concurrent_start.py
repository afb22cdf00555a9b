"""Concurrent start-up on an empty store: two API processes and a scheduler, started at the same
instant, all come up with the schema at head (migrations are serialised by a lock).

The start-ups run in real processes: each imports everything, reports ready, and waits for a go
file, so the three open the store within a millisecond of each other.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import pytest
from alembic import command

from finaldrive.service.db.engine import make_engine
from finaldrive.service.db.migrate import (
    MigrationBusyError,
    alembic_config,
    current_revision,
    ensure_schema,
    head_revision,
    migration_lock,
)
from finaldrive.service.machine import free_port


def test_a_start_up_waits_for_the_migration_another_process_runs(store_url: str) -> None:
    """While the lock is held (here, by this thread; the lock works between threads as between
    processes), a start-up that may not create the schema waits, then finds it at head; past its
    wait it fails, saying why."""
    engine = make_engine(store_url)
    try:
        with pytest.raises(MigrationBusyError, match="another process has been migrating"), migration_lock(store_url):
            ensure_schema(engine, store_url, create=True, wait_s=0.3)
        errors: list[BaseException] = []

        def start() -> None:
            try:
                ensure_schema(engine, store_url, create=False, wait_s=30)
            except BaseException as exc:
                errors.append(exc)

        waiter = threading.Thread(target=start)
        with migration_lock(store_url):
            waiter.start()
            time.sleep(0.5)
            assert waiter.is_alive()  # without the wait it would have refused the empty database at once
            command.upgrade(alembic_config(store_url), "head")
        waiter.join(10)
        assert not waiter.is_alive() and not errors
        assert current_revision(engine) == head_revision()
    finally:
        engine.dispose()


#: A process's start-up: what ``finaldrive serve`` (``_check_store``, then the app's ``start_services``)
#: or ``finaldrive scheduler`` (``_check_store``, then ``run_scheduler``'s ``open_database``) does first;
#: once per trial, on the trial's URL, when the trial's go file appears. It writes its outcome to a file.
START = """
import os, sys, time, traceback
from pathlib import Path
from finaldrive.service.cli.server_cmds import _check_store
from finaldrive.service.config import Settings
from finaldrive.service.services import open_database, start_services
role, name, where, trials = sys.argv[1:]
where = Path(where)
for trial in range(int(trials)):
    (where / f"ready{trial}-{name}").touch()
    while not (where / f"go{trial}").exists():
        time.sleep(0.0005)
    settings = Settings(db_url=(where / f"url{trial}").read_text(), executor="serial")
    try:
        _check_store(settings)
        if role == "serve":
            start_services(settings).close()
        else:
            open_database(settings).dispose()
        outcome = "up"
    except BaseException:
        outcome = traceback.format_exc()
    (where / f"outcome-{name}").write_text(outcome)
    (where / f"outcome-{name}").rename(where / f"done{trial}-{name}")
"""
ROLES = ("serve", "serve", "scheduler")
TRIALS = 10


def _wait_for_files(files: list[Path], procs: list[subprocess.Popen[bytes]], log: Path) -> None:
    deadline = time.monotonic() + 90
    while not all(f.exists() for f in files):
        assert time.monotonic() < deadline, f"timed out waiting for {files}: {log.read_text()[-3000:]}"
        assert all(p.poll() in (None, 0) for p in procs), log.read_text()[-3000:]
        time.sleep(0.002)


@pytest.mark.slow   # three processes start ten times
@pytest.mark.parametrize("store", ["sqlite", "postgresql"])
def test_three_processes_start_together_on_an_empty_store(store: str, tmp_path: Path,
                                                          request: pytest.FixtureRequest) -> None:
    """10 trials, each on a new empty store: every process comes up and the schema is at head."""
    server = request.getfixturevalue("postgres") if store == "postgresql" else None
    names = [f"{role}{i}" for i, role in enumerate(ROLES)]
    log = tmp_path / "log"
    with log.open("ab") as out:
        procs = [subprocess.Popen([sys.executable, "-c", START, role, f"{role}{i}", str(tmp_path), str(TRIALS)],
                                  stdout=out, stderr=subprocess.STDOUT) for i, role in enumerate(ROLES)]
    try:
        for trial in range(TRIALS):
            url = server.new_database() if server is not None else f"sqlite:///{tmp_path / f'store{trial}.db'}"
            (tmp_path / f"url{trial}").write_text(url)
            _wait_for_files([tmp_path / f"ready{trial}-{name}" for name in names], procs, log)
            (tmp_path / f"go{trial}").touch()
            done = [tmp_path / f"done{trial}-{name}" for name in names]
            _wait_for_files(done, procs, log)
            failed = {f.name: f.read_text()[-3000:] for f in done if f.read_text() != "up"}
            assert not failed, f"trial {trial}: {failed}"
            engine = make_engine(url)
            assert current_revision(engine) == head_revision()
            engine.dispose()
    finally:
        for p in procs:
            p.kill()
            p.wait()


#: The real command line (``finaldrive serve`` or ``scheduler``), run once the go file appears.
CLI = """
import os, sys, time
import finaldrive.service.services
from finaldrive.service.cli import main, server_cmds
go = sys.argv[1]
while not os.path.exists(go):
    time.sleep(0.0005)
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.slow
@pytest.mark.parametrize("store", ["sqlite", "postgresql"])
def test_two_servers_and_a_scheduler_start_together_on_an_empty_store(store: str, tmp_path: Path,
                                                                     request: pytest.FixtureRequest) -> None:
    """Real ``finaldrive serve`` x2 and ``finaldrive scheduler``: all stay up, both servers healthy, and
    each sees the three schedulers (two beside the servers, one alone)."""
    url = request.getfixturevalue("postgres").new_database() if store == "postgresql" else \
        f"sqlite:///{tmp_path / 'store.db'}"
    go, log = tmp_path / "go", tmp_path / "log"
    ports = [free_port(), free_port()]
    commands = [*(["serve", "--port", str(port), "--db", url, "--executor", "serial"] for port in ports),
                ["scheduler", "--db", url, "--executor", "serial"]]
    with log.open("ab") as out:
        procs = [subprocess.Popen([sys.executable, "-c", CLI, str(go), *cmd], stdout=out, stderr=subprocess.STDOUT,
                                  env={**os.environ, "FINALDRIVE_LEASE_SECONDS": "30"}) for cmd in commands]
    try:
        time.sleep(1.0)  # the imports before the barrier
        go.touch()
        deadline = time.monotonic() + 90
        healthy: set[int] = set()
        while len(healthy) < len(ports):
            assert time.monotonic() < deadline, log.read_text()[-5000:]
            assert all(p.poll() is None for p in procs), log.read_text()[-5000:]
            for port in set(ports) - healthy:
                try:
                    reply = httpx.get(f"http://127.0.0.1:{port}/v1/health", timeout=5)
                except httpx.TransportError:
                    continue
                if reply.status_code == 200 and sum(s["alive"] for s in reply.json()["schedulers"]) == 3:
                    healthy.add(port)
            time.sleep(0.1)
        assert all(p.poll() is None for p in procs)
        engine = make_engine(url)
        assert current_revision(engine) == head_revision()
        engine.dispose()
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait(30)
