"""The paper-study report dict (service.report.build) as markdown; fixed float formats only."""

from __future__ import annotations

from typing import Any

from finaldrive.service.report import analysis as A

_HOW = """\
Produced by the tool, not by hand. The study ran through the job service:

```sh
finaldrive db upgrade --db sqlite:///./finaldrive.db
finaldrive serve --db sqlite:///./finaldrive.db &              # a local Ray on all cores (the default executor)
finaldrive study paper --server http://127.0.0.1:8000          # submits kind "paper-study", follows progress
finaldrive report paper-study {job} --out docs/paper-study.md --db sqlite:///./finaldrive.db
```

`finaldrive study paper --local` runs the same job in-process. Re-running either command
resumes the same job (same Idempotency-Key); re-running the report on the stored study
rewrites this file byte for byte."""


def _f(x: float | None, fmt: str = ".3f") -> str:
    return "–" if x is None else format(x, fmt)


def _signed(x: float) -> str:
    """``+.3f`` without a negative zero."""
    return format(round(x, 3) + 0.0, "+.3f")


def _yes(v: bool | None) -> str:
    return "not computable" if v is None else ("**holds**" if v else "**does not hold**")


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return [*lines, ""]


def render(rep: dict[str, Any], figs: dict[str, str]) -> str:
    """The whole document; ``figs`` maps figure keys (``map:i``, ``de:i``, ``table14``) to relative paths."""
    job, run, spec = rep["job"], rep["run"], rep["job"]["spec"]
    s, de = spec["settings"], spec["de"]
    out = [
        f"# Paper study (job {job['id']}): Table 9 sweep and Table 10 DE on {len(job['roads'])} roads", "",
        _HOW.format(job=job["id"]), "",
        f"Spec: grid `{spec['grid']}`; {_optimiser(de)}, seed {spec['seed']} "
        f"(road i: seed + i); simulation {s['duration']:g} s, method `{s['method']}`, dt {s['dt']:g} s; "
        f"vehicle: {'the paper' + chr(39) + 's (engine/data/vehicle.json)' if spec['vehicle'] is None else 'custom'}.",
        "",
        *_run(run, rep["machine"]),
        *_conclusions(rep),
        *_roads(rep["roads"], rep["fitness_vs_paper"]),
        *_sweep(rep["roads"], figs),
        *_sharpness(rep["roads"]),
        *_table14(rep["table14"], figs),
        *_robust(rep["robust"]),
        *_de_figures(rep["roads"], figs),
    ]
    return "\n".join(out).rstrip() + "\n"


def _run(run: dict[str, Any], machine: dict[str, Any]) -> list[str]:
    rows = [
        ["state", run["state"]], ["evaluations planned", f"{run['total_planned']:,}"],
        ["stored (ok / failed)", f"{run['stored']:,} ({run['ok']:,} / {run['failed']:,})"],
        ["taken from the result cache", f"{run['cached']:,}"], ["simulated", f"{run['simulated']:,}"],
        ["created / started / finished", f"{run['created_at']} / {run['started_at']} / {run['finished_at']}"],
        ["wall time (started to finished, including any time the service was down)", f"{_f(run['wall_s'], '.1f')} s"],
        ["simulations per second", _f(run["simulations_per_s"], ".1f")],
        ["engine time per simulation (mean)", f"{_f(run['mean_ms_per_simulation'], '.2f')} ms"],
        ["machine", f"{machine['cpu']}, {machine['logical_cores']} logical cores, {machine['os']}, "
                    f"Python {machine['python']}"],
    ]
    return ["## Run", "", *_table(["", ""], rows)]


