"""PNG plots of results (matplotlib, Agg canvas, no pyplot: safe in server threads).

The only module that imports matplotlib. Designs are rows (a2 [rad], L2 [m], R_WS [m]).
Polar maps follow the paper's Figs. 9-11: the engine sprocket axis around the swingarm
pivot, angle a2 (from the chassis x axis, 0 deg = forward; the model's definition) and
radius L2, with the swingarm at its design angle phi0 - theta0 drawn as a line.
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

from finaldrive.engine import default_vehicle
from finaldrive.service.scene import ROW_OFFSET_M

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


def _save(fig: Figure, path: str | Path) -> None:
    FigureCanvasAgg(fig)
    fig.savefig(str(path), dpi=_DPI)


def _polar_axes(fig: Figure, rect: Any = 111) -> PolarAxes:
    """Polar axes, a2 = 0 (forward) pointing right, counter-clockwise."""
    ax = cast(PolarAxes, fig.add_subplot(rect, projection="polar"))
    ax.set_theta_zero_location("E")
    ax.set_theta_direction(1)
    return ax


def _swingarm(ax: Axes, r_max: float) -> None:
    v = default_vehicle()
    angle = v["phi0"] - v["theta0"]
    ax.plot([angle, angle], [0.0, r_max], color="black", lw=3, solid_capstyle="butt",
            label=f"swingarm (to the rear axle, {math.degrees(angle):.0f}°)")
    ax.plot([0.0], [0.0], "o", color="black", ms=6)


def _mark_best(ax: Axes, best: tuple[float, float] | None, label: str = "best") -> None:
    if best is not None:
        a2, l2 = best
        ax.plot([a2], [l2], marker="*", color="white", mec="black", ms=18, ls="", label=f"{label}: a2 = "
                f"{math.degrees(a2) % 360:.0f}°, L2 = {l2 * 1000:.0f} mm")


def sweep_map_png(path: str | Path, designs: np.ndarray, values: np.ndarray, *, title: str,
                  value_label: str = "distance [m]", best: tuple[float, float] | None = None,
                  best_label: str = "best") -> None:
    """A sweep's values over the engine sprocket position (polar a2, L2), as Figs. 9-11.

    Failed designs (NaN) are left blank. With several R_WS per (a2, L2) the highest value
    is shown. ``best`` is (a2 [rad], L2 [m]).
    """
    designs = np.asarray(designs, dtype=float).reshape(-1, 3)
    values = np.asarray(values, dtype=float)
    fig = Figure(figsize=(7.2, 6.4))
    ax = _polar_axes(fig)
    a2s, a2_idx = np.unique(np.round(designs[:, 0] % (2 * math.pi), 9), return_inverse=True)
    l2s, l2_idx = np.unique(np.round(designs[:, 1], 9), return_inverse=True)
    grid = np.full((len(l2s), len(a2s)), np.nan)
    for i, j, v in zip(l2_idx, a2_idx, values, strict=True):
        if np.isfinite(v) and not v <= grid[i, j]:
            grid[i, j] = v
    mappable: Any
    if len(a2s) > 1 and len(l2s) > 1 and np.isfinite(grid).sum() >= 0.5 * grid.size:
        mappable = ax.pcolormesh(_edges(a2s, periodic=True), _edges(l2s), np.ma.masked_invalid(grid),
                                 cmap="viridis", shading="flat")
    else:  # scattered designs (e.g. a DE population or a coarse grid)
        ok = np.isfinite(values)
        mappable = ax.scatter(
            designs[ok, 0], designs[ok, 1], c=values[ok], cmap="viridis", s=40, edgecolors="k", lw=0.3
        )
        if not ok.all():
            ax.scatter(designs[~ok, 0], designs[~ok, 1], marker="x", color="red", s=25, label="failed")
    r_max = max(float(designs[:, 1].max()), 1e-3) * 1.05
    ax.set_ylim(0, r_max)
    _swingarm(ax, r_max)
    _mark_best(ax, best, best_label)
    ax.set_xlabel("a2 [deg] (0° = forward)   ·   radius: L2 [m]")
    ax.set_rlabel_position(112)
    fig.colorbar(mappable, ax=ax, label=value_label, pad=0.1, shrink=0.8)
    ax.legend(loc="upper left", bbox_to_anchor=(-0.12, 1.12), fontsize=8, framealpha=0.9)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.08, right=0.95, bottom=0.12, top=0.88)
    _save(fig, path)


def _edges(centres: np.ndarray, periodic: bool = False) -> np.ndarray:
    """Cell edges around sorted centres (a periodic axis closes the circle)."""
    if len(centres) == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    if periodic:
        ext = np.concatenate([[centres[-1] - 2 * math.pi], centres, [centres[0] + 2 * math.pi]])
        return np.asarray(0.5 * (ext[:-1] + ext[1:]), dtype=float)
    mid = 0.5 * (centres[:-1] + centres[1:])
    return np.concatenate([[max(0.0, 2 * centres[0] - mid[0])], mid, [2 * centres[-1] - mid[-1]]]).astype(float)


def de_history_png(path: str | Path, history: list[dict[str, Any]], population: np.ndarray, *, title: str) -> None:
    """Best and mean fitness per generation (left) and the final population on the polar map (right).

    ``history`` holds generation records in the outputs' names (``finaldrive.engine.history_record``):
    ``generation``, ``best_fitness_m``, ``mean_fitness_m``;
    ``population`` is (n, 3), or (n, 4) with the fitness as fourth column (used for colour).
    """
    population = np.asarray(population, dtype=float)
    fig = Figure(figsize=(12, 5.2))
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
    else:
        pax.scatter(population[:, 0], population[:, 1], s=45, edgecolors="k", lw=0.3, label="designs")
    pax.set_ylim(0, r_max)
    pax.set_rlabel_position(112)
    _swingarm(pax, r_max)
    pax.set_xlabel("final population: a2 [deg], radius L2 [m]")
    pax.legend(loc="upper left", bbox_to_anchor=(-0.25, 1.15), fontsize=8)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.07, right=0.95, bottom=0.15, top=0.85, wspace=0.3)
    _save(fig, path)


def _num(v: Any) -> float:
    return math.nan if v is None else float(v)


def series_png(path: str | Path, runs: list[tuple[str, Mapping[str, np.ndarray]]], *, title: str) -> None:
    """Fig. 13: distance, chain tension, SR, Fz, slip and Fx against time, one line per run."""
    fig = Figure(figsize=(11, 8.5))
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
    .rrd by service.recording.scene_at); geometries keep the recording's vertical offsets."""
    colours = ("tab:blue", "tab:red", "tab:green", "tab:purple")
    fig = Figure(figsize=(11, 6.5))
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
