"""Shared fixtures: the paper's tables, the vehicle, and the stores (SQLite and a real PostgreSQL)."""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from finaldrive.engine import default_vehicle, paper_tables


@pytest.fixture(autouse=True)
def _alone_if_exclusive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Under pytest-xdist, a test marked ``exclusive`` runs with no other test beside it: every test holds
    the run's machine lock shared, an exclusive one holds it alone. A turnstile taken before it keeps an
    exclusive test from waiting forever: while one waits, no other test starts. A test marked ``cluster``
    (it starts Ray nodes of its own) runs beside no other such test."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        yield
        return
    run = tmp_path_factory.getbasetemp().parent        # the run's folder, shared by its workers
    alone = request.node.get_closest_marker("exclusive") is not None
    cluster = request.node.get_closest_marker("cluster") is not None
    with (open(run / "turnstile.lock", "a") as turnstile, open(run / "machine.lock", "a") as machine,
          open(run / "cluster.lock", "a") as clusters):
        fcntl.flock(turnstile, fcntl.LOCK_EX)
        fcntl.flock(machine, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        fcntl.flock(turnstile, fcntl.LOCK_UN)
        if cluster:   # taken after the machine lock and given back first: no cycle with an exclusive test
            fcntl.flock(clusters, fcntl.LOCK_EX)
        yield                                           # all released when the files close


@pytest.fixture(scope="session")
def tables() -> dict:
    return paper_tables()


@pytest.fixture(scope="session")
def vehicle():
    return default_vehicle()


@pytest.fixture(scope="session")
def postgres() -> Iterator[object]:
    """A PostgreSQL server for the session (skipped, with the reason, where none is installed)."""
    from tests.pg import PostgresServer, bindir

    binaries = bindir()
    if binaries is None:
        pytest.skip("PostgreSQL server binaries (initdb, pg_ctl) not found; install Debian's postgresql")
    server = PostgresServer(binaries).start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """An empty database URL, once for each store: a SQLite file and a PostgreSQL database."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'store.db'}"
    server = request.getfixturevalue("postgres")
    return str(server.new_database())