def _conclusions(rep: dict[str, Any]) -> list[str]:
    c = rep["conclusions"]
    c1, c2, c3 = c["spread_vs_roughness"], c["position"], c["geometry_gain"]
    ours, paper = c2["ours"], c2["paper"]
    levels = ", ".join(f"{float(h) * 100:g} cm: {v:.3f} m" for h, v in c1["spread_by_height_m"].items())
    out = ["## Do the paper's conclusions hold here?", "",
           "Computed from the stored evaluations; thresholds are stated with each check.", "",
           "**(1) The further the road from flat, the larger the spread of distance over sprocket positions.** "
           f"Spread = max - min of the sweep's distance on a road (failed designs left out). Mean spread by "
           f"road height H_y: {levels}. Spearman rank correlation of spread with H_y: "
           f"{_f(c1['spearman_height_spread'])} (with the p95 - p5 spread: {_f(c1['spearman_height_spread_p5_p95'])}; "
           f"with the road's largest slope: {_f(c1['spearman_slope_spread'])}). "
           f"{_monotone(c1['mean_spread_increases_with_height'])} "
           f"Holds if rho >= {A.SPREAD_RHO:g}: {_yes(c1['holds'])}.", ""]
    if ours:
        out += [
            "**(2) The optimum puts the engine sprocket close to the swingarm pivot, aligned with the swingarm.** "
            f"Over the {ours['n']} DE optima: median L2 = {ours['median_l2_m']:.3f} m (range "
            f"{c2['l2_range_m'][0]:g}-{c2['l2_range_m'][1]:g} m; max {ours['max_l2_m']:.3f} m; "
            f"{100 * ours['share_l2_le_0.04_m']:.0f} % have L2 <= 0.04 m); close if the median is in the lowest "
            f"{100 * A.CLOSE_L2_FRACTION:.0f} % of the range: {_yes(c2['close_holds'])}. "
            f"Angle between r_1->2 (a2) and the swingarm line (phi0 = {c2['phi0_deg']:.1f} deg, or its opposite "
            f"{c2['phi0_deg'] - 180:.1f} deg): median {ours['median_angle_to_swingarm_deg']:.1f} deg, "
            f"{100 * ours['share_within_20_deg']:.0f} % within {A.ALIGNED_DEG:g} deg; the sprocket axis lies a "
            f"median {1000 * ours['median_offset_from_swingarm_line_m']:.1f} mm off the swingarm line. Aligned if the "
            f"median angle is <= {A.ALIGNED_DEG:g} deg: {_yes(c2['aligned_holds'])}.", ""]
    if paper:
        out += [
            f"The same measures on the paper's own {paper['n']} rows (Tables 11-13): "
            f"median L2 = {paper['median_l2_m']:.3f} m, "
            f"median angle to the swingarm line {paper['median_angle_to_swingarm_deg']:.1f} deg "
            f"({100 * paper['share_within_20_deg']:.0f} % within {A.ALIGNED_DEG:g} deg), median offset "
            f"{1000 * paper['median_offset_from_swingarm_line_m']:.1f} mm. "
            "With L2 this small the angle matters little: "
            'the offset from the line is the better measure of "aligned and close".',
            "",
        ]
    if c3["holds"] is not None:
        out += ["**(3) Geometry 1 beats geometry 2 by about 2 %.** On sine:0.04:3, geometry 1 travels "
                f"{c3['gain_pct']:.2f} % further than geometry 2 (paper: {c3['paper_gain_pct']:.2f} %). Holds if "
                f"geometry 1 is ahead by {A.GAIN_BAND_PCT[0]:g}-{A.GAIN_BAND_PCT[1]:g} %: {_yes(c3['holds'])}.", ""]
    out += _disagreements(rep)
    return out


