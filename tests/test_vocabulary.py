"""One vocabulary: every output field that carries a unit names it, one spelling a quantity.

The names are collected from the real outputs: the API's OpenAPI schema, the CLI's JSON and CSV
(geometry, simulate with its series file, evaluate, roads, calibrate), the database's columns and
the recordings' plots. docs/fields.md must be the table ``python -m finaldrive.engine.fields`` prints.
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
from finaldrive.service.recording import PLOTS

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
    design = ["--a2-deg", "195.3", "--l2", "0.037", "--rws", "0.088"]
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
