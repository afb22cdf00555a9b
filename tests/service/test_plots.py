"""PNG plots: the public functions and GET /v1/jobs/{id}/plots/{name}.png."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.projections.polar import PolarAxes

from finaldrive.engine import Design, default_vehicle
from finaldrive.engine.study.sweep import parse_grid
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from finaldrive.service.media import plots
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


def _luminance(rgb: tuple[float, ...]) -> float:
    """Relative luminance (WCAG 2)."""
    lin = [c / 12.92 if c <= 0.03928 else ((c + 0.055) / 1.055) ** 2.4 for c in rgb[:3]]
    return 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]


def assert_radial_labels_legible(fig: Figure, avoid_deg: list[float], markers: np.ndarray | None = None) -> None:
    """The polar map's L2 labels: at least two, >= 9 pt, dark on a box light enough over any colour (WCAG contrast
    >= 7 with black beneath the box), apart from each other, from the pivot's surroundings and from ``markers``
    (rows a2 [rad], L2 [m]: scattered designs), along a direction at least 45 deg from the swingarm and the best
    design; no angle label under a legend."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()   # type: ignore[attr-defined]
    ax = next(a for a in fig.axes if isinstance(a, PolarAxes))
    labels = [t for t in ax.get_yticklabels() if t.get_visible() and t.get_text()]
    assert len(labels) >= 2
    boxes = []
    for t in labels:
        assert t.get_fontsize() >= 9, t.get_text()
        patch = t.get_bbox_patch()
        assert patch is not None, t.get_text()
        face = to_rgba(patch.get_facecolor())
        alpha = face[3] if patch.get_alpha() is None else patch.get_alpha()
        beneath = tuple(alpha * c for c in face[:3])   # the box over black, the worst case
        text = _luminance(to_rgba(t.get_color()))
        assert (_luminance(beneath) + 0.05) / (text + 0.05) >= 7, t.get_text()
        boxes.append(patch.get_window_extent(renderer))
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not a.overlaps(b), (a, b)
    centre = ax.transData.transform((0.0, 0.0))
    radius = np.hypot(*(ax.transData.transform((math.pi / 2, ax.get_rmax())) - centre))
    clear = 0.15 * radius   # the pivot's marker and the designs crowding around it
    for box in boxes:
        nearest = np.clip(centre, [box.x0, box.y0], [box.x1, box.y1])
        assert np.hypot(*(nearest - centre)) > clear, (box, centre)
        for x, y in ax.transData.transform(markers) if markers is not None else []:
            assert not box.padded(5).contains(x, y), (box, x, y)   # a marker's radius: 45 pt^2 at 110 dpi, 5 px
    position = ax.get_rlabel_position()
    assert all(abs((position - a + 180) % 360 - 180) >= 45 for a in avoid_deg), (position, avoid_deg)
    legends = [*fig.legends, *(a.get_legend() for a in fig.axes if a.get_legend() is not None)]
    for t in ax.get_xticklabels():
        assert not any(t.get_window_extent(renderer).overlaps(g.get_window_extent(renderer)) for g in legends), t


@pytest.mark.parametrize("best_deg", [204.0, 20.0, 100.0])
def test_sweep_map_radial_labels_are_legible(best_deg: float) -> None:
    """Issue 31, item 6: the radial labels were 8 crowded ones from the pivot out, black on the cells, and the
    legend hid the 90 deg label."""
    grid = parse_grid("a2_deg=0:354:6,l2_m=0:0.2:0.02,rws_m=0.093")
    values = 20 + np.cos(grid[:, 0] - 3.3) * grid[:, 1]
    near = values >= values.max() - 0.01
    fig = plots.sweep_map_figure(grid, values, title="grid", best=(math.radians(best_deg), 0.02), near=near,
                                 near_label="fitness within 0.1 % of the best (6 designs)")
    assert_radial_labels_legible(fig, [190.0, best_deg])
    few = grid[::37]
    scattered = plots.sweep_map_figure(few, values[::37], title="few", best=(math.radians(best_deg), 0.1))
    assert_radial_labels_legible(scattered, [190.0, best_deg], few[:, :2])


def test_de_history_radial_labels_are_legible() -> None:
    population = np.column_stack([np.linspace(0, 6, 8), np.linspace(0, 0.2, 8), np.full(8, 0.09), np.arange(8.0)])
    fig = plots.de_history_figure([{"generation": 1, "best_fitness_m": 1.0, "mean_fitness_m": 0.5}], population,
                                  title="de")
    assert_radial_labels_legible(fig, [190.0, math.degrees(6.0)], population[:, :2])


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


def test_the_maps_swingarm_is_where_the_dashboard_draws_it(client: TestClient) -> None:
    """The PNG's swingarm line is at the static sag GET /v1/geometry gives (the dashboard's map draws that), not
    at the design angle phi0 - theta0 (0.36 deg apart on the paper's bike); with a softer rear spring, lower."""
    grid = parse_grid("a2_deg=0:350:10,l2_m=0:0.2:0.02,rws_m=0.093")
    fig = plots.sweep_map_figure(grid, np.ones(len(grid)), title="t")
    line = next(ln for ln in fig.axes[0].get_lines() if ln.get_label().startswith("swingarm"))
    drawn = math.degrees(line.get_xdata()[0])
    served = client.get("/v1/geometry", params={"a2_deg": 0, "l2_m": 0, "rws_m": 0.093}).json()["swingarm_angle_deg"]
    assert drawn == pytest.approx(served, abs=0.01)
    v = default_vehicle()
    assert abs(drawn - math.degrees(v["phi0"] - v["theta0"])) > 0.3
    assert plots.swingarm_at_sag_deg(v.replace(k_rs=0.8 * v["k_rs"])) < drawn - 0.1   # more sag: a lower swingarm
    refused = Design.from_deg(190.0, 0.55, 0.15)   # L2 beyond the vehicle's l2_max: no equilibrium drawn from
    assert plots.swingarm_at_sag_deg(v, refused) == pytest.approx(math.degrees(v["phi0"] - v["theta0"]))