def _disagreements(rep: dict[str, Any]) -> list[str]:
    fp, t14 = rep["fitness_vs_paper"], rep["table14"]
    out = ["### Where this model disagrees with the paper", ""]
    if fp:
        out.append(
            f"- DE optimum fitness minus the paper's, over {fp['n']} roads: mean {_signed(fp['mean_m'])} m "
            f"(from {_signed(fp['min_m'])} to {_signed(fp['max_m'])} m; mean absolute {fp['mean_abs_m']:.3f} m). The "
            "drive torque is calibrated once, on the flat road's Table 11 optimum "
            "(docs/engine.md#reading-notes-reference-choices), so the "
            "flat road matches by construction and the rough roads show how the model's response to "
            "the road differs: the centres of mass, the start from static equilibrium, x = 0 of the "
            "road and the bump centre (mu = 5 m) are reference choices the paper does not give."
        )
    pos = rep["conclusions"]["position"]
    if pos["ours"] and pos["paper"]:
        o, p = pos["ours"], pos["paper"]
        out.append(
            f"- Optimum position: median L2 {o['median_l2_m']:.3f} m here against {p['median_l2_m']:.3f} m in the "
            f"paper's rows; median offset from the swingarm line "
            f"{1000 * o['median_offset_from_swingarm_line_m']:.1f} against "
            f"{1000 * p['median_offset_from_swingarm_line_m']:.1f} mm. Where L2 is a few millimetres the "
            "angle a2 hardly moves the sprocket, so the DE's a2 is close to arbitrary there and the angle "
            "check is weak evidence either way."
        )
    g1, g2 = t14["ours"]["geometry1"], t14["ours"]["geometry2"]
    p1, p2 = t14["paper"]["geometry1"], t14["paper"]["geometry2"]
    if g1["distance_m"] is not None and g2["distance_m"] is not None:
        d1, d2 = p1["distance_m"], p2["distance_m"]
        out.append(f"- Table 14: distances {g1['distance_m']:.3f} / {g2['distance_m']:.3f} m against the paper's "
                   f"{d1:.3f} / {d2:.3f} m ({g1['distance_m'] - d1:+.3f} / {g2['distance_m'] - d2:+.3f} m); "
                   f"geometry 2's slack {_f(_mm(g2['slack_m']), '.1f')} mm against {_mm(p2['slack_m']):.1f} mm. "
                   "Geometry 2 is simulated with R_WS = 0.050 m (the text; Table 14 prints 0.150 m)." + _gap_cause(t14))
    if rep["job"]["spec"]["grid"] == "table9":
        out.append("- The sweep uses R_WS = 0.093 m (the paper does not say which R_WS its sweep used; 93 mm is "
                   "the mean of its 23 DE optima, section 5.3).")
    out.append("- Nothing was tuned to match these rows.")
    return [*out, ""]


def _monotone(v: bool | None) -> str:
    if v is None:
        return "With one road height, no trend can be seen."
    return f"The mean spread {'grows' if v else 'does not grow'} monotonically with H_y."


def _gap_cause(t14: dict[str, Any]) -> str:
    ours, paper = t14["ours"]["gain_pct"], t14["paper"]["gain_pct"]
    if ours is None or paper is None or abs(ours - paper) < 0.5:
        return ""
    more = "less" if ours < paper else "more"
    return (f" The gap between the geometries is {ours:.2f} % here against {paper:.2f} %: this model's distance "
            f"depends {more} on the chain's line of action than the paper's. Likely causes: the tyre's transient "
            "slip model (eqs. 41-43, whose printed forms docs/engine.md#reading-notes-extraction-faults corrects, "
            "with the algebraic loop of "
            "eq. 41 closed by choice), and the drive torque calibrated on the flat road only.")


def _mm(metres: float | None) -> float | None:
    """Slack is stored in m (docs/fields.md) and read in mm in the tables."""
    return None if metres is None else 1000.0 * metres


def _design_cells(d: dict[str, Any] | None) -> list[str]:
    if d is None:
        return ["–"] * 6
    return [_f(d["a2_deg"], ".1f"), _f(d["l2_m"], ".3f"), _f(d["rws_m"], ".3f"), _f(_mm(d["slack_m"]), ".3f"),
            _f(d["squat_ratio"], ".3f"), _f(d["fitness_m"], ".3f")]


