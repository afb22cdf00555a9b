"""Rerun recordings (.rrd) of simulated designs: the only module that imports rerun.

One recording holds one or more geometries on the same road, one above the other
(``/world/g1``, ``/world/g2``, ...; the road is drawn under each), and their Fig. 13 time
series under ``/plots/<quantity>/g<k>``. The timeline ``sim_time`` has one frame per series
row: ``duration * fps + 1`` frames. The logged points are the engine's coordinates unchanged;
each ``/world/g<k>`` carries a transform per frame that shifts x by minus the reference x
(scene.reference_x, common to all geometries) and flips y (Rerun's 2D views draw y downwards;
a transform on the view's origin itself would not apply). The view's visual bounds cover the
bikes around that reference, so it opens zoomed on them and the road scrolls past.

Every per-frame entity is sent as columns (one chunk for all its frames, whatever the writer's speed),
its radii, colours and, for the geometry's label, its text logged once, static.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from finaldrive.engine import Design, Road, SimSettings, Vehicle, default_vehicle, simulate
from finaldrive.service.media.scene import (
    ROW_OFFSET_M,
    Run,
    force_labels,
    frame,
    reference_x,
    road_strip,
    tyre_forces,
)

APPLICATION_ID = "finaldrive"
TIMELINE = "sim_time"
#: (series key, entity name, legend unit) of the Fig. 13 plots.
PLOTS: tuple[tuple[str, str, str], ...] = (
    ("distance_m", "distance_m", "m"),
    ("chain_tension_n", "chain_tension_n", "N"),
    ("squat_ratio", "squat_ratio", "-"),
    ("fz_rear_n", "fz_rear_n", "N"),
    ("fz_front_n", "fz_front_n", "N"),
    ("kappa", "kappa", "-"),
    ("fx_n", "fx_n", "N"),
)
PARTS = ("chassis", "swingarm", "damper", "fork", "rear_wheel", "front_wheel",
         "engine_sprocket", "wheel_sprocket", "chain")
_COLOURS = ((31, 119, 180), (214, 39, 40), (44, 160, 44), (148, 103, 189))
_PART_WIDTH = {"chassis": 0.012, "swingarm": 0.012, "fork": 0.01, "chain": 0.006}
_FORCE_COLOUR = (230, 120, 0)
#: The view: at least this far either side of the reference x, and this much beyond the bikes [m].
_VIEW_HALF_WIDTH_M = 1.5
_VIEW_MARGIN_M = 0.1
#: The view's least width per height: rerun fills the panel's width with the bounds' x range (seen in
#: its web viewer, where the 3:2 split makes the Mechanism panel about 1.6 times as wide as tall), so
#: bounds narrower than this would crop the lower rows.
_VIEW_ASPECT = 1.7
#: A geometry's label this far above its bikes' highest point [m]; room under the lowest road for
#: the tyre-force labels [m] (a label is drawn under its anchor, about 25 px tall).
_LABEL_RISE_M = 0.2
_FORCE_LABEL_ROOM_M = 0.2

#: One run's parts, frame by frame (scene.frame).
_Frames = list[dict[str, list[np.ndarray]]]


class RecordingError(RuntimeError):
    """A geometry could not be simulated, so there is nothing to record."""


def run_key(index: int) -> str:
    """Entity name of the ``index``-th geometry (0-based): g1, g2, ..."""
    return f"g{index + 1}"


def series_settings(duration: float, fps: int, base: SimSettings | None = None) -> SimSettings:
    """Settings whose series has one row per frame (``fps`` must divide 1/dt)."""
    base = base or SimSettings()
    stride = round(1.0 / (fps * base.dt))
    if stride < 1 or abs(stride * fps * base.dt - 1.0) > 1e-9:
        raise ValueError(f"fps must divide 1/dt = {1.0 / base.dt:g} Hz, got {fps}")
    return replace(base, duration=duration, series=True, series_stride=stride)


def simulate_runs(designs: Sequence[tuple[str, Design]], road: Road, settings: SimSettings,
                  vehicle: Vehicle | None = None) -> list[Run]:
    """Simulate each (label, design) with series; :class:`RecordingError` if one fails."""
    runs = []
    for label, design in designs:
        result = simulate(design, road, settings, vehicle)
        if not result.ok or result.series is None:
            raise RecordingError(f"{label}: the simulation failed: {result.reason}")
        outcome = {k: float(v) for k, v in result.summary().items() if isinstance(v, float)}
        runs.append(Run(label, design, result.series, outcome))
    return runs


def blueprint(x_range: tuple[float, float], y_range: tuple[float, float]) -> rrb.Blueprint:
    """The 2D mechanism on the left (opening on the view-space bounds ``x_range``, ``y_range`` [m]),
    the Fig. 13 plots in a grid on the right."""
    plots = [rrb.TimeSeriesView(origin=f"/plots/{name}", name=f"{name} [{unit}]") for _, name, unit in PLOTS]
    bounds = rrb.VisualBounds2D(x_range=x_range, y_range=y_range)
    mechanism = rrb.Spatial2DView(origin="/world", name="Mechanism", visual_bounds=bounds)
    return rrb.Blueprint(rrb.Horizontal(mechanism, rrb.Grid(*plots), column_shares=[3, 2]), collapse_panels=True)


def _offset(index: int) -> float:
    return -index * ROW_OFFSET_M


def write_recording(path: str | Path, runs: Sequence[Run], road: Road, *, name: str,
                    recording_id: str | None = None, vehicle: Vehicle | None = None) -> None:
    """Write ``runs`` (all on ``road``, same time rows) to ``path``; closes the file."""
    vehicle = vehicle or default_vehicle()
    ref = reference_x(runs)
    frames = [[frame(run, k, run.design.rws / vehicle["sprocket_ratio"], _offset(i)) for k in range(len(ref))]
              for i, run in enumerate(runs)]
    reach, bottom, top = _extent(frames, ref)
    label_y = top + _LABEL_RISE_M
    half = max(_VIEW_HALF_WIDTH_M, reach + _VIEW_MARGIN_M)
    lowest = _offset(len(runs) - 1) + bottom - _FORCE_LABEL_ROOM_M
    half = max(half, 0.5 * _VIEW_ASPECT * (label_y + _VIEW_MARGIN_M - lowest))
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
    try:
        rec.save(str(path), default_blueprint=blueprint((-half, half), (-(label_y + _VIEW_MARGIN_M), -lowest)))
        rec.send_recording_name(name)
        rec.send_property("road", rr.AnyValues(spec=road.spec))
        for i, run in enumerate(runs):
            _log_run(rec, run, run_key(i), i, road, frames[i], ref, label_y)
    finally:
        rec.disconnect()


def _extent(frames: list[_Frames], ref: np.ndarray) -> tuple[float, float, float]:
    """How far the bikes reach from the reference x, and their lowest and highest y above their
    row's offset, over the whole run [m]."""
    reach, bottom, top = 0.0, np.inf, -np.inf
    for i, run_frames in enumerate(frames):
        for k, parts in enumerate(run_frames):
            points = np.concatenate([strip for strips in parts.values() for strip in strips])
            reach = max(reach, float(np.abs(points[:, 0] - ref[k]).max()))
            bottom = min(bottom, float(points[:, 1].min()) - _offset(i))
            top = max(top, float(points[:, 1].max()) - _offset(i))
    return reach, bottom, top


