"""Migrations: an empty database upgraded to head matches the models; other revisions are refused."""

from __future__ import annotations

import argparse
import sqlite3
from pathlib import Path

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from fastapi.testclient import TestClient
from sqlalchemy import text

from finaldrive.service.cli import main, server_cmds
from finaldrive.service.config import Settings
from finaldrive.service.db.engine import PAGE_SIZE, make_engine
from finaldrive.service.db.migrate import SchemaMismatchError, alembic_config, current_revision, head_revision, upgrade
from finaldrive.service.db.models import Base
from finaldrive.service.main import create_app


@pytest.fixture
def url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'm.db'}"


def test_empty_database_upgraded_to_head_matches_models(url: str) -> None:
    upgrade(url)
    engine = make_engine(url)
    with engine.connect() as conn:
        assert compare_metadata(MigrationContext.configure(conn), Base.metadata) == []
        assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
        assert conn.exec_driver_sql("PRAGMA synchronous").scalar() == 2  # FULL
        assert conn.exec_driver_sql("PRAGMA page_size").scalar() == PAGE_SIZE != 4096
    assert current_revision(engine) == head_revision()
    engine.dispose()


def test_a_store_made_with_sqlite_s_default_pages_keeps_them_and_is_upgraded(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    old = sqlite3.connect(path)  # a store from before PAGE_SIZE: made by SQLite's defaults, in WAL mode
    old.execute("PRAGMA journal_mode = WAL")
    old.execute("CREATE TABLE earlier (x INTEGER)")
    old.close()
    url = f"sqlite:///{path}"
    upgrade(url)
    engine = make_engine(url)
    with engine.connect() as conn:
        assert conn.exec_driver_sql("PRAGMA page_size").scalar() == 4096
        assert conn.exec_driver_sql("PRAGMA integrity_check").scalar() == "ok"
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
        assert [(change[0], change[1].name) for change in diff] == [("remove_table", "earlier")]  # ours all there
    assert current_revision(engine) == head_revision()
    engine.dispose()


def test_downgrade_and_upgrade_again(url: str) -> None:
    upgrade(url)
    command.downgrade(alembic_config(url), "base")
    engine = make_engine(url)
    assert current_revision(engine) is None
    upgrade(url)
    assert current_revision(engine) == head_revision()
    engine.dispose()


def _set_revision(url: str, revision: str) -> None:
    engine = make_engine(url)
    with engine.begin() as conn:
        conn.execute(text("UPDATE alembic_version SET version_num = :r"), {"r": revision})
    engine.dispose()


def test_service_refuses_a_database_at_another_revision(url: str) -> None:
    upgrade(url)
    _set_revision(url, "v0.0.1.a")
    with (
        pytest.raises(SchemaMismatchError, match="newer finaldrive"),
        TestClient(create_app(Settings(db_url=url, executor="serial", allowed_hosts=["testserver"]))),
    ):
        pass


def test_service_refuses_tables_without_a_revision_and_says_what_to_run(
    url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = make_engine(url)
    with engine.begin() as conn:
        conn.exec_driver_sql("CREATE TABLE legacy (id INTEGER PRIMARY KEY)")
    engine.dispose()
    assert main(["serve", "--db", url]) == 2
    assert main(["scheduler", "--db", url]) == 2
    err = capsys.readouterr().err
    assert "revision none" in err and f"finaldrive db upgrade --db {url}" in err
    assert server_cmds.run_db_upgrade(argparse.Namespace(db=url)) == 0
    assert current_revision(make_engine(url)) == head_revision()
