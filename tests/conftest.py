"""Shared fixtures: the paper's tables, the vehicle, and the stores (SQLite and a real PostgreSQL)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from finaldrive.engine import default_vehicle, paper_tables


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