def _log_run(rec: rr.RecordingStream, run: Run, key: str, index: int, road: Road, frames: _Frames,
             ref: np.ndarray, label_y: float) -> None:
    colour = _COLOURS[index % len(_COLOURS)]
    d = run.design
    offset = _offset(index)
    root = f"/world/{key}"
    # as floats: a design built from integers (L2 = 0) would type the property as an integer, and rerun
    # would then drop the other designs' decimal values
    values: dict[str, Any] = {"label": run.label, "a2_deg": float(d.a2_deg), "l2_m": float(d.l2),
                              "rws_m": float(d.rws), **run.outcome}
    rec.send_property(key, rr.AnyValues(**values))
    t = run.series["t_s"]
    times = rr.TimeColumn(TIMELINE, duration=t)
    zeros = np.zeros_like(ref)
    rec.send_columns(root, indexes=[times],  # follow the reference, into the view's y-down space
                     columns=rr.Transform3D.columns(translation=np.column_stack([-ref, zeros, zeros]),
                                                    scale=np.tile([1.0, -1.0, 1.0], (len(ref), 1))))
    rec.log(f"{root}/road", rr.LineStrips2D([road_strip(road, [run], offset)], radii=0.004, colors=(90, 90, 90)),
            static=True)
    for series_key, name, unit in PLOTS:
        path = f"/plots/{name}/{key}"
        rec.log(path, rr.SeriesLines(names=f"{run.label} [{unit}]", colors=colour, widths=2), static=True)
        rec.send_columns(path, indexes=[times], columns=rr.Scalars.columns(scalars=run.series[series_key]))
    # each per-frame entity is one column: one chunk, not one per batcher flush (rerun's web viewer took minutes
    # over a file of 855 chunks; issue 31); what does not change from frame to frame is logged once, static
    for part in PARTS:
        strips = [strip for parts in frames for strip in parts[part]]
        rec.log(f"{root}/{part}", rr.LineStrips2D.from_fields(radii=_PART_WIDTH.get(part, 0.006), colors=colour),
                static=True)
        rec.send_columns(f"{root}/{part}", indexes=[times], columns=rr.LineStrips2D.columns(strips=strips).partition(
            [len(parts[part]) for parts in frames]))
    forces = [tyre_forces(run, k, offset) for k in range(len(t))]
    rec.log(f"{root}/tyre_forces", rr.Arrows2D.from_fields(radii=0.008, colors=_FORCE_COLOUR), static=True)
    rec.send_columns(f"{root}/tyre_forces", indexes=[times], columns=rr.Arrows2D.columns(
        origins=np.concatenate([o for o, _ in forces]), vectors=np.concatenate([v for _, v in forces]),
    ).partition([len(o) for o, _ in forces]))
    labels = [force_labels(run, k, offset) for k in range(len(t))]
    rec.log(f"{root}/force_labels", rr.Points2D.from_fields(radii=0.0, colors=_FORCE_COLOUR), static=True)
    rec.send_columns(f"{root}/force_labels", indexes=[times], columns=rr.Points2D.columns(
        positions=np.concatenate([a for a, _ in labels]), labels=[text for _, texts in labels for text in texts],
    ).partition([len(a) for a, _ in labels]))
    rec.log(f"{root}/label", rr.Points2D.from_fields(radii=0.0, colors=colour, labels=[run.label]), static=True)
    rec.send_columns(f"{root}/label", indexes=[times], columns=rr.Points2D.columns(
        positions=np.column_stack([ref, np.full_like(ref, offset + label_y)])))