def _roads(roads: list[dict[str, Any]], fp: dict[str, Any] | None) -> list[str]:
    header = ["road", "a2 [deg]", "L2 [m]", "R_WS [m]", "slack [mm]", "SR", "fitness [m]", "distance [m]",
              "paper a2", "paper L2", "paper R_WS", "paper slack", "paper SR", "paper fitness", "Δ fitness [m]",
              "DE failed"]
    rows = []
    for r in roads:
        d, p = r["de_best"], r["paper"]
        paper = _design_cells(p)
        delta = "–" if d is None or p is None else _signed(d["fitness_m"] - p["fitness_m"])
        rows.append([f"`{r['name']}`", *_design_cells(d), _f(d and d["distance_m"]), *paper, delta,
                     f"{r['de_failed']}/{r['de_evals']}"])
    return ["## Per road: the DE optimum next to the paper's Tables 11-13", "",
            "Ours: the best successful evaluation of the road's DE run (a2 wrapped to [0, 360) deg). "
            "Paper: the row as printed (Table 12's 371.0 deg = 11 deg).", "", *_table(header, rows)]


def _sweep(roads: list[dict[str, Any]], figs: dict[str, str]) -> list[str]:
    header = ["road", "H_y [m]", "failed", "best fitness: a2 [deg], L2 [m]", "best fitness [m]",
              "distance min [m]", "max [m]", "spread [m]", "p95 - p5 [m]"]
    rows = []
    for r in roads:
        b, d = r["sweep_best"], r["sweep_distance"]
        rows.append([f"`{r['name']}`", _f(r["height_m"], ".2f"), f"{r['sweep_failed']}/{r['sweep_evals']}",
                     "–" if b is None else f"{b['a2_deg']:.0f}, {b['l2_m']:.2f}", _f(b and b["fitness_m"]),
                     *(["–"] * 4 if d is None else [_f(d["min_m"]), _f(d["max_m"]), _f(d["spread_m"]),
                                                   _f(d["spread_p5_p95_m"])])])
    out = ["## Sweep (Table 9; maps as Figs. 9-11)", "", *_table(header, rows)]
    for r in roads:
        if f"map:{r['index']}" in figs:
            out += [f"![sweep map {r['name']}]({figs['map:' + str(r['index'])]})", ""]
    return out


def _band_cells(r: dict[str, Any]) -> list[str]:
    """A road's numerical band [mm] (flagged above 1 mm) and its ties among the next best designs."""
    band, ties = r.get("numerical_band"), r.get("ties") or []
    if band is None or band["band_m"] is None:
        return ["–" if band is None else "unknown (" + "; ".join(band["failed"].values()) + ")", "–"]
    flag = " (> 1 mm)" if band["exceeds_limit"] else ""
    tied = f"{sum(t['tie'] for t in ties[1:])} of {len(ties) - 1}" if len(ties) > 1 else "–"
    return [f"{1000 * band['band_m']:.3f}{flag}", tied]


def _sharpness(roads: list[dict[str, Any]]) -> list[str]:
    header = ["road", "near-optimal", "a2 [deg]", "L2 [mm]", "R_WS [mm]", "not decided", "band [mm]", "ties"]
    rows = []
    for r in roads:
        n = r.get("near_optimal") or {}
        g = n.get("ranges") or {}
        if not g:
            rows.append([f"`{r['name']}`", "–", "–", "–", "–", "–", *_band_cells(r)])
            continue
        lo, hi = g["a2_deg"]
        a2 = "any (L2 = 0)" if lo is None else f"{lo:.0f} – {hi % 360 if hi >= 360 else hi:.0f}"
        rows.append([f"`{r['name']}`", f"{n['count']}/{n['evaluated']}", a2,
                     f"{1000 * g['l2_m'][0]:.1f} – {1000 * g['l2_m'][1]:.1f}",
                     f"{1000 * g['rws_m'][0]:.1f} – {1000 * g['rws_m'][1]:.1f}",
                     ", ".join(k.split("_")[0] for k, v in n["verdicts"].items() if v == "undetermined") or "–",
                     *_band_cells(r)])
    return ["## Sharpness of each optimum", "",
            "Near-optimal set: the road's successful evaluations (sweep and DE) whose fitness is within 0.1 % of "
            "the best, with each variable's range over it (a2: the shortest arc, through 0 where the second "
            "value is smaller). Not decided: a variable whose range covers at least half of what the study "
            "explored (engine/study/sharpness.py; docs/optimisation.md#sharpness-of-an-optimum). Band: the "
            "numerical band of the road's best fitness, its largest change when re-simulated 100x tighter and "
            "with the reference method where the vehicle allows it; ties: how many of the next best distinct "
            "designs have a fitness closer "
            "to the best's than their two bands together (engine/study/band.py; "
            "docs/optimisation.md#numerical-bands-and-ties).", "",
            *_table(header, rows)]


