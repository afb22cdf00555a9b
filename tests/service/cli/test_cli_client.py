"""The job client without a server: an injected httpx transport, an injected sleep."""

from __future__ import annotations

import io
import json
from collections.abc import Callable
from typing import Any

import httpx
import pytest

from finaldrive.engine import default_vehicle, load_vehicle_dict
from finaldrive.service.cli import main, remote
from finaldrive.service.client import ServiceClient


def job(state: str = "running", done: int = 3, **extra: Any) -> dict[str, Any]:
    best = {"a2_deg": 190.0, "l2_m": 0.03, "rws_m": 0.09, "fitness_m": 20.5, "distance_m": 20.6}
    return {"id": 7, "kind": "de", "state": state, "total": 12, "done": done, "failed": 1, "eta_s": 42.0,
            "error": None, "created_at": "2026-01-01T00:00:00Z",
            "roads": [{"index": 0, "name": "flat", "spec": "flat", "best": best}], **extra}


def use_transport(monkeypatch: pytest.MonkeyPatch, handler: Callable[[httpx.Request], httpx.Response]) -> None:
    def make(args: Any) -> ServiceClient:
        http = httpx.Client(transport=httpx.MockTransport(handler), base_url="http://fd.test")
        return ServiceClient("http://fd.test", http=http)

    monkeypatch.setattr(remote, "connect", make)


def problem(status: int, detail: str) -> httpx.Response:
    return httpx.Response(status, json={"type": "about:blank", "title": "x", "status": status, "detail": detail},
                          headers={"content-type": "application/problem+json"})


def test_progress_line() -> None:
    line = remote.progress_line(job())
    assert line.startswith("job 7 running") and "4/12" in line and "failed 1" in line
    assert "best 20.500 m" in line and "ETA 42s" in line
    assert "ETA" not in remote.progress_line(job("succeeded", 11))


def test_follow_polls_until_terminal_and_sleeps_between() -> None:
    states = iter([job(done=0), job(done=5), job("succeeded", 11)])
    slept: list[float] = []

    class Fake:
        def job(self, job_id: int) -> dict[str, Any]:
            return next(states)

    out = io.StringIO()
    final = remote.follow(Fake(), 7, out=out, interval=0.5, sleep=slept.append)
    assert final["state"] == "succeeded" and slept == [0.5, 0.5]
    assert [line.split("]")[1].split()[0] for line in out.getvalue().splitlines()] == ["1/12", "6/12", "12/12"]