def record(path: str | Path, designs: Sequence[tuple[str, Design]], road: Road, *, duration: float = 3.5,
           fps: int = 50, base: SimSettings | None = None, vehicle: Vehicle | None = None,
           recording_id: str | None = None) -> list[Run]:
    """Simulate ``designs`` on ``road`` and write them side by side to ``path``."""
    settings = series_settings(duration, fps, base)
    runs = simulate_runs(designs, road, settings, vehicle)
    name = " vs ".join(label for label, _ in designs) + f" on {road.spec}"
    write_recording(path, runs, road, name=name, recording_id=recording_id, vehicle=vehicle)
    return runs


def scene_at(path: str | Path, t: float) -> tuple[dict[str, list[np.ndarray]], list[tuple[np.ndarray, np.ndarray]]]:
    """What a finished .rrd shows under ``/world`` at ``t`` [s]: line strips per entity and
    tyre-force arrows (origins, vectors), read back from the file (for a matplotlib render)."""
    from rerun.chunk import RrdReader

    strips: dict[str, list[np.ndarray]] = {}
    arrows: list[tuple[np.ndarray, np.ndarray]] = []
    target = round(t * 1e9)
    for chunk in RrdReader(str(path)).stream().to_chunks():
        if not chunk.entity_path.startswith("/world/"):
            continue
        batch = chunk.to_record_batch()
        row = 0
        if not chunk.is_static:
            times = np.asarray(batch.column(TIMELINE).cast("int64").to_pylist())
            row = int(np.argmin(np.abs(times - target)))
            if abs(times[row] - target) > 1e6:  # not in this chunk
                continue
        names = batch.schema.names
        if "LineStrips2D:strips" in names:
            strips[chunk.entity_path] = [np.asarray(s) for s in batch.column("LineStrips2D:strips")[row].as_py()]
        elif "Arrows2D:vectors" in names:
            arrows.append((np.asarray(batch.column("Arrows2D:origins")[row].as_py()),
                           np.asarray(batch.column("Arrows2D:vectors")[row].as_py())))
    return strips, arrows


def properties_of(path: str | Path, key: str) -> dict[str, object]:
    """The recording property ``key`` (a run's label, design and outcome) of a finished .rrd."""
    from rerun.chunk import RrdReader

    for chunk in RrdReader(str(path)).stream().to_chunks():
        if chunk.is_static and chunk.entity_path == f"/__properties/{key}":
            batch = chunk.to_record_batch()
            values = {name: batch.column(name)[0].as_py() for name in batch.schema.names
                      if not name.startswith("rerun.")}
            return {name: v[0] if isinstance(v, list) and len(v) == 1 else v for name, v in values.items()}
    raise KeyError(f"{path}: no property {key!r}")


def read_rows(path: str | Path) -> dict[str, list[object]]:
    """The temporal chunks of a finished .rrd as record batches, by entity path."""
    from rerun.chunk import RrdReader

    out: dict[str, list[object]] = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        if not chunk.is_static:
            out.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return out


def chunk_counts(path: str | Path) -> dict[str, int]:
    """Chunks per entity path of a finished .rrd's recording, static and temporal, as the file stores them."""
    from rerun.chunk import RrdReader

    counts: dict[str, int] = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        counts[chunk.entity_path] = counts.get(chunk.entity_path, 0) + 1
    return counts


def frame_count(path: str | Path, entity: str) -> int:
    """Time rows logged on ``entity``."""
    return sum(batch.num_rows for batch in read_rows(path).get(entity, []))  # type: ignore[attr-defined]


def scalars_of(path: str | Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], value) of one series entity, in time order."""
    t: list[int] = []
    v: list[float] = []
    for batch in read_rows(path).get(entity, []):
        t.extend(batch.column(TIMELINE).cast("int64").to_pylist())  # type: ignore[attr-defined]
        v.extend(x[0] for x in batch.column("Scalars:scalars").to_pylist())  # type: ignore[attr-defined]
    order = np.argsort(t, kind="stable")
    return np.asarray(t, dtype=float)[order] * 1e-9, np.asarray(v, dtype=float)[order]


def serve_viewer(port: int) -> None:
    """Serve rerun's own web viewer on 127.0.0.1:``port`` (returns at once; the server lives with
    the process). :mod:`finaldrive.service.web.viewer` copies the files from it."""
    rr.serve_web_viewer(web_port=port, open_browser=False)
