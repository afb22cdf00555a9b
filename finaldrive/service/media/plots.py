"""PNG plots of results (matplotlib, Agg canvas, no pyplot: safe in server threads).

The only module that imports matplotlib. Designs are rows (a2 [rad], L2 [m], R_WS [m]).
Polar maps follow the paper's Figs. 9-11: the engine sprocket axis around the swingarm
pivot, angle a2 (from the chassis x axis, 0 deg = forward; the model's definition) and
radius L2, with the swingarm at static sag drawn as a line (as the dashboard's map).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.projections.polar import PolarAxes
from matplotlib.text import Text
from matplotlib.ticker import MaxNLocator

from finaldrive.engine import Design, Vehicle, default_vehicle, static_geometry
from finaldrive.service.media.scene import ROW_OFFSET_M

#: Fig. 13 panels: (series key, axis label).
SERIES_PANELS: tuple[tuple[str, str], ...] = (
    ("distance_m", "distance [m]"),
    ("chain_tension_n", "chain tension [N]"),
    ("squat_ratio", "squat ratio SR [-]"),
    ("fz_rear_n", "rear vertical force Fz [N]"),
    ("kappa", "rear longitudinal slip κ [-]"),
    ("fx_n", "rear longitudinal force Fx [N]"),
)
_DPI = 110


#: The polar maps' radial (L2) labels: their size [pt], and no label closer to the pivot than this share of the
#: map's radius (the designs crowd there).
RADIAL_LABEL_PT = 10.0
RADIAL_LABEL_CLEAR = 0.2
#: the white box around a radial label, beyond the text [in the font's size]
RADIAL_LABEL_PAD = 0.25


def _figure(figsize: tuple[float, float]) -> Figure:
    """A figure on an Agg canvas (its renderer measures text before it is saved)."""
    fig = Figure(figsize=figsize, dpi=_DPI)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | Path) -> None:
    fig.savefig(str(path), dpi=_DPI)


def _polar_axes(fig: Figure, rect: Any = 111) -> PolarAxes:
    """Polar axes, a2 = 0 (forward) pointing right, counter-clockwise."""
    ax = cast(PolarAxes, fig.add_subplot(rect, projection="polar"))
    ax.set_theta_zero_location("E")
    ax.set_theta_direction(1)
    return ax


def swingarm_at_sag_deg(vehicle: Vehicle | None = None, design: Design | None = None) -> float:
    """The swingarm's direction at static sag on flat ground (the engine's equilibrium; pivot to rear axle,
    in a2's frame), as the dashboard's map draws it: at ``design``, by default the vehicle's calibration
    design (over the paper's design space it moves by about a thousandth of a degree). Where the engine
    finds no equilibrium for them, the vehicle's design angle phi0 - theta0."""
    v = vehicle or default_vehicle()
    try:
        d = design or Design.from_deg(v["calibration_a2_deg"], v["calibration_l2"], v["calibration_rws"])
        return float(static_geometry(d, v)["swingarm_angle_deg"])
    except (ValueError, ArithmeticError):
        return math.degrees(v["phi0"] - v["theta0"])


def _swingarm(ax: Axes, r_max: float, swingarm_deg: float | None) -> float:
    """The swingarm at static sag (:func:`swingarm_at_sag_deg` unless given), from the pivot; returns its
    angle [rad]."""
    angle = math.radians(swingarm_at_sag_deg() if swingarm_deg is None else swingarm_deg)
    ax.plot([angle, angle], [0.0, r_max], color="black", lw=3, solid_capstyle="butt",
            label=f"swingarm at static sag, {math.degrees(angle):.1f}°")
    ax.plot([0.0], [0.0], "o", color="black", ms=6)
    return angle


def _radial_labels(fig: Figure, ax: PolarAxes, r_max: float, avoid: Sequence[float], markers: np.ndarray) -> None:
    """Legible L2 labels: four round rings or so, in mm, RADIAL_LABEL_PT dark text on a white box, none in the
    crowd around the pivot; along a direction at least 45° from the angles ``avoid`` [rad] (the swingarm, the best
    design) whose boxes cover the fewest ``markers`` (rows a2 [rad], L2 [m]), mid-way between two spokes where that
    costs none. Measures the labels on the canvas: call it once the figure's layout is final."""
    rings = [float(r) for r in MaxNLocator(4).tick_values(0.0, r_max) if 0.0 < r <= r_max]
    labelled = [r for r in rings if r >= RADIAL_LABEL_CLEAR * r_max]
    texts = {r: f"{1000 * r:.4g} mm" for r in labelled}
    ax.set_yticks(rings, [texts.get(r, "") for r in rings])
    # the box's pad, a marker's radius (5 px) and 2 px for where each matplotlib puts the label (3.9 and 3.11 differ by
    # a px or two; with 6 px a label touched a marker under 3.9, with 8 px or more no direction is free in a test) [px]
    pad = RADIAL_LABEL_PAD * RADIAL_LABEL_PT * fig.dpi / 72.0 + 7.0
    half = []
    for r in labelled:
        probe = Text(0.0, 0.0, texts[r], fontsize=RADIAL_LABEL_PT)
        probe.set_figure(fig)
        extent = probe.get_window_extent()   # on the figure's canvas
        half.append([extent.width / 2 + pad, extent.height / 2 + pad])
    seen = ax.transData.transform(markers) if len(markers) else np.empty((0, 2))

    def rank(c: float) -> tuple[bool, int, bool, float]:
        clear = min((abs((math.degrees(a) - c + 180.0) % 360.0 - 180.0) for a in avoid), default=180.0)
        centres = ax.transData.transform(np.column_stack([np.full(len(labelled), math.radians(c)), labelled]))
        under = (np.abs(seen[:, None, :] - centres[None, :, :]) <= np.array(half)).all(axis=2).any(axis=1)
        return clear >= 45.0, -int(under.sum()), c % 45.0 == 22.5, clear   # then mid-way between spokes

    ax.set_rlabel_position(max((11.25 * k for k in range(32) if k % 4), key=rank))   # off the spokes (every 45°)
    ax.tick_params(axis="y", labelsize=RADIAL_LABEL_PT, labelcolor="0.1")
    for label in ax.get_yticklabels():   # centred on its ring: the outermost stays inside the rim
        label.set(horizontalalignment="center", verticalalignment="center", bbox={
            "boxstyle": f"round,pad={RADIAL_LABEL_PAD}", "facecolor": "white", "edgecolor": "none", "alpha": 0.85})


def _mark_best(ax: Axes, best: tuple[float, float] | None, label: str = "best") -> None:
    if best is not None:
        a2, l2 = best
        ax.plot([a2], [l2], marker="*", color="white", mec="black", ms=18, ls="", label=f"{label}: a2 = "
                f"{math.degrees(a2) % 360:.0f}°, L2 = {l2 * 1000:.0f} mm")


def sweep_map_png(path: str | Path, designs: np.ndarray, values: np.ndarray, **kwargs: Any) -> None:
    """:func:`sweep_map_figure` as a PNG file."""
    _save(sweep_map_figure(designs, values, **kwargs), path)


def sweep_map_figure(designs: np.ndarray, values: np.ndarray, *, title: str, value_label: str = "distance [m]",
                     best: tuple[float, float] | None = None, best_label: str = "best",
                     near: np.ndarray | None = None, near_label: str = "near-optimal",
                     swingarm_deg: float | None = None) -> Figure:
    """A sweep's values over the engine sprocket position (polar a2, L2), as Figs. 9-11.

    Failed designs (NaN) are left blank. With several R_WS per (a2, L2) the highest value
    is shown. ``best`` is (a2 [rad], L2 [m]). ``near`` (a bool a design) outlines the
    near-optimal set: a red line around its cells on a grid, red rings on scattered designs.
    ``swingarm_deg``: the swingarm's line (default: :func:`swingarm_at_sag_deg`, the paper's vehicle).
    """
    designs = np.asarray(designs, dtype=float).reshape(-1, 3)
    values = np.asarray(values, dtype=float)
    fig = _figure((7.2, 6.4))
    ax = _polar_axes(fig)
    a2s, a2_idx = np.unique(np.round(designs[:, 0] % (2 * math.pi), 9), return_inverse=True)
    l2s, l2_idx = np.unique(np.round(designs[:, 1], 9), return_inverse=True)
    grid = np.full((len(l2s), len(a2s)), np.nan)
    for i, j, v in zip(l2_idx, a2_idx, values, strict=True):
        if np.isfinite(v) and not v <= grid[i, j]:
            grid[i, j] = v
    mappable: Any
    markers = designs[:, :2]   # what the radial labels should not cover
    if len(a2s) > 1 and len(l2s) > 1 and np.isfinite(grid).sum() >= 0.5 * grid.size:
        markers = markers[:0]   # cells cover the whole map: no direction is freer than another
        mappable = ax.pcolormesh(_edges(a2s, periodic=True), _edges(l2s), np.ma.masked_invalid(grid),
                                 cmap="viridis", shading="flat")
        if near is not None and near.any():
            inside = np.zeros(grid.shape, dtype=bool)
            inside[l2_idx[near], a2_idx[near]] = True
            _outline(ax, inside, _edges(a2s, periodic=True), _edges(l2s), near_label)
    else:  # scattered designs (e.g. a DE population or a coarse grid)
        ok = np.isfinite(values)
        mappable = ax.scatter(
            designs[ok, 0], designs[ok, 1], c=values[ok], cmap="viridis", s=40, edgecolors="k", lw=0.3
        )
        if not ok.all():
            ax.scatter(designs[~ok, 0], designs[~ok, 1], marker="x", color="red", s=25, label="failed")
        if near is not None and near.any():
            ax.scatter(designs[near, 0], designs[near, 1], s=110, facecolors="none", edgecolors="red", lw=1.4,
                       label=near_label)
    r_max = max(float(designs[:, 1].max()), 1e-3) * 1.05
    ax.set_ylim(0, r_max)
    swingarm = _swingarm(ax, r_max, swingarm_deg)
    _mark_best(ax, best, best_label)
    ax.set_xlabel("a2 [deg] (0° = forward)   ·   radius: L2")
    fig.colorbar(mappable, ax=ax, label=value_label, pad=0.1, shrink=0.8)
    # under the map, across the figure: above the map, a legend of long labels covered the 90° label
    fig.legend(*ax.get_legend_handles_labels(), loc="lower center", ncol=2, fontsize=8, framealpha=0.9)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.06, right=0.95, bottom=0.16, top=0.9)
    _radial_labels(fig, ax, r_max, [swingarm, *([best[0]] if best is not None else [])], markers)
    return fig