def test_submit_maps_options_to_the_spec(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    seen: list[dict[str, Any]] = []

    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(json.loads(request.content))
        assert request.headers["Idempotency-Key"] == "k1"
        return httpx.Response(201, json=job("queued", 0))

    use_transport(monkeypatch, handler)
    argv = ["submit", "robust-de", "--roads", "flat,sine:0.02:3", "--road", "bump:0.02:0.5", "--np", "8",
            "--iters", "3", "--seed", "4", "--aggregate", "worst", "--duration", "1.5", "--idempotency-key", "k1",
            "--bounds", "a2_deg=90:270,l2_m=0:0.1", "--optimiser", "cmaes", "--preset", "paper"]
    assert main(argv) == 0
    assert seen == [{"kind": "robust-de", "roads": ["bump:0.02:0.5", "flat", "sine:0.02:3"], "seed": 4,
                     "settings": {"duration": 1.5, "method": "fast"}, "aggregate": "worst",
                     "de": {"np": 8, "iters": 3, "optimiser": "cmaes", "preset": "paper"},  # the rest: the server's
                     "bounds": {"a2_deg": [90.0, 270.0], "l2_m": [0.0, 0.1], "rws_m": [0.05, 0.15]}}]
    assert capsys.readouterr().out.startswith("job 7: de on 1 road(s), 12 evaluations, queued")
    seen.clear()
    assert main(["submit", "sweep", "--road", "flat", "--drive", "launch", "--idempotency-key", "k1"]) == 0
    vehicle = seen[0]["vehicle"]  # the whole vehicle goes with the job, its drive the launch
    assert load_vehicle_dict(vehicle).packed().tolist() == default_vehicle().replace(drive_model=1.0).packed().tolist()
    assert main(["submit", "de", "--road", "flat", "--grid", "table9"]) == 2
    assert main(["submit", "sweep"]) == 2
    assert main(["submit", "de", "--road", "flat", "--preset", "paper", "--max-evals", "20"]) == 2  # NP 50
    assert "--max-evals: must be >= np (50)" in capsys.readouterr().err


def test_follow_exit_code_when_the_job_is_cancelled(monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    use_transport(monkeypatch, lambda r: httpx.Response(200, json=job("cancelled", 4)))
    assert main(["status", "7", "--follow"]) == remote.EXIT_JOB_NOT_SUCCEEDED
    assert capsys.readouterr().err.strip().endswith("finaldrive: job 7 cancelled")
    assert main(["status", "7"]) == 0


def test_http_errors_are_one_line_with_their_own_code(monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    use_transport(monkeypatch, lambda r: problem(404, "job 99 does not exist"))
    assert main(["best", "99"]) == remote.EXIT_HTTP
    assert capsys.readouterr().err == "finaldrive: error: HTTP 404: job 99 does not exist\n"
    use_transport(monkeypatch, lambda r: httpx.Response(502, text="<html>bad\ngateway</html>"))
    assert main(["jobs"]) == remote.EXIT_HTTP
    assert capsys.readouterr().err.count("\n") == 1


def test_unreachable_server(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    def refuse(request: httpx.Request) -> httpx.Response:
        raise httpx.ConnectError("connection refused")

    use_transport(monkeypatch, refuse)
    assert main(["cancel", "3", "--json"]) == remote.EXIT_UNREACHABLE
    err = capsys.readouterr().err
    assert err.startswith("finaldrive: error: cannot reach the service at http://fd.test") and err.count("\n") == 1


def test_results_csv_follows_the_cursor(monkeypatch: pytest.MonkeyPatch, tmp_path: Any,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    pages = {None: ("id,fitness_m\n1,20.1\n", "1"), "1": ("id,fitness_m\n2,20.2\n", "")}

    def handler(request: httpx.Request) -> httpx.Response:
        assert request.url.params["road"] == "flat"
        text, cursor = pages[request.url.params.get("cursor")]
        return httpx.Response(200, text=text, headers={"X-Next-Cursor": cursor, "content-type": "text/csv"})

    use_transport(monkeypatch, handler)
    out = tmp_path / "r.csv"
    assert main(["results", "7", "--road", "flat", "--csv", str(out)]) == 0
    assert out.read_text() == "id,fitness_m\n1,20.1\n2,20.2\n"
    assert "wrote 2 evaluations" in capsys.readouterr().out


def test_record_and_plot_need_their_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["record", "--out", "x.rrd"]) == 2
    assert main(["record", "--compare", "1,2", "--road", "flat", "--out", "x.rrd"]) == 2
    assert "expected A2_DEG,L2,RWS" in capsys.readouterr().err
    assert main(["plot", "--out", "x.png"]) == 2


def test_local_record_simulate_record_and_series_plot(tmp_path: Any, capsys: pytest.CaptureFixture[str]) -> None:
    from finaldrive.service.media.recording import frame_count

    two = tmp_path / "two.rrd"
    assert main(["record", "--compare", "0,0,0.093", "270,0.15,0.15", "--road", "sine:0.04:3", "--duration", "0.2",
                 "--fps", "25", "--out", str(two), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["frames"] == 6
    assert frame_count(two, "/world/g2/rear_wheel") == 6
    one = tmp_path / "one.rrd"
    assert main(["simulate", "--a2-deg", "0", "--l2-m", "0", "--rws-m", "0.093", "--road", "flat", "--duration", "0.2",
                 "--record", str(one), "--json"]) == 0
    assert frame_count(one, "/world/g1/chain") == 11 and frame_count(one, "/world/g2/chain") == 0
    png = tmp_path / "s.png"
    assert main(["plot", "--series", "0,0,0.093", "--road", "flat", "--duration", "0.2", "--out", str(png)]) == 0
    assert png.read_bytes().startswith(b"\x89PNG")


def test_best_prints_which_variables_are_decided(monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    seen: list[httpx.Request] = []
    sharp = {"road": "flat", "tolerance_pct": 0.1, "tolerance_m": 0.0205, "best_fitness_m": 20.5, "count": 9,
             "evaluated": 84, "ranges": {"a2_deg": [190.0, 360.0], "l2_m": [0.01, 0.012], "rws_m": [0.09, 0.1]},
             "explored": {}, "verdicts": {"a2_deg": "undetermined"},
             "sentences": ["a2 is not decided: any a2 from 190 to 360 deg is within 20.5 mm of the best fitness"]}

    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request)
        return httpx.Response(200, json={"job_id": 7, "roads": job()["roads"], "sharpness": [sharp]})

    use_transport(monkeypatch, handler)
    assert main(["best", "7", "--tolerance-pct", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "near-optimal set: 9 of 84 evaluated designs" in out and "a2 is not decided" in out
    assert seen[0].url.params["tolerance_pct"] == "0.5"


def _polled_best(seen: list[httpx.Request], ready: dict[str, Any]) -> Any:
    """A /best that answers 202 (its jobs running, Retry-After 0) once, then 200 with ``ready`` in the road's
    sharpness; each request into ``seen``."""
    sharp = {"road": "flat", "tolerance_pct": 0.1, "tolerance_m": 0.0205, "best_fitness_m": 20.5, "count": 2,
             "evaluated": 3, "ranges": {"a2_deg": [0.0, 10.0], "l2_m": [0.0, 0.0], "rws_m": [0.09, 0.09]},
             "explored": {}, "verdicts": {}, "sentences": []}

    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request)
        if len(seen) == 1:
            return httpx.Response(202, headers={"Retry-After": "0"}, json={"job_id": 7, "roads": job()["roads"],
                                                                          "sharpness": [sharp]})
        return httpx.Response(200, json={"job_id": 7, "roads": job()["roads"], "sharpness": [sharp | ready]})
    return handler


def test_best_band_polls_and_prints_the_band_and_ties(monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """202 (the band jobs running) is polled as Retry-After asks; then the best's band and its ties."""
    seen: list[httpx.Request] = []
    band = {"fitness_m": 20.5, "distance_m": 20.6, "band_m": 0.0021, "distance_band_m": 0.002, "exceeds_limit": True,
            "runs": {}, "failed": {}}
    ties = [{**band, "a2_deg": 0.0, "l2_m": 0.0, "rws_m": 0.09, "tie": True},
            {**band, "fitness_m": 20.499, "a2_deg": 10.0, "l2_m": 0.0, "rws_m": 0.09, "tie": True},
            {**band, "fitness_m": 20.4, "a2_deg": 20.0, "l2_m": 0.0, "rws_m": 0.09, "tie": False}]
    use_transport(monkeypatch, _polled_best(seen, {"numerical_band": band, "ties": ties}))
    assert main(["best", "7", "--band"]) == 0
    out = capsys.readouterr().out
    assert len(seen) == 2 and all(r.url.params["band"] == "true" for r in seen)
    assert "numerical band of the best's fitness: +-2.10 mm, wider than 1 mm" in out
    assert "of the next 2 best designs, 1 tie with it" in out


def test_best_model_band_polls_and_prints_each_alternatives_ranking(monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    seen: list[httpx.Request] = []
    ranking = {"fitness_m": [20.5, 20.4, 20.3], "distance_m": [20.6, 20.5, 20.4], "failed": ["", "", ""],
               "rank_correlation": 1.0, "best": 0, "same_best": True, "largest_change_m": 0.0}
    bands = {"designs": [{"a2_deg": 0.0, "l2_m": 0.0, "rws_m": 0.09}] * 3, "baseline": ranking,
             "alternatives": {"drive_double": ranking | {"rank_correlation": -0.5, "best": 2, "same_best": False,
                                                         "largest_change_m": 0.0123, "failed": ["", "x", ""],
                                                         "what": "the drive doubled", "road": "flat"}},
             "skipped": ["road_enveloped"], "skipped_reasons": {"road_enveloped": "a computed profile"}}
    use_transport(monkeypatch, _polled_best(seen, {"model_bands": bands}))
    assert main(["best", "7", "--model-band"]) == 0
    out = capsys.readouterr().out
    assert len(seen) == 2 and all(r.url.params["model_band"] == "true" for r in seen)
    assert "model bands of its 3 best distinct designs" in out
    assert "drive_double" in out and "-0.50" in out and "another best" in out and "12.3 mm" in out
    assert "(1 failed)" in out and "left out: road_enveloped (a computed profile)" in out
