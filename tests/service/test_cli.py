"""``finaldrive serve`` / ``finaldrive db upgrade`` wiring; the CLI stays import-light."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from service.cli import main


def test_building_the_cli_imports_no_web_or_database_stack() -> None:
    code = (
        "import sys; from service.cli import build_parser; build_parser(); "
        "heavy = {'fastapi', 'sqlalchemy', 'alembic', 'uvicorn'} & set(sys.modules); "
        "assert not heavy, heavy"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_db_upgrade(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = f"sqlite:///{tmp_path / 'cli.db'}"
    assert main(["db", "upgrade", "--db", url]) == 0
    assert "is at schema revision" in capsys.readouterr().out
    assert main(["db", "upgrade", "--db", url]) == 0  # idempotent


def test_serve_rejects_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--executor", "gpu"]) == 2
    assert "invalid choice" in capsys.readouterr().err
