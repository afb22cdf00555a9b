"""The paper-study report: generated from a tiny real study, byte-identical when re-run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from finaldrive.service.cli import main
from finaldrive.service.config import Settings
from finaldrive.service.db.results import generation_records
from finaldrive.service.main import create_app
from finaldrive.service.report import write_paper_study
from finaldrive.service.report.analysis import alignment_deg, de_history, offset_mm
from finaldrive.service.report.data import StudyNotFound, from_database, from_server
from finaldrive.service.services import open_database

ROADS = ["flat", "sine:0.04:3"]


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> str:
    """A finished tiny paper-study (2 roads, 12-design grid, NP 4, 1 iteration, 0.2 s simulations)."""
    url = f"sqlite:///{tmp_path_factory.mktemp('study') / 'study.db'}"
    assert main(["study", "paper", "--local", "--db", url, "--executor", "serial", "--roads", ",".join(ROADS),
                 "--grid", "a2_deg=0:300:60,l2_m=0.02|0.12", "--np", "4", "--iters", "1", "--duration", "0.2",
                 "--interval", "60"]) == 0
    return url


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.slow
def test_report_is_complete_and_byte_identical_when_rerun(study: str, tmp_path: Path) -> None:
    out_a, out_b = tmp_path / "a", tmp_path / "b"
    for out in (out_a, out_b):
        assert main(["report", "paper-study", "1", "--out", str(out / "paper-study.md"), "--db", study]) == 0
    files = _files(out_a)
    assert files == _files(out_b)
    assert {"paper-study.md", "paper-study.json", "paper-study/table14-series.png"} <= set(files)
    assert {f"paper-study/sweep-{i:02d}-{name.replace(':', '_')}.png" for i, name in enumerate(ROADS)} <= set(files)
    md = files["paper-study.md"].decode()
    for heading in ("## Run", "## Do the paper's conclusions hold here?", "## Per road", "## Sweep",
                    "## Table 14", "## Robust design", "## Sharpness of each optimum", "(1)", "(2)", "(3)"):
        assert heading in md
    for name in ROADS:
        assert f"`{name}`" in md and f"![sweep map {name}](paper-study/sweep-" in md
    report = json.loads(files["paper-study.json"])
    assert [r["name"] for r in report["roads"]] == ROADS
    assert report["run"]["stored"] == report["run"]["total_planned"] == 2 * 12 + 2 * 8
    assert report["roads"][0]["paper"]["fitness_m"] == 20.708
    assert report["robust"]["method"].startswith("best mean fitness over the stored Table 9 sweep grid")
    assert report["table14"]["ours"]["geometry2"]["rws_m"] == 0.05
    for road in report["roads"]:  # each road's best banded, as engine.numerical_bands gives it, and its ties
        band, ties = road["numerical_band"], road["ties"]
        assert band["band_m"] is not None and band["band_m"] >= 0 and ties[0]["tie"] is True and len(ties) == 5
        assert band["fitness_m"] == pytest.approx(road["near_optimal"]["best_fitness_m"], abs=1e-5)
    assert "| band [mm] | ties |" in md


def test_the_server_and_the_database_give_the_same_study(study: str, tmp_path: Path) -> None:
    from_db = from_database(study, 1)
    settings = Settings(db_url=study, executor="serial", status_cache_seconds=0, allowed_hosts=["testserver"])
    with TestClient(create_app(settings)) as client:
        via_api = from_server("http://testserver", 1, client=client)
    assert from_db.spec == via_api.spec and from_db.roads == via_api.roads
    assert (from_db.started_at, from_db.finished_at) == (via_api.started_at, via_api.finished_at)
    assert from_db.evals.keys() == via_api.evals.keys()
    for key, values in from_db.evals.items():
        assert values.tolist() == pytest.approx(via_api.evals[key].tolist(), nan_ok=True, rel=0, abs=0)
    a = write_paper_study(from_db, tmp_path / "db" / "r.md", figures=False)
    b = write_paper_study(via_api, tmp_path / "api" / "r.md", figures=False)
    assert a.markdown.read_bytes() == b.markdown.read_bytes() and a.json.read_bytes() == b.json.read_bytes()


def test_the_reports_de_history_is_the_one_the_store_holds(study: str) -> None:
    """The report recomputes each road's DE history from the evaluations; the API's /history reads
    the optimiser's own records: the same generations, evaluations, best and mean."""
    data = from_database(study, 1)
    db = open_database(Settings(db_url=study))
    with db.read() as session:
        stored = generation_records(session, 1)
    db.dispose()
    for road in range(len(ROADS)):
        report = de_history(data, road, 4)
        assert [r["generation"] for r in report] == [r["generation"] for r in stored[road]] == [0, 1]
        for ours, theirs in zip(report, stored[road], strict=True):
            assert ours["n_evals"] == theirs["n_evals"]
            assert ours["best_fitness_m"] == pytest.approx(theirs["best_fitness_m"], abs=1e-6)
            assert ours["mean_fitness_m"] == pytest.approx(theirs["mean_fitness_m"], abs=1e-6)


def test_a_job_that_is_not_a_paper_study_is_refused(study: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(StudyNotFound, match="does not exist"):
        from_database(study, 99)
    assert main(["report", "paper-study", "99", "--db", study]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_alignment_with_the_swingarm() -> None:
    phi0 = 190.0
    assert alignment_deg(190.0, phi0) == alignment_deg(10.0, phi0) == 0.0
    assert alignment_deg(371.0, phi0) == pytest.approx(1.0)
    assert alignment_deg(100.0, phi0) == alignment_deg(280.0, phi0) == 90.0
    assert offset_mm(280.0, 0.1, phi0) == pytest.approx(100.0)
    assert offset_mm(10.0, 0.2, phi0) == pytest.approx(0.0, abs=1e-9)