def _table14(t: dict[str, Any], figs: dict[str, str]) -> list[str]:
    rows = []
    for g in ("geometry1", "geometry2"):
        o, p = t["ours"][g], t["paper"][g]
        rows.append([g, f"{o['a2_deg']:g}", f"{o['l2_m']:g}", f"{o['rws_m']:g} (paper table: {p['rws_m']:g})",
                     _f(o["squat_ratio"]), f"{p['squat_ratio']:.3f}", _f(_mm(o["slack_m"]), ".2f"),
                     f"{_mm(p['slack_m']):.2f}", _f(o["distance_m"]), f"{p['distance_m']:.3f}", o["status"]])
    header = [
        "",
        "a2 [deg]",
        "L2 [m]",
        "R_WS [m]",
        "SR",
        "paper SR",
        "slack [mm]",
        "paper slack",
        "d [m]",
        "paper d",
        "status",
    ]
    out = [
        f"## Table 14: two geometries on `{t['road']}`",
        "",
        *_table(header, rows),
        f"Geometry 1 ahead by {_f(t['ours']['gain_pct'], '.2f')} % (paper {_f(t['paper']['gain_pct'], '.2f')} %).",
        "",
    ]
    if "table14" in figs:
        out += [f"![Fig. 13 style series]({figs['table14']})", ""]
    return out


def _robust(rb: dict[str, Any] | None) -> list[str]:
    if rb is None:
        return ["## Robust design", "", "No sweep design succeeded on every road.", ""]
    rows = [
        [f"`{r['name']}`", _f(r["fitness_m"]), _f(r["optimum_m"]), _f(r["regret_m"]), _f(r["regret_pct"], ".2f")]
        for r in rb["per_road"]
    ]
    return [
        "## Robust design over all roads",
        "",
        f"Method: {rb['method']}: a2 = {rb['a2_deg']:.1f} deg, L2 = {rb['l2_m']:.3f} m, R_WS = {rb['rws_m']:.3f} m, "
        f"mean fitness {rb['mean_fitness_m']:.3f} m ({rb['n_valid_designs']} grid designs succeeded on every road). "
        f"What it costs on each road against that road's own optimum (the best of its DE and sweep): mean "
        f"{rb['mean_regret_pct']:.2f} %, at most {rb['max_regret_pct']:.2f} %.",
        "",
        *_table(["road", "fitness [m]", "road optimum [m]", "regret [m]", "regret [%]"], rows),
    ]


def _de_figures(roads: list[dict[str, Any]], figs: dict[str, str]) -> list[str]:
    keys = [(r["name"], figs[f"de:{r['index']}"]) for r in roads if f"de:{r['index']}" in figs]
    if not keys:
        return []
    return ["## DE convergence per road", "", *[f"![DE {name}]({path})\n" for name, path in keys]]


def _optimiser(de: dict[str, Any]) -> str:
    """The optimiser's settings as the spec stored them (before methods had names: the DE's)."""
    stop = "" if de.get("patience") is None else (
        f", stopping after {de['patience']} generations without a gain of more than {de.get('tol_m', 0) * 1e3:g} mm")
    if de.get("optimiser", "de") == "de":
        return (f"DE NP = {de['np']}, F = {de['f']:g}, CP = {de['cp']:g}, MP = {de['mp']:g}, "
                f"MR = {de['mr_fraction']:g} of the range, {de['iters']} iterations{stop}")
    return f"{de['optimiser']}: population {de['np']}, sigma {de['sigma']:g}, {de['iters']} rounds{stop}"