def _outline(ax: Axes, inside: np.ndarray, a_edges: np.ndarray, r_edges: np.ndarray, label: str) -> None:
    """Red line around the cells ``inside`` (rows: L2, columns: a2, periodic) of a polar grid."""
    n_r, n_a = inside.shape
    style: dict[str, Any] = {"color": "red", "lw": 1.6}
    for i, j in zip(*np.nonzero(inside), strict=True):
        arc = np.linspace(a_edges[j], a_edges[j + 1], 8)
        if i == 0 or not inside[i - 1, j]:
            ax.plot(arc, np.full(arc.size, r_edges[i]), **style)
        if i == n_r - 1 or not inside[i + 1, j]:
            ax.plot(arc, np.full(arc.size, r_edges[i + 1]), **style)
        if not inside[i, (j - 1) % n_a]:
            ax.plot([a_edges[j]] * 2, r_edges[i:i + 2], **style)
        if not inside[i, (j + 1) % n_a]:
            ax.plot([a_edges[j + 1]] * 2, r_edges[i:i + 2], **style)
    ax.plot([], [], label=label, **style)


def _edges(centres: np.ndarray, periodic: bool = False) -> np.ndarray:
    """Cell edges around sorted centres (a periodic axis closes the circle)."""
    if len(centres) == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    if periodic:
        ext = np.concatenate([[centres[-1] - 2 * math.pi], centres, [centres[0] + 2 * math.pi]])
        return np.asarray(0.5 * (ext[:-1] + ext[1:]), dtype=float)
    mid = 0.5 * (centres[:-1] + centres[1:])
    return np.concatenate([[max(0.0, 2 * centres[0] - mid[0])], mid, [2 * centres[-1] - mid[-1]]]).astype(float)


