"""Rerun recordings: the .rrd read back (entities, frames, values), and the /v1/recordings API."""

from __future__ import annotations

import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient
from rerun.chunk import RrdReader

from finaldrive.engine import DIAGNOSTICS, Design, Road, SimSettings, simulate
from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from finaldrive.service.media.recording import (
    PARTS,
    PLOTS,
    chunk_counts,
    frame_count,
    properties_of,
    record,
    scalars_of,
    series_settings,
)
from finaldrive.service.media.scene import ROW_OFFSET_M
from tests.service.processes import console_script
from tests.service.svc_helpers import ToyTask, running_scheduler, wait_done

ROAD = Road.parse("sine:0.04:3")
DURATION, FPS = 0.4, 50
# geometry 1 from integers, as a script would write it: its design's properties still floats beside geometry 2's
DESIGNS = [("geometry 1", Design.from_deg(0, 0, 0.093)), ("geometry 2", Design.from_deg(270.0, 0.15, 0.15))]


def verify(path: Path) -> None:
    """``rerun rrd verify`` exits 0 (analytics off first, so no banner or network)."""
    exe = console_script("rerun")
    subprocess.run([exe, "analytics", "disable"], capture_output=True, check=False)
    done = subprocess.run([exe, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


@pytest.fixture(scope="module")
def rrd(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rrd") / "two.rrd"
    record(path, DESIGNS, ROAD, duration=DURATION, fps=FPS)
    return path


def test_two_geometries_every_part_every_frame(rrd: Path) -> None:
    frames = round(DURATION * FPS) + 1
    for key in ("g1", "g2"):
        assert frame_count(rrd, f"/world/{key}") == frames  # the transform follows the bikes
        for part in (*PARTS, "tyre_forces", "force_labels", "label"):
            assert frame_count(rrd, f"/world/{key}/{part}") == frames, part
        for _, name, _ in PLOTS:
            assert frame_count(rrd, f"/plots/{name}/{key}") == frames, name
    reader = RrdReader(str(rrd))
    assert [r.application_id for r in reader.recordings()] == ["finaldrive"]
    assert reader.blueprints(), "the default blueprint is stored"
    static = {c.entity_path for c in reader.stream().to_chunks() if c.is_static}
    assert {"/world/g1/road", "/world/g2/road"} <= static
    verify(rrd)


def test_every_entity_is_a_few_chunks_however_slow_the_writer(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 31: rerun's web viewer took up to minutes over a file of 855 chunks (176 frames, two geometries).
    The batcher flushes every RERUN_FLUSH_TICK_SECS, so frames logged one by one split into a chunk per flush, more
    the slower the writer; at 1 ms that was 41 to 49 chunks on one entity here. Columns are one chunk each."""
    monkeypatch.setenv("RERUN_FLUSH_TICK_SECS", "0.001")
    path = tmp_path / "columns.rrd"
    record(path, DESIGNS, ROAD, duration=1.0, fps=FPS)
    counts = chunk_counts(path)
    for key in ("g1", "g2"):
        assert frame_count(path, f"/world/{key}/chain") == 51
        for entity in (f"/world/{key}", *(f"/world/{key}/{part}" for part in (*PARTS, "tyre_forces", "force_labels",
                                                                             "label", "road"))):
            assert counts[entity] <= 20, (entity, counts[entity])
    assert max(counts.values()) <= 20, counts


def test_each_geometry_carries_its_outcome_and_exact_extremes(rrd: Path) -> None:
    for i, (label, design) in enumerate(DESIGNS):
        result = simulate(design, ROAD, series_settings(DURATION, FPS))
        props = properties_of(rrd, f"g{i + 1}")
        assert props["label"] == label and props["a2_deg"] == design.a2_deg and props["rws_m"] == design.rws
        assert props["l2_m"] == design.l2
        for name in ("distance_m", "fitness_m", "slack_m", *DIAGNOSTICS):
            assert props[name] == pytest.approx(getattr(result, name), rel=1e-12, abs=1e-12), name
        # the extremes are the integrator's, not the 50 fps series': at least as wide as what is drawn
        assert props["chain_tension_max_n"] >= scalars_of(rrd, f"/plots/chain_tension_n/g{i + 1}")[1].max()


def test_series_equal_the_engines(rrd: Path) -> None:
    for i, (_, design) in enumerate(DESIGNS):
        series = simulate(design, ROAD, series_settings(DURATION, FPS)).series
        assert series is not None
        for key, name, _ in PLOTS:
            t, values = scalars_of(rrd, f"/plots/{name}/g{i + 1}")
            np.testing.assert_allclose(t, series["t_s"], atol=1e-9)
            np.testing.assert_allclose(values, series[key], rtol=1e-12, atol=1e-12)


def test_fps_must_divide_the_step_rate() -> None:
    with pytest.raises(ValueError, match="fps must divide"):
        series_settings(1.0, 7, SimSettings())


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    """The API and a scheduler (it produces the recordings; the jobs use the toy fitness)."""
    settings = Settings(db_url=f"sqlite:///{tmp_path / 'r.db'}", executor="serial", status_cache_seconds=0,
                        allowed_hosts=["testserver"])
    with TestClient(create_app(settings)) as c, running_scheduler(settings, ToyTask()):
        yield c


def wait_recording(client: TestClient, rid: int, timeout: float = 60) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        body = client.get(f"/v1/recordings/{rid}").json()
        if body["status"] in ("succeeded", "failed"):
            return body
        time.sleep(0.05)
    raise AssertionError(body)


def test_api_records_a_jobs_best_beside_a_design(client: TestClient, tmp_path: Path) -> None:
    job = client.post("/v1/jobs", json={"kind": "sweep", "roads": ["sine:0.04:3"],
                                        "grid": "a2_deg=0:90:90,l2_m=0.05,rws_m=0.09"}).json()
    wait_done(client, job["id"])
    r = client.post("/v1/recordings", json={"job_id": job["id"], "duration": 0.2, "fps": 25,
                                            "designs": [{"a2_deg": 270, "l2_m": 0.15, "rws_m": 0.15}]})
    assert r.status_code == 202 and r.headers["Location"] == f"/v1/recordings/{r.json()['id']}"
    body = wait_recording(client, r.json()["id"])
    assert body["status"] == "succeeded", body
    labels = [f"job {job['id']} best", "a2 = 270 deg, L2 = 0.150 m, R_WS = 0.150 m"]
    assert [d["label"] for d in body["designs"]] == labels
    assert body["road"] == "sine:0.04:3" and body["frames"] == 6 and "path" not in body
    download = client.get(body["file"])
    assert download.status_code == 200
    assert download.headers["content-disposition"] == f'attachment; filename="finaldrive-recording-{body["id"]}.rrd"'
    out = tmp_path / "dl.rrd"
    out.write_bytes(download.content)
    assert frame_count(out, "/world/g2/chain") == 6
    verify(out)


def test_api_errors(client: TestClient) -> None:
    assert client.get("/v1/recordings/99").status_code == 404
    assert client.get("/v1/recordings/99/file").status_code == 404
    no_road = client.post("/v1/recordings", json={"designs": [{"a2_deg": 0, "l2_m": 0, "rws_m": 0.09}]})
    assert no_road.status_code == 422 and "road" in no_road.json()["detail"]
    bad_road = client.post("/v1/recordings",
                           json={"road": "moon", "designs": [{"a2_deg": 0, "l2_m": 0, "rws_m": 0.09}]})
    assert bad_road.status_code == 422 and bad_road.json()["detail"].startswith("body.road: unknown road")
    assert client.post("/v1/recordings", json={"job_id": 42}).status_code == 404
    too_big = client.post("/v1/recordings",
                          json={"road": "flat", "designs": [{"a2_deg": 190, "l2_m": 0.5, "rws_m": 0.5}]})
    assert too_big.status_code == 422 and "l2_max" in too_big.json()["detail"]  # refused, never a failed recording
    failing = client.post("/v1/recordings", json={"road": "bump:0.5:0.01:0", "duration": 0.2,
                                                   "designs": [{"a2_deg": 190, "l2_m": 0.05, "rws_m": 0.09}]}).json()
    body = wait_recording(client, failing["id"])  # a kerb under the tyre: no equilibrium; the service goes on
    assert body["status"] == "failed" and "static equilibrium not found" in body["error"]
    assert client.get(f"/v1/recordings/{body['id']}/file").status_code == 409


def test_scene_read_back_matches_the_engine(rrd: Path) -> None:
    from finaldrive.engine.model import coordinates as C
    from finaldrive.service.media.recording import scene_at

    strips, arrows = scene_at(rrd, 0.2)
    assert {f"/world/g1/{p}" for p in PARTS} <= set(strips) and len(arrows) == 2
    q = simulate(DESIGNS[0][1], ROAD, series_settings(DURATION, FPS)).series["q"][10]  # t = 0.2 s
    chain = [[q[C.X10], q[C.Y10]], [q[C.X11], q[C.Y11]]]
    np.testing.assert_allclose(strips["/world/g1/chain"][0], chain, atol=1e-6)  # stored as float32


# --- the 2D view: zoomed on the bikes, following them; labels apart -------------------------------------------------

#: The view at its opening zoom, as the issue measured it (830 px wide); a label is drawn centred under its anchor:
#: 5 px below it, about 7 px a character and 16 px tall, on a background 6 px (sides) and 4 px (top, bottom) larger.
VIEW_PX = (830, 600)


def _label_box(anchor: np.ndarray, text: str, px_per_m: float) -> tuple[float, float, float, float]:
    """(left, top, right, bottom) [m, view space] of a label's background."""
    half, top = (7 * len(text) + 12) / 2 / px_per_m, anchor[1] + 1 / px_per_m
    return anchor[0] - half, top, anchor[0] + half, top + 24 / px_per_m


@pytest.fixture(scope="module")
def ride(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A ride long enough (2 s, about 6.6 m) to leave any fixed 3 m view."""
    path = tmp_path_factory.mktemp("rrd") / "ride.rrd"
    record(path, DESIGNS, ROAD, duration=2.0, fps=25)
    return path


def _bounds(path: Path) -> tuple[list[float], list[float]]:
    reader = RrdReader(str(path))
    for chunk in reader.stream(store=reader.blueprints()[0]).to_chunks():
        if chunk.entity_path.endswith("/VisualBounds2D"):
            (value,) = chunk.to_record_batch().column("VisualBounds2D:range")[0].as_py()
            return value["x_range"], value["y_range"]
    raise AssertionError("no VisualBounds2D in the blueprint")


def _world(path: Path) -> dict[str, dict[int | None, dict[str, Any]]]:
    """Entity -> time [ns] (None: static) -> column -> value, for everything under /world. An entity's static
    components hold at every time (as the viewer shows them): merged into its timed rows, None only for an
    entity with nothing timed."""
    static: dict[str, dict[str, Any]] = {}
    timed: dict[str, dict[int | None, dict[str, Any]]] = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        if not chunk.entity_path.startswith("/world/"):
            continue
        batch = chunk.to_record_batch()
        columns = [n for n in batch.schema.names if ":" in n]
        if chunk.is_static:
            static.setdefault(chunk.entity_path, {}).update({n: batch.column(n)[0].as_py() for n in columns})
            continue
        for row, t in enumerate(batch.column("sim_time").cast("int64").to_pylist()):
            timed.setdefault(chunk.entity_path, {})[t] = {n: batch.column(n)[row].as_py() for n in columns}
    return {entity: {t: {**static.get(entity, {}), **row} for t, row in timed[entity].items()} if entity in timed
            else {None: static[entity]} for entity in static.keys() | timed.keys()}


def _to_view(transform: dict[str, Any], points: Any) -> np.ndarray:
    """Points of /world/g<k>/... in the view's space: the logged transform (scale, then translation)."""
    scale, translation = (np.asarray(transform[f"Transform3D:{c}"])[0, :2] for c in ("scale", "translation"))
    return np.asarray(np.asarray(points, dtype=float).reshape(-1, 2) * scale + translation)


def test_the_view_opens_on_the_bikes_not_the_road(ride: Path) -> None:
    (x0, x1), (y0, y1) = _bounds(ride)
    road = np.asarray(_world(ride)["/world/g1/road"][None]["LineStrips2D:strips"][0])
    assert x0 < 0 < x1 and x0 == pytest.approx(-x1), "centred on the reference"
    assert x1 - x0 == pytest.approx(max(3.0, 1.7 * (y1 - y0))), "3 m, or wide enough that a wide panel shows every row"
    assert np.ptp(road[:, 0]) > 2.5 * (x1 - x0), "the road is far longer than the view"
    assert ROW_OFFSET_M + 1.0 < y1 - y0 < ROW_OFFSET_M + 2.0, "both rows, each a bike's height"


def test_the_view_follows_the_bikes(ride: Path) -> None:
    (x0, x1), (y0, y1) = _bounds(ride)
    world = _world(ride)
    transforms = {key: world[f"/world/{key}"] for key in ("g1", "g2")}
    assert transforms["g1"].keys() == transforms["g2"].keys() and None not in transforms["g1"]
    for t, transform in transforms["g1"].items():  # one reference for both: their relative advance shows
        assert transform == transforms["g2"][t]
    travelled = []
    for key, per_time in transforms.items():
        for part in (*PARTS, "tyre_forces", "force_labels", "label"):
            for t, row in world[f"/world/{key}/{part}"].items():
                if "LineStrips2D:strips" in row:
                    points = np.concatenate([np.asarray(s) for s in row["LineStrips2D:strips"]])
                elif "Arrows2D:vectors" in row:
                    origins = np.asarray(row["Arrows2D:origins"])
                    points = np.concatenate([origins, origins + np.asarray(row["Arrows2D:vectors"])])
                else:
                    points = np.asarray(row["Points2D:positions"])
                view = _to_view(per_time[t], points)
                assert (view[:, 0] >= x0).all() and (view[:, 0] <= x1).all(), (key, part, t)
                assert (view[:, 1] >= y0).all() and (view[:, 1] <= y1).all(), (key, part, t)
                if part == "chassis":
                    travelled.append(points[:, 0].mean())
    assert np.ptp(travelled) > 1.2 * (x1 - x0), "the bikes ride out of any fixed view of this size"
    road = world["/world/g1/road"][None]["LineStrips2D:strips"][0]  # static: it scrolls past
    start, end = transforms["g1"][0], transforms["g1"][max(t or 0 for t in transforms["g1"])]
    first, last = (_to_view(transform, road)[:, 0] for transform in (start, end))
    assert first[0] - last[0] == pytest.approx(max(travelled) - min(travelled), abs=0.3)


def test_labels_are_readable_and_apart(ride: Path) -> None:
    (x0, x1), (y0, y1) = _bounds(ride)
    px_per_m = min(VIEW_PX[0] / (x1 - x0), VIEW_PX[1] / (y1 - y0))
    world = _world(ride)
    for key in ("g1", "g2"):
        assert all("Arrows2D:labels" not in row for row in world[f"/world/{key}/tyre_forces"].values())
        assert "LineStrips2D:labels" not in world[f"/world/{key}/road"][None]  # the label follows the bike
    for t in world["/world/g1"]:
        boxes = []
        for i, key in enumerate(("g1", "g2")):
            transform = world[f"/world/{key}"][t]
            forces = world[f"/world/{key}/force_labels"][t]
            rear, front = forces["Points2D:labels"]
            assert rear.startswith("Fz ") and ", Fx " in rear and rear.endswith(" kN") and front.startswith("Fz ")
            label = world[f"/world/{key}/label"][t]
            assert label["Points2D:labels"] == [DESIGNS[i][0]]
            for entity in (forces, label):
                for anchor, text in zip(_to_view(transform, entity["Points2D:positions"]),
                                        entity["Points2D:labels"], strict=True):
                    boxes.append(_label_box(anchor, text, px_per_m))
        for a in range(len(boxes)):
            for b in range(a + 1, len(boxes)):
                (l1, t1, r1, b1), (l2, t2, r2, b2) = boxes[a], boxes[b]
                assert r1 <= l2 or r2 <= l1 or b1 <= t2 or b2 <= t1, (t, boxes[a], boxes[b])
