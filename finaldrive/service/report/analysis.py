"""What a paper-study found, computed from its stored evaluations (pure; no I/O).

Everything returned is JSON-ready and rounded (``_r``), so the report files are stable.
Definitions (stated in the report too):

- per road: the DE optimum (best successful DE evaluation; ties to the earliest slot),
  the sweep's best and the spread of sweep distance (max - min, and p95 - p5);
- the robust design: the Table 9 grid design with the best mean fitness over all roads
  (free: read from the stored sweep; a design that failed on any road is excluded), and
  its regret on each road against that road's own optimum (the best of DE and sweep);
- the sharpness of each road's optimum: the near-optimal set, every successful evaluation of the
  road (sweep and DE) within 0.1 % of the best fitness, with each variable's range over it;
- conclusion checks: spread vs road height (Spearman rank correlation), optimum L2 vs the
  range, optimum direction vs the swingarm line (phi0), geometry 1 vs geometry 2.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
from scipy.stats import spearmanr

from finaldrive.engine import (
    DEFAULT_TOLERANCE_PCT,
    PRESETS,
    Road,
    aggregate,
    best_distinct,
    near_optimal,
    numerical_bands,
    regret,
    tie_flags,
)
from finaldrive.service.report.data import StudyData
from finaldrive.service.report.table14 import study_settings

#: ``step`` of the sweep part of a paper-study (service.jobs.drivers.SWEEP_STEP).
SWEEP_STEP = -1
#: Swingarm design angle phi0 of the default vehicle [deg] (3.316 rad).
PHI0_DEG = math.degrees(3.316)
#: Thresholds of the verdicts (stated in the report).
CLOSE_L2_FRACTION = 0.25      # "close to the pivot": median optimum L2 <= 25 % of the L2 range
ALIGNED_DEG = 20.0            # "aligned": median angle to the swingarm line <= 20 deg
SPREAD_RHO = 0.5              # spread grows with road height: Spearman rho >= 0.5
GAIN_BAND_PCT = (1.0, 3.0)    # "about 2 %": geometry 1 ahead by 1-3 %


def _r(x: float | None, nd: int = 6) -> float | None:
    """A finite float rounded to ``nd`` decimals (-0.0 -> 0.0), else None."""
    if x is None or not math.isfinite(float(x)):
        return None
    v = round(float(x), nd)
    return 0.0 if v == 0 else v


def wrap_deg(a: float) -> float:
    """An angle in [0, 360) deg."""
    return float(a) % 360.0


def alignment_deg(a2_deg: float, phi0_deg: float = PHI0_DEG) -> float:
    """Angle [0, 90] deg between the direction a2 and the swingarm line (phi0 or phi0 - 180)."""
    d = abs((a2_deg - phi0_deg + 180.0) % 360.0 - 180.0)
    return min(d, 180.0 - d)


def offset_mm(a2_deg: float, l2_m: float, phi0_deg: float = PHI0_DEG) -> float:
    """Distance of the engine sprocket axis from the swingarm line [mm]."""
    return 1000.0 * l2_m * abs(math.sin(math.radians(a2_deg - phi0_deg)))


def road_height(spec: str) -> float:
    """H_y of a road spec (0 for flat)."""
    parts = spec.split(":")
    return 0.0 if parts[0] == "flat" else float(parts[1])


def road_slope(spec: str) -> float:
    """Largest slope of a road: 2 pi H / lambda (sine), H e^-1/2 / sigma (bump), 0 (flat)."""
    parts = spec.split(":")
    if parts[0] == "sine":
        return 2 * math.pi * float(parts[1]) / float(parts[2])
    if parts[0] == "bump":
        return float(parts[1]) * math.exp(-0.5) / float(parts[2])
    return 0.0


def _design(e: dict[str, np.ndarray], i: int) -> dict[str, Any]:
    return {
        "a2_deg": _r(wrap_deg(e["a2_deg"][i]), 3), "l2_m": _r(e["l2_m"][i], 5),
        "rws_m": _r(e["rws_m"][i], 5), "slack_m": _r(e["slack_m"][i], 7),
        "squat_ratio": _r(e["squat_ratio"][i], 4), "fitness_m": _r(e["fitness_m"][i], 4),
        "distance_m": _r(e["distance_m"][i], 4),
    }


def _best(e: dict[str, np.ndarray], mask: np.ndarray) -> int | None:
    """Index of the best successful evaluation in ``mask`` (first slot on ties)."""
    idx = np.flatnonzero(mask & e["ok"] & np.isfinite(e["fitness_m"]))
    return None if idx.size == 0 else int(idx[np.argmax(e["fitness_m"][idx])])


def sweep_table(data: StudyData) -> tuple[np.ndarray, np.ndarray]:
    """(designs (n, 3) by grid row, fitness (n_roads, n) with NaN where failed or missing)."""
    e = data.evals
    sweep = e["step"] == SWEEP_STEP
    n = int(e["candidate"][sweep].max()) + 1 if sweep.any() else 0
    designs = np.full((n, 3), np.nan)
    fitness = np.full((len(data.roads), n), np.nan)
    for i in np.flatnonzero(sweep):
        c = e["candidate"][i]
        designs[c] = (e["a2"][i], e["l2_m"][i], e["rws_m"][i])
        if e["ok"][i]:
            fitness[e["road_index"][i], c] = e["fitness_m"][i]
    return designs, fitness


def de_history(data: StudyData, road: int, np_size: int) -> list[dict[str, Any]]:
    """Per DE generation of a road (0 = the initial population, as the optimiser and the API's
    /history count): best and mean fitness of the population, i.e. of the ``np_size`` best
    successful evaluations so far ((mu + lambda) selection), and evaluations so far."""
    e = data.evals
    on_road = (e["road_index"] == road) & (e["step"] >= 0)
    out: list[dict[str, Any]] = []
    for g in np.unique(e["step"][on_road]):
        upto = on_road & (e["step"] <= g)
        f = np.sort(e["fitness_m"][upto & e["ok"]])[::-1][:np_size]
        out.append({"generation": int(g), "n_evals": int(upto.sum()),
                    "best_fitness_m": _r(float(f[0]) if f.size else None, 6),
                    "mean_fitness_m": _r(float(f.mean()) if f.size else None, 6)})
    return out


def de_population(data: StudyData, road: int, np_size: int) -> np.ndarray:
    """The final DE population of a road, (n, 4) rows a2, L2, R_WS, fitness: its ``np_size``
    best successful evaluations ((mu + lambda) selection keeps exactly those)."""
    e = data.evals
    idx = np.flatnonzero((e["road_index"] == road) & (e["step"] >= 0) & e["ok"])
    order = idx[np.lexsort((idx, -e["fitness_m"][idx]))][:np_size]
    return np.stack([e["a2"][order], e["l2_m"][order], e["rws_m"][order], e["fitness_m"][order]], axis=1)


def per_road(data: StudyData) -> list[dict[str, Any]]:
    """One record a road: paper row, DE optimum, sweep best and spread, counts."""
    e = data.evals
    out = []
    for r, (name, spec) in enumerate(data.roads):
        on_road = e["road_index"] == r
        sweep, de = on_road & (e["step"] == SWEEP_STEP), on_road & (e["step"] >= 0)
        d = e["distance_m"][sweep & e["ok"]]
        i_de, i_sw = _best(e, de), _best(e, sweep)
        preset = PRESETS.get(spec)
        paper = None if preset is None or preset.paper is None else {
            k: _r(v, 7 if k == "slack_m" else 4) for k, v in sorted(preset.paper.items())}  # slack: to the um
        out.append({
            "index": r, "name": name, "spec": spec, "height_m": _r(road_height(spec), 4),
            "max_slope": _r(road_slope(spec), 5), "paper": paper,
            "de_best": None if i_de is None else _design(e, i_de),
            "de_evals": int(de.sum()), "de_failed": int((de & ~e["ok"]).sum()),
            "sweep_best": None if i_sw is None else _design(e, i_sw),
            "near_optimal": _near(e, on_road & e["ok"]),
            "sweep_evals": int(sweep.sum()), "sweep_failed": int((sweep & ~e["ok"]).sum()),
            "sweep_distance": None if d.size == 0 else {
                "min_m": _r(d.min(), 4), "max_m": _r(d.max(), 4),
                "spread_m": _r(d.max() - d.min(), 4),
                "p5_m": _r(np.percentile(d, 5), 4), "p95_m": _r(np.percentile(d, 95), 4),
                "spread_p5_p95_m": _r(np.percentile(d, 95) - np.percentile(d, 5), 4),
            },
        })
    return out


def add_bands(data: StudyData, roads: list[dict[str, Any]]) -> None:
    """Each road's numerical band (engine.study.band) of its best successful evaluation (sweep or DE)
    and of the next best distinct designs, with which tie with it: ``numerical_band`` and ``ties``."""
    settings, vehicle = study_settings(data.spec)
    e = data.evals
    for r in roads:
        mask = (e["road_index"] == r["index"]) & e["ok"]
        designs = np.stack([e["a2"][mask], e["l2_m"][mask], e["rws_m"][mask]], axis=1)
        rows = designs[best_distinct(designs, e["fitness_m"][mask])]
        bands = numerical_bands(rows, Road.parse(r["spec"]), settings, vehicle) if len(rows) else []
        r["numerical_band"] = _band(bands[0]) if bands else None
        r["ties"] = [{"a2_deg": _r(math.degrees(x[0]) % 360.0, 4), "l2_m": _r(x[1], 6), "rws_m": _r(x[2], 6),
                      **_band(b), "tie": tie} for x, b, tie in zip(rows, bands, tie_flags(bands), strict=True)]


def _band(band: dict[str, Any]) -> dict[str, Any]:
    """A band rounded as the report rounds (to the 0.1 um; fitness and distance to the 10 um)."""
    return {"fitness_m": _r(band["fitness_m"], 5), "distance_m": _r(band["distance_m"], 5),
            "band_m": _r(band["band_m"], 7), "distance_band_m": _r(band["distance_band_m"], 7),
            "exceeds_limit": band["exceeds_limit"], "failed": band["failed"]}


def _near(e: dict[str, np.ndarray], mask: np.ndarray) -> dict[str, Any]:
    """The near-optimal set of the evaluations in ``mask`` (engine study.sharpness), rounded."""
    designs = np.stack([e["a2"][mask], e["l2_m"][mask], e["rws_m"][mask]], axis=1)
    near = near_optimal(designs, e["fitness_m"][mask], e["distance_m"][mask], DEFAULT_TOLERANCE_PCT)
    for key in ("ranges", "explored"):
        near[key] = {k: [_r(v, 5) for v in pair] for k, pair in near.get(key, {}).items()}
    near["tolerance_m"] = _r(near.get("tolerance_m"), 5)
    near["best_fitness_m"] = _r(near.get("best_fitness_m"), 5)
    return near


def robust(data: StudyData, roads: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The grid design with the best mean fitness over all roads, and its regret per road."""
    designs, fitness = sweep_table(data)
    if fitness.size == 0:
        return None
    score = aggregate(fitness, "mean")
    if not np.isfinite(score).any():
        return None
    c = int(np.nanargmax(score))
    optimum = np.array([
        max((x["fitness_m"] for x in (r["de_best"], r["sweep_best"]) if x and x["fitness_m"] is not None),
            default=math.nan)
        for r in roads
    ])
    loss = regret(fitness[:, c], optimum)
    a2, l2, rws = designs[c]
    return {
        "method": "best mean fitness over the stored Table 9 sweep grid (no extra simulations)",
        "candidate": c, "a2_deg": _r(wrap_deg(math.degrees(a2)), 3), "l2_m": _r(l2, 5), "rws_m": _r(rws, 5),
        "mean_fitness_m": _r(score[c], 4), "n_valid_designs": int(np.isfinite(score).sum()),
        "per_road": [
            {"name": r["name"], "fitness_m": _r(fitness[i, c], 4), "optimum_m": _r(optimum[i], 4),
             "regret_m": _r(loss.absolute_m[i], 4), "regret_pct": _r(loss.percent[i], 3)}
            for i, r in enumerate(roads)
        ],
        "max_regret_pct": _r(np.nanmax(loss.percent), 3), "mean_regret_pct": _r(np.nanmean(loss.percent), 3),
    }