def de_history_png(path: str | Path, history: list[dict[str, Any]], population: np.ndarray, *, title: str,
                   swingarm_deg: float | None = None) -> None:
    """:func:`de_history_figure` as a PNG file."""
    _save(de_history_figure(history, population, title=title, swingarm_deg=swingarm_deg), path)


def de_history_figure(history: list[dict[str, Any]], population: np.ndarray, *, title: str,
                      swingarm_deg: float | None = None) -> Figure:
    """Best and mean fitness per generation (left) and the final population on the polar map (right).

    ``history`` holds generation records in the outputs' names (``finaldrive.engine.history_record``):
    ``generation``, ``best_fitness_m``, ``mean_fitness_m``;
    ``population`` is (n, 3), or (n, 4) with the fitness as fourth column (used for colour).
    """
    population = np.asarray(population, dtype=float)
    fig = _figure((12, 5.2))
    ax = fig.add_subplot(121)
    gens = [h["generation"] for h in history]
    ax.plot(gens, [_num(h.get("best_fitness_m")) for h in history], "o-", label="best fitness")
    ax.plot(gens, [_num(h.get("mean_fitness_m")) for h in history], "s--", label="mean fitness (finite)")
    ax.set_xlabel("generation (0 = initial population)")
    ax.set_ylabel("fitness [m]")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title("convergence")
    pax = _polar_axes(fig, 122)
    r_max = max(float(population[:, 1].max()) if len(population) else 0.0, 1e-3) * 1.1
    marked: list[float] = []
    if population.shape[1] >= 4:
        fit = population[:, 3]
        ok = np.isfinite(fit)
        sc = pax.scatter(population[ok, 0], population[ok, 1], c=fit[ok], cmap="viridis", s=45, edgecolors="k", lw=0.3)
        if not ok.all():
            pax.scatter(population[~ok, 0], population[~ok, 1], marker="x", color="red", s=30, label="failed")
        fig.colorbar(sc, ax=pax, label="fitness [m]", pad=0.12, shrink=0.8)
        if ok.any():
            b = int(np.nanargmax(np.where(ok, fit, -np.inf)))
            _mark_best(pax, (population[b, 0], population[b, 1]))
            marked.append(float(population[b, 0]))
    else:
        pax.scatter(population[:, 0], population[:, 1], s=45, edgecolors="k", lw=0.3, label="designs")
    pax.set_ylim(0, r_max)
    marked.append(_swingarm(pax, r_max, swingarm_deg))
    pax.set_xlabel("final population: a2 [deg], radius L2")
    pax.legend(loc="upper left", bbox_to_anchor=(-0.25, 1.15), fontsize=8)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.07, right=0.95, bottom=0.15, top=0.85, wspace=0.3)
    _radial_labels(fig, pax, r_max, marked, population[:, :2])
    return fig


