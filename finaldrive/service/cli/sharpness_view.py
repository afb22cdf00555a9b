"""Human text of an optimum's sharpness (engine study.sharpness): near-optimal set, sensitivities, spreads."""

from __future__ import annotations

import math
from typing import Any


def spread_text(s: dict[str, list[float]]) -> str:
    """Ranges of a2 [deg], L2 and R_WS [mm] and the fitness [m]."""
    lo, hi = s["a2_deg"]
    if lo is None or math.isnan(lo):
        a2 = "a2 any (L2 = 0)"
    else:
        a2 = f"a2 {lo:.0f} to {hi:.0f} deg" if hi < 360 else f"a2 {lo:.0f} through 0 to {hi - 360:.0f} deg"
    parts = [a2,
             f"L2 {1000 * s['l2_m'][0]:.1f} to {1000 * s['l2_m'][1]:.1f} mm",
             f"R_WS {1000 * s['rws_m'][0]:.1f} to {1000 * s['rws_m'][1]:.1f} mm"]
    if "fitness_m" in s:
        parts.append(f"fitness {s['fitness_m'][0]:.3f} to {s['fitness_m'][1]:.3f} m")
    return ", ".join(parts)


def near_lines(near: dict[str, Any], indent: str = "  ") -> list[str]:
    """The near-optimal set: its size and one sentence a variable (decided or not)."""
    if not near.get("count"):
        return [f"{indent}near-optimal set: none (no successful evaluation)"]
    head = (f"{indent}near-optimal set: {near['count']} of {near['evaluated']} evaluated designs within "
            f"{1000 * near['tolerance_m']:.3g} mm ({near['tolerance_pct']:g} %) of the best fitness "
            f"{near['best_fitness_m']:.3f} m: {spread_text(near['ranges'])}")
    return [head, *(f"{indent}  {s}" for s in near["sentences"])]


def sensitivity_lines(s: dict[str, Any] | None, tolerance_m: float, indent: str = "  ") -> list[str]:
    from finaldrive.engine import sensitivity_sentences

    if s is None:
        return []
    schemes = sorted(set(s["schemes"].values()))
    head = (f"{indent}sensitivity at the best ({s['simulations']} simulations, {' and '.join(schemes)} "
            f"differences; fitness {s['fitness_m']:.3f} m, distance {s['distance_m']:.3f} m):")
    return [head, *(f"{indent}  {line}" for line in sensitivity_sentences(s, tolerance_m))]


def sharpness_lines(sharp: dict[str, Any]) -> list[str]:
    """Everything the study reported on its optimum's sharpness."""
    near = sharp["near_optimal"]
    lines = ["sharpness:", *near_lines(near)]
    lines += sensitivity_lines(sharp.get("sensitivity"), near.get("tolerance_m", 0.0))
    if sharp.get("sensitivity") is None and sharp.get("sensitivity_note"):
        lines.append(f"  sensitivity: {sharp['sensitivity_note']}")
    pop = sharp.get("final_population")
    if pop:
        lines.append(f"  final DE population ({pop['count']} designs): {spread_text(pop['ranges'])}")
    rep = sharp.get("repeats")
    if rep:
        lines.append(f"  {len(rep['optima'])} seeds ({', '.join(str(o['seed']) for o in rep['optima'])}): optima "
                     f"{spread_text(rep['spread'])}")
        lines += [f"    seed {o['seed']}: a2 {o['a2_deg']:.1f} deg, L2 {1000 * o['l2_m']:.1f} mm, "
                  f"R_WS {1000 * o['rws_m']:.1f} mm, fitness {o['fitness_m']:.3f} m" for o in rep["optima"]]
    return lines


def band_lines(band: dict[str, Any], ties: list[dict[str, Any]], *, what: str = "fitness",
               indent: str = "  ") -> list[str]:
    """A best's numerical band, and how many of the next best designs tie with it (engine.study.band)."""
    how = "re-simulated 100x tighter" + (" and with the reference method" if "reference" in band.get("runs", {})
                                         else "")
    left_out = band.get("failed", {}) if band["band_m"] is not None else {}
    how += "".join(f"; {label} left out: {why}" for label, why in left_out.items())
    lines = [f"{indent}numerical band of the best's {what}: {band_text(band)} ({how})"]
    if len(ties) > 1:
        tied = sum(t["tie"] for t in ties[1:])
        lines.append(f"{indent}  of the next {len(ties) - 1} best designs, {tied} tie with it (fitness closer than "
                     "the two bands together)" + (": the numerics do not decide between them" if tied else ""))
    return lines


def model_band_lines(bands: dict[str, Any], indent: str = "  ") -> list[str]:
    """A road's best designs under each modelling alternative (engine.study.model_band): the rank
    correlation with the model as given, whether the best stays the best, the largest change."""
    lines = [f"{indent}model bands of its {len(bands['designs'])} best distinct designs (rank correlation with the "
             "model as given; the same best?; the largest change of a fitness):"]
    for name, alt in bands["alternatives"].items():
        rho = "-" if alt["rank_correlation"] is None else f"{alt['rank_correlation']:+.2f}"
        change = "-" if alt["largest_change_m"] is None else (
            f"{alt['largest_change_m'] * 1000:.1f} mm" if alt["largest_change_m"] < 1.0
            else f"{alt['largest_change_m']:.3f} m")
        failed = sum(bool(f) for f in alt["failed"])
        which = "same best" if alt["same_best"] else "another best" if alt["best"] is not None else "none succeeded"
        lines.append(f"{indent}  {name:<22} {rho:>6}  {which:<14} "
                     f"{change}" + (f"  ({failed} failed)" if failed else ""))
    if bands["skipped"]:
        lines.append(f"{indent}  left out: " + "; ".join(f"{name} ({bands['skipped_reasons'].get(name, '')})"
                                                         for name in bands["skipped"]))
    return lines


def band_text(band: dict[str, Any]) -> str:
    """A band as people read it: +-x mm, flagged above 1 mm, or why it is unknown."""
    if band["band_m"] is None:
        return "unknown (a re-run failed: " + "; ".join(f"{k}: {v}" for k, v in band.get("failed", {}).items()) + ")"
    flag = ", wider than 1 mm" if band["exceeds_limit"] else ""
    return f"+-{band['band_m'] * 1000:.2f} mm{flag}"