def _spearman(x: list[float], y: list[float]) -> float | None:
    if len(x) < 3 or len(set(x)) < 2 or len(set(y)) < 2:
        return None
    return _r(float(spearmanr(x, y).statistic), 3)


def conclusions(
    roads: list[dict[str, Any]], table14: dict[str, Any] | None, l2_range: tuple[float, float]
) -> dict[str, Any]:
    """The three checks of the paper's conclusions, with their numbers and verdicts."""
    sp = [r for r in roads if r["sweep_distance"]]
    heights = [r["height_m"] for r in sp]
    spreads = [r["sweep_distance"]["spread_m"] for r in sp]
    by_height: dict[str, float] = {}
    for h in sorted(set(heights)):
        vals = [s for s, hh in zip(spreads, heights, strict=True) if hh == h]
        by_height[f"{h:g}"] = _r(float(np.mean(vals)), 4)  # type: ignore[assignment]
    rho = _spearman(heights, spreads)
    rho_p = _spearman(heights, [r["sweep_distance"]["spread_p5_p95_m"] for r in sp])
    rho_slope = _spearman([r["max_slope"] for r in sp], spreads)
    levels = list(by_height.values())
    monotone = all(b >= a for a, b in itertools.pairwise(levels)) if len(levels) > 1 else None
    c1 = {
        "spread_by_height_m": by_height, "spearman_height_spread": rho,
        "spearman_height_spread_p5_p95": rho_p, "spearman_slope_spread": rho_slope,
        "mean_spread_increases_with_height": monotone,
        "holds": None if rho is None else bool(rho >= SPREAD_RHO),
    }

    def position(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
        if not rows:
            return None
        l2 = np.array([x["l2_m"] for x in rows])
        a2 = [x["a2_deg"] for x in rows]
        dev = np.array([alignment_deg(a) for a in a2])
        off = np.array([offset_mm(a, l) for a, l in zip(a2, l2, strict=True)])
        return {
            "n": len(rows), "median_l2_m": _r(np.median(l2), 4), "max_l2_m": _r(l2.max(), 4),
            "share_l2_le_0.04_m": _r(float(np.mean(l2 <= 0.04)), 3),
            "median_angle_to_swingarm_deg": _r(np.median(dev), 2),
            "share_within_20_deg": _r(float(np.mean(dev <= ALIGNED_DEG)), 3),
            "median_offset_from_swingarm_line_m": _r(np.median(off) / 1000.0, 5),
        }

    ours = position([r["de_best"] for r in roads if r["de_best"]])
    paper = position([r["paper"] for r in roads if r["paper"]])
    span = l2_range[1] - l2_range[0]
    c2 = {
        "ours": ours,
        "paper": paper,
        "l2_range_m": [l2_range[0], l2_range[1]],
        "phi0_deg": _r(PHI0_DEG, 3),
        "close_holds": None if ours is None else bool(ours["median_l2_m"] <= l2_range[0] + CLOSE_L2_FRACTION * span),
        "aligned_holds": None if ours is None else bool(ours["median_angle_to_swingarm_deg"] <= ALIGNED_DEG),
    }
    c3: dict[str, Any] = {"holds": None}
    if (
        table14 is not None
        and table14["ours"]["geometry1"]["distance_m"]
        and table14["ours"]["geometry2"]["distance_m"]
    ):
        gain = table14["ours"]["gain_pct"]
        c3 = {"gain_pct": gain, "paper_gain_pct": table14["paper"]["gain_pct"],
              "holds": bool(gain is not None and GAIN_BAND_PCT[0] <= gain <= GAIN_BAND_PCT[1])}
    return {"spread_vs_roughness": c1, "position": c2, "geometry_gain": c3}


def fitness_vs_paper(roads: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Our DE optimum's fitness minus the paper's, over the roads with a paper row."""
    diffs = [r["de_best"]["fitness_m"] - r["paper"]["fitness_m"] for r in roads if r["paper"] and r["de_best"]]
    if not diffs:
        return None
    d = np.array(diffs)
    return {"n": len(diffs), "mean_m": _r(d.mean(), 4), "min_m": _r(d.min(), 4), "max_m": _r(d.max(), 4),
            "mean_abs_m": _r(np.abs(d).mean(), 4)}


def run_stats(data: StudyData) -> dict[str, Any]:
    """Counts, wall time and rates of the job."""
    e = data.evals
    simulated = int((~e["cached"]).sum())
    wall = data.wall_s
    sim_s = float(e["wall_s"][~e["cached"]].sum())
    return {
        "state": data.state,
        "total_planned": data.total,
        "stored": int(e["ok"].size),
        "ok": int(e["ok"].sum()),
        "failed": int((~e["ok"]).sum()),
        "cached": int(e["cached"].sum()),
        "simulated": simulated,
        "created_at": _time(data.created_at),
        "started_at": _time(data.started_at),
        "finished_at": _time(data.finished_at),
        "wall_s": _r(wall, 1),
        "simulations_per_s": _r(simulated / wall, 1) if wall else None,
        "simulation_cpu_s": _r(sim_s, 1),
        "mean_ms_per_simulation": _r(1000 * sim_s / simulated, 2) if simulated else None,
    }


def _time(t: Any) -> str | None:
    return None if t is None else t.strftime("%Y-%m-%d %H:%M:%S UTC")
