"""The parser: help text and defaults everywhere, --version, one-line errors; the CLI stays import-light."""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from finaldrive.service.cli import build_parser, main, package_version
from finaldrive.service.cli.commands import COMMANDS


def test_building_the_cli_imports_no_web_or_database_stack() -> None:
    code = (
        "import sys; from finaldrive.service.cli import build_parser; build_parser(every=True); "
        "heavy = {'fastapi', 'sqlalchemy', 'alembic', 'uvicorn', 'numba', 'ray', 'rerun'} & set(sys.modules); "
        "assert not heavy, heavy"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_help_and_version_import_no_command_module_nor_numpy_or_pydantic() -> None:
    """`finaldrive --help` lists the commands from commands.COMMANDS alone (0.10 s here, issue 31 asks <= 0.3 s:
    docs/performance.md); a command builds its own module's parsers only."""
    code = (
        "import sys; from finaldrive.service.cli import build_parser; build_parser(); "
        "heavy = {'numpy', 'pydantic', 'finaldrive.service.config', 'finaldrive.service.cli.server_cmds'} & "
        "set(sys.modules); assert not heavy, heavy; build_parser('simulate'); "
        "assert 'finaldrive.service.cli.engine_cmds' in sys.modules and 'finaldrive.service.cli.server_cmds' "
        "not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_every_listed_command_is_its_modules_in_the_listed_order() -> None:
    sub = next(a for a in build_parser(every=True)._actions if isinstance(a, argparse._SubParsersAction))
    assert list(sub.choices) == list(COMMANDS)
    for name in COMMANDS:
        listed = next(a for a in build_parser(name)._actions if isinstance(a, argparse._SubParsersAction))
        assert listed.choices[name].add_help, name   # its module's parser, in full


def test_db_upgrade(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = f"sqlite:///{tmp_path / 'cli.db'}"
    assert main(["db", "upgrade", "--db", url]) == 0
    assert "is at schema revision" in capsys.readouterr().out
    assert main(["db", "upgrade", "--db", url]) == 0  # idempotent


def test_serve_rejects_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--executor", "gpu"]) == 2
    assert "invalid choice" in capsys.readouterr().err


def _parsers(
    parser: argparse.ArgumentParser, path: str = "finaldrive"
) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, f"{path} {name}")


def test_every_command_option_and_argument_has_help_that_shows_its_default() -> None:
    missing, no_default = [], []
    for path, parser in _parsers(build_parser(every=True)):
        formatter = parser._get_formatter()
        for action in parser._actions:
            if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            name = "/".join(action.option_strings) or action.dest
            if not action.help:
                missing.append(f"{path} {name}")
                continue
            shown = formatter._expand_help(action) if action.help else ""
            hidden = action.default is None or action.default is False or action.default is argparse.SUPPRESS
            if not hidden and str(action.default) not in shown:
                no_default.append(f"{path} {name}")
    assert missing == [], f"options without help: {missing}"
    assert no_default == [], f"options whose help does not show the default: {no_default}"


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"finaldrive {package_version()}" != "finaldrive unknown"


@pytest.mark.parametrize("argv", [
    ["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.093", "--road", "flat",
     "--record", "/missing/dir/x.rrd"],
    ["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.093", "--road", "flat", "--series", "/missing/x.csv"],
    ["evaluate", "--designs", "/missing/designs.csv", "--road", "flat"],
    ["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.093", "--road", "profile:/missing/road.csv"],
    ["optimize", "--road", "flat", "--vehicle", "/missing/vehicle.json"],
    ["calibrate", "--out", "/missing/dir/v.json"],
    ["optimize", "--road", "flat", "--bounds", "l2_m=0.2:0.1"],
    ["optimize", "--road", "flat", "--np", "2"],
])
def test_bad_paths_and_arguments_are_one_line_without_a_traceback(
        argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("finaldrive: error: ") and err.count("\n") == 1 and "Traceback" not in err
