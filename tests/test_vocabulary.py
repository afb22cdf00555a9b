"""One vocabulary: every output field that carries a unit names it, one spelling a quantity.

The names are collected from the real outputs: the API's OpenAPI schema, the CLI's JSON and CSV
(geometry, simulate with its series file, evaluate, roads, optimize, calibrate), the database's
columns and the recordings' plots; the CLI's options are the API's words (or listed as the CLI's
own, with why), the docs' command lines use options that exist, and roads print as their specs.
docs/fields.md must be the table ``python -m finaldrive.engine.fields`` prints.
"""

from __future__ import annotations

import csv
import io
import json
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from finaldrive.engine import FIELDS, base_of, unit_of
from finaldrive.engine.fields import table_markdown
from finaldrive.service.cli import main
from finaldrive.service.config import Settings
from finaldrive.service.db.models import Base
from finaldrive.service.main import create_app
from finaldrive.service.media.recording import PLOTS

ROOT = Path(__file__).resolve().parents[1]
#: spellings of units the rule does not use (SI, angles in degrees)
NOT_SI = ("_mm", "_ms", "_cm", "_km", "_kn", "_g", "_min", "_h", "_rad")


def _keys(value: Any) -> Iterator[str]:
    """Every key of nested JSON."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield str(key)
            yield from _keys(item)
    elif isinstance(value, list):
        for item in value:
            yield from _keys(item)


def _cli_json(argv: list[str], capsys: pytest.CaptureFixture[str]) -> Any:
    assert main(argv) == 0, argv
    return json.loads(capsys.readouterr().out)


def _output_names(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> dict[str, set[str]]:
    """Field name -> where it was seen."""
    seen: dict[str, set[str]] = defaultdict(set)
    design = ["--a2-deg", "195.3", "--l2-m", "0.037", "--rws-m", "0.088"]
    for key in _keys(_cli_json(["geometry", *design, "--travel", "--points", "5", "--json"], capsys)):
        seen[key].add("cli geometry")
    series = tmp_path / "series.csv"
    for key in _keys(_cli_json(["simulate", *design, "--road", "flat", "--duration", "0.2", "--json",
                                "--series", str(series)], capsys)):
        seen[key].add("cli simulate")
    for key in next(csv.reader(io.StringIO(series.read_text()))):
        seen[key].add("cli series csv")
    designs = tmp_path / "designs.csv"
    designs.write_text("a2_deg,l2_m,rws_m\n0,0,0.093\n")
    assert main(["evaluate", "--designs", str(designs), "--road", "flat", "--duration", "0.2"]) == 0
    for key in next(csv.reader(io.StringIO(capsys.readouterr().out))):
        seen[key].add("cli evaluate csv")
    for key in _keys(_cli_json(["roads", "--json"], capsys)):
        seen[key].add("cli roads")
    for key in _keys(_cli_json(["optimize", "--road", "flat", "--np", "4", "--iters", "1", "--duration", "0.2",
                                "--executor", "serial", "--json"], capsys)):
        seen[key].add("cli optimize")
    for key in _keys(_cli_json(["calibrate", "--out", str(tmp_path / "v.json")], capsys)):
        seen[key].add("cli calibrate")
    schema = create_app(Settings(db_url=f"sqlite:///{tmp_path / 'api.db'}")).openapi()
    for component in schema["components"]["schemas"].values():
        for key in component.get("properties", {}):
            seen[key].add("api")
    for table in Base.metadata.tables.values():
        for column in table.columns:
            seen[column.name].add(f"database {table.name}")
    for _, entity, _ in PLOTS:
        seen[entity].add("recording plots")
    return seen


def test_no_quantity_has_two_unit_spellings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    seen = _output_names(tmp_path, capsys)
    assert {"a2_deg", "l2_m", "rws_m", "slack_m", "fitness_m", "t_s", "pitch_deg"} <= set(seen)  # it looked
    by_base: dict[str, set[str]] = defaultdict(set)
    for name in seen:
        if not name.endswith("_pct"):  # a share of something, not a unit of it (tolerance_pct beside tolerance_m)
            by_base[base_of(name)].add(name)
    twice = {base: sorted(names) for base, names in by_base.items()
             if len(names) > 1 and base in {base_of(n) for n in names if unit_of(n)}}
    assert not twice, {base: {n: sorted(seen[n]) for n in names} for base, names in twice.items()}
    not_si = {name: sorted(seen[name]) for name in seen if name.lower().endswith(NOT_SI)}
    assert not not_si, not_si


def test_every_physical_field_is_documented_with_its_unit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    seen = _output_names(tmp_path, capsys)
    engine_outputs = {"cli simulate", "cli series csv", "cli evaluate csv", "cli geometry"}
    engine_fields = {name for name, where in seen.items() if unit_of(name) and where & engine_outputs}
    missing = sorted(engine_fields - set(FIELDS))
    assert not missing, missing
    assert all(FIELDS[name].unit == unit_of(name) for name in FIELDS)


def test_docs_fields_table_is_current() -> None:
    text = (ROOT / "docs" / "fields.md").read_text()
    assert table_markdown() in text, "regenerate: python -m finaldrive.engine.fields"


def test_every_value_of_the_result_record_reaches_every_output() -> None:
    """One declaration (engine.record): the engine's results, the store's columns, the API's
    evaluation fields, the evaluate command's columns and docs/fields.md carry each value of the
    record, under its name, and with its documented unit."""
    from finaldrive.engine import RECORD, VALUES, BatchResult, SimResult
    from finaldrive.service.cli.engine_cmds import EVALUATE_COLUMNS
    from finaldrive.service.schemas import EvaluationOut

    assert len(VALUES) == len(set(VALUES)) == len(RECORD) > 20
    result = SimResult.of("ok", "", **{name: float(i) for i, name in enumerate(VALUES)})
    assert list(result.summary()) == ["status", "reason", *VALUES]
    assert [getattr(result, name) for name in VALUES] == [float(i) for i in range(len(VALUES))]
    batch = BatchResult.from_results(np.zeros((1, 3)), [result])
    assert batch.values.shape == (1, len(VALUES)) and batch.ledger_residual_j[0] == VALUES.index("ledger_residual_j")
    columns = Base.metadata.tables["evaluations"].columns
    for value in RECORD:
        assert value.name in columns and value.name in EvaluationOut.model_fields, value.name
        assert value.name in EVALUATE_COLUMNS and FIELDS[value.name].unit == unit_of(value.name), value.name
        assert FIELDS[value.name].meaning == value.meaning


#: Long options with no API field of their name: what each is, and why it has no API word.
CLI_ONLY = {
    "help": "argparse", "version": "the program's", "json": "output format", "csv": "output file",
    "out": "output file", "png": "output file", "record": "output .rrd file", "server": "which service (its URL)",
    "db": "the database URL: the service's FINALDRIVE_DB_URL setting", "port": "where to listen",
    "timeout": "how long the client waits",
    "follow": "the client polls until the job ends", "exit_with_parent": "process supervision",
    "scheduler": "serve --no-scheduler: process layout", "workers": "local executor's processes",
    "repeat": "optimize runs the study K times with seeds seed+k", "stride": "simulate prints every k-th row",
    "skip_cog": "calibrate's steps", "skip_torque": "calibrate's steps",
    "idempotency_key": "the API's Idempotency-Key header",
    "design": "record: a design of the request's designs", "compare": "record: the request's further designs",
    "drive": "a vehicle's drive_model by name (the API takes the whole vehicle)",
}


def _cli_options() -> dict[str, set[str]]:
    """Every long option of every command, as its word (``--tol-m`` -> ``tol_m``) -> commands."""
    import argparse

    from finaldrive.service.cli import build_parser

    parser = build_parser(every=True)
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out: dict[str, set[str]] = defaultdict(set)
    for command, p in [("", parser), *sub.choices.items()]:
        for action in p._actions:
            for option in action.option_strings:
                if option.startswith("--"):
                    out[option[2:].replace("-", "_").removeprefix("no_")].add(command)
    return out


def _api_words(tmp_path: Path) -> set[str]:
    """Every request and response field and query parameter of the API."""
    schema = create_app(Settings(db_url=f"sqlite:///{tmp_path / 'api.db'}")).openapi()
    words = {key for c in schema["components"]["schemas"].values() for key in c.get("properties", {})}
    words |= {p["name"] for ops in schema["paths"].values() for op in ops.values() for p in op.get("parameters", [])}
    return words


def test_every_cli_option_is_the_api_word_for_its_quantity(tmp_path: Path) -> None:
    options, api = _cli_options(), _api_words(tmp_path)
    assert {"a2_deg", "l2_m", "rws_m", "mr_fraction", "aggregate", "tolerance_pct", "roads"} <= set(options) & api
    stray = {word: sorted(options[word]) for word in options if word not in api and word not in CLI_ONLY}
    assert not stray, f"options with no API field of that name (rename to the API's word, or list in CLI_ONLY): {stray}"
    # an option kept out of the API must not be an API word spelt another way (l2 beside l2_m)
    clashes = {word: sorted(a for a in api if base_of(a) == word) for word in CLI_ONLY}
    assert not {w: a for w, a in clashes.items() if a}, clashes
    assert set(CLI_ONLY) <= set(options), sorted(set(CLI_ONLY) - set(options))  # no stale entries


def test_the_docs_use_the_commands_options() -> None:
    """Every ``--option`` on a ``finaldrive COMMAND`` line of the README and docs is an option of COMMAND."""
    import argparse
    import re

    from finaldrive.service.cli import build_parser

    def options(p: argparse.ArgumentParser) -> set[str]:  # with a command's own subcommands' (db upgrade)
        nested = [q for a in p._actions if isinstance(a, argparse._SubParsersAction) for q in a.choices.values()]
        return {o for a in p._actions for o in a.option_strings}.union(*map(options, nested))

    parser = build_parser(every=True)
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    known = {name: options(p) for name, p in sub.choices.items()}
    wrong: list[str] = []
    lines = 0
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for line in path.read_text().splitlines():
            for m in re.finditer(r"(?:^|[`$&;(]\s*)finaldrive ([a-z-]+)((?: +[^`&;|#]*)?)", line):
                command, rest = m.group(1), m.group(2)
                if command not in known:
                    continue
                lines += 1
                for option in re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", rest):
                    if option not in known[command]:
                        wrong.append(f"{path.name}: finaldrive {command} {option}")
    assert lines > 30, lines  # it read them
    assert not wrong, wrong


def test_a_road_is_printed_as_its_spec(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The CLI's and the API's outputs name a road by its spec, whichever way it was given."""
    from fastapi.testclient import TestClient

    from finaldrive.engine import Road

    presets = _cli_json(["roads", "--json"], capsys)
    assert len(presets) == 23 and all(r["name"] == r["spec"] == Road.parse(r["spec"]).spec for r in presets)
    out = _cli_json(["optimize", "--roads", "sine-h4cm-l3m,flat", "--np", "4", "--iters", "0", "--duration", "0.1",
                     "--executor", "serial", "--no-band", "--json"], capsys)
    assert out["roads"] == ["sine:0.04:3", "flat"] and [r["road"] for r in out["per_road"]] == out["roads"]
    assert out["aggregate"] == "mean"
    settings = Settings(db_url=f"sqlite:///{tmp_path / 'r.db'}", executor="serial", allowed_hosts=["testserver"])
    with TestClient(create_app(settings)) as client:
        assert [r["name"] for r in client.get("/v1/roads").json()] == [r["spec"] for r in presets]
