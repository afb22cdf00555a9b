"""PNG plots: the public functions and GET /v1/jobs/{id}/plots/{name}.png."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient

from finaldrive.engine.study.sweep import parse_grid
from finaldrive.service import plots
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from tests.service.svc_helpers import DE, SWEEP, ToyTask, running_scheduler, wait_done

PNG = b"\x89PNG\r\n\x1a\n"


def is_png(data: bytes) -> bool:
    return data.startswith(PNG) and len(data) > 10_000


def test_sweep_map_grid_and_scatter(tmp_path: Path) -> None:
    grid = parse_grid("a2_deg=0:350:10,l2_m=0:0.2:0.02,rws_m=0.093")
    values = 20 + np.cos(grid[:, 0] - 3.3) * grid[:, 1]
    values[5] = math.nan  # a failed design stays blank
    plots.sweep_map_png(tmp_path / "grid.png", grid, values, title="grid", best=(3.3, 0.2))
    plots.sweep_map_png(tmp_path / "few.png", grid[::37], values[::37], title="scatter", value_label="fitness [m]")
    assert is_png((tmp_path / "grid.png").read_bytes()) and is_png((tmp_path / "few.png").read_bytes())


def test_sweep_map_outlines_the_near_optimal_set(tmp_path: Path) -> None:
    grid = parse_grid("a2_deg=0:350:10,l2_m=0:0.2:0.02,rws_m=0.093")
    values = 20 + np.cos(grid[:, 0] - 3.3) * grid[:, 1]
    near = values >= values.max() - 0.02
    for name, rows in (("grid", slice(None)), ("few", slice(None, None, 7))):
        plots.sweep_map_png(tmp_path / f"{name}.png", grid[rows], values[rows], title=name, near=near[rows])
        assert is_png((tmp_path / f"{name}.png").read_bytes())


def test_de_history_and_series(tmp_path: Path) -> None:
    history = [{"generation": g, "best_fitness_m": 20 + 0.1 * g, "mean_fitness_m": 19 + 0.2 * g} for g in range(1, 6)]
    population = np.column_stack([np.linspace(0, 6, 8), np.linspace(0, 0.2, 8), np.full(8, 0.09), np.arange(8.0)])
    plots.de_history_png(tmp_path / "de.png", history, population, title="de")
    t = np.linspace(0, 1, 50)
    series = {key: np.sin(t * k) for k, (key, _) in enumerate(plots.SERIES_PANELS, start=1)} | {"t_s": t}
    plots.series_png(tmp_path / "s.png", [("one", series), ("two", {k: v * 2 for k, v in series.items()})], title="s")
    assert is_png((tmp_path / "de.png").read_bytes()) and is_png((tmp_path / "s.png").read_bytes())


def test_plot_routes(client: TestClient) -> None:
    sweep = client.post("/v1/jobs", json=SWEEP).json()
    de = client.post("/v1/jobs", json=DE).json()
    wait_done(client, sweep["id"])
    wait_done(client, de["id"])
    for url in (f"/v1/jobs/{sweep['id']}/plots/sweep-map.png?road=1&value=distance",
                f"/v1/jobs/{sweep['id']}/plots/sweep-map.png", f"/v1/jobs/{de['id']}/plots/de-history.png"):
        r = client.get(url)
        assert r.status_code == 200 and r.headers["content-type"] == "image/png" and is_png(r.content), url
    assert client.get(f"/v1/jobs/{sweep['id']}/plots/de-history.png").status_code == 409
    assert client.get(f"/v1/jobs/{sweep['id']}/plots/sweep-map.png?road=moon").status_code == 422
    assert client.get("/v1/jobs/999/plots/sweep-map.png").status_code == 404
    assert client.get(f"/v1/jobs/{sweep['id']}/plots/pie.png").status_code == 422


def test_points_are_a_roads_columns(client: TestClient) -> None:
    sweep = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    stored = client.get(f"/v1/jobs/{sweep['id']}/evaluations", params={"road": "1"}).json()["items"]
    points = client.get(f"/v1/jobs/{sweep['id']}/points", params={"road": "sine:0.025:3"}).json()
    assert list(points) == ["road", "id", "step", "a2_deg", "l2_m", "rws_m", "distance_m", "fitness_m",
                            "squat_ratio", "slack_m", "status"]
    assert points["road"] == "sine:0.025:3" and points["id"] == [e["id"] for e in stored]
    for name in ("step", "a2_deg", "l2_m", "rws_m", "distance_m", "fitness_m", "squat_ratio", "slack_m", "status"):
        assert points[name] == [e[name] for e in stored], name
    assert client.get(f"/v1/jobs/{sweep['id']}/points").json()["road"] == "flat"
    assert client.get(f"/v1/jobs/{sweep['id']}/points?road=moon").status_code == 422
    assert client.get("/v1/jobs/999/points").status_code == 404


def test_failed_evaluations_are_nulls_in_points(settings: Settings) -> None:
    with TestClient(create_app(settings)) as c, running_scheduler(settings, ToyTask(fail_above_l2=0.12)):
        job = wait_done(c, c.post("/v1/jobs", json=SWEEP).json()["id"])
        points = c.get(f"/v1/jobs/{job['id']}/points").json()
    failed = [i for i, s in enumerate(points["status"]) if s == "failed"]
    assert len(failed) == 4 and all(points["fitness_m"][i] is None for i in failed)
    assert all(points["l2_m"][i] == 0.15 for i in failed)