def _num(v: Any) -> float:
    return math.nan if v is None else float(v)


def series_png(path: str | Path, runs: list[tuple[str, Mapping[str, np.ndarray]]], *, title: str) -> None:
    """Fig. 13: distance, chain tension, SR, Fz, slip and Fx against time, one line per run."""
    fig = _figure((11, 8.5))
    axes = fig.subplots(3, 2, sharex=True)
    for ax, (key, label) in zip(axes.ravel(), SERIES_PANELS, strict=True):
        for name, series in runs:
            ax.plot(series["t_s"], series[key], lw=1.2, label=name)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time t [s]")
    axes[0, 0].legend(fontsize=9)
    fig.suptitle(title)
    fig.tight_layout()
    _save(fig, path)


def scene_png(path: str | Path, strips: Mapping[str, Sequence[np.ndarray]],
              arrows: Sequence[tuple[np.ndarray, np.ndarray]], *, title: str, xlim: tuple[float, float]) -> None:
    """A recording's 2D scene at one instant (entity path -> line strips, as read back from the
    .rrd by service.media.recording.scene_at); geometries keep the recording's vertical offsets."""
    colours = ("tab:blue", "tab:red", "tab:green", "tab:purple")
    fig = _figure((11, 6.5))
    ax = fig.add_subplot(111)
    for entity, lines in sorted(strips.items()):
        parts = entity.split("/")  # /world/g<k>/<part>
        colour = "0.45" if parts[-1] == "road" else colours[(int(parts[2][1:]) - 1) % 4]
        width = 2.2 if parts[-1] in ("chassis", "swingarm") else 1.2
        for line in lines:
            ax.plot(line[:, 0], line[:, 1], color=colour, lw=width)
    for origins, vectors in arrows:
        for o, v in zip(origins, vectors, strict=True):
            ax.annotate("", xy=o + v, xytext=o, arrowprops={"arrowstyle": "->", "color": "tab:orange", "lw": 1.8})
    ax.set_xlim(*xlim)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel(f"y [m] (each geometry {ROW_OFFSET_M:g} m lower than the last)")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def travel_png(path: str | Path, travel: Mapping[str, Any], *, title: str) -> None:
    """Squat ratio, anti-squat and chain growth over the rear wheel travel (engine travel_kinematics),
    the design pose and the static sag marked."""
    curve = travel["curve"]
    x = [1000.0 * c["travel_m"] for c in curve]
    panels = (("squat_ratio", "squat ratio SR [-]", 1.0), ("anti_squat_pct", "anti-squat [%]", 1.0),
              ("chain_growth_m", "chain growth [mm]", 1000.0))
    fig = _figure((8, 8.5))
    axes = fig.subplots(3, 1, sharex=True)
    for ax, (key, label, scale) in zip(axes, panels, strict=True):
        ax.plot(x, [scale * c[key] for c in curve], color="tab:blue", lw=1.6)
        for mark, colour, name in (("design_pose", "tab:red", "design pose"),
                                   ("static_sag", "tab:green", "static sag")):
            m = travel[mark]
            ax.plot([1000.0 * m["travel_m"]], [scale * m[key]], "o", color=colour, label=name)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=9)
    axes[-1].set_xlabel("rear wheel travel from full extension [mm]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path)
