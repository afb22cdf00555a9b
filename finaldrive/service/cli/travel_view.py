"""Human text of the travel kinematics and of the squat a simulation shows (`finaldrive geometry --travel`)."""

from __future__ import annotations

from typing import Any

_COLUMNS = ("travel[mm]  swingarm[deg]     SR  anti-squat[%]  anti-rise[%]  chain growth[mm]  kickback[deg]  "
            "leverage  chain angle[deg]  chain above pivot[mm]")


def _row(point: dict[str, Any], mark: str = "") -> str:
    return (f"{1000 * point['travel_m']:10.1f}  {point['swingarm_angle_deg']:13.2f}  {point['squat_ratio']:5.3f}  "
            f"{point['anti_squat_pct']:13.1f}  {point['anti_rise_pct']:12.1f}  {1000 * point['chain_growth_m']:16.2f}  "
            f"{point['kickback_deg']:13.3f}  {point['leverage_ratio']:8.3f}  "
            f"{point['chain_angle_deg']:16.2f}  {1000 * point['chain_above_pivot_m']:21.1f}  {mark}").rstrip()


def travel_lines(t: dict[str, Any]) -> list[str]:
    """The curve from full extension to full compression, the design pose and the static sag in place."""
    sag = t["static_sag"]
    marks = [(t["design_pose"], "<- design pose"), (sag, f"<- static sag ({sag['sag_pct']:.0f} %)")]
    rows = [(c["travel_m"], _row(c)) for c in t["curve"]] + [(m["travel_m"], _row(m, label)) for m, label in marks]
    verdict = "> 100 %: drive extends the rear" if sag["anti_squat_pct"] > 100 else "< 100 %: drive compresses the rear"
    return [
        f"rear wheel travel {1000 * t['rear_wheel_travel_m']:.0f} mm from full extension (swingarm "
        f"{t['extension_angle_deg']:.1f} deg) to full compression ({t['compression_angle_deg']:.1f} deg); "
        f"engine sprocket {1000 * t['engine_sprocket_x_m']:.1f}, {1000 * t['engine_sprocket_y_m']:.1f} mm "
        "from the pivot",
        f"sprockets: {t['engine_sprocket_teeth']:.1f} and {t['wheel_sprocket_teeth']:.1f} teeth of a "
        f"{1000 * t['chain_pitch_m']:.3f} mm pitch chain (not rounded); chain: {t['chain_links']:.1f} links",
        f"fork: {t['fork_angle_deg']:.1f} deg from the vertical; anti-dive {t['anti_dive_pct']:.0f} % over the whole "
        "travel (front brake caliper on the fork slider: -100 tan(fork angle) / tan(sigma))",
        "SR: the paper's squat ratio K / tan(tau); anti-squat: 100 tan(tau) / tan(sigma), tan(sigma) = "
        f"{t['cog_height_m']:.3f} m / {t['wheelbase_m']:.3f} m; anti-rise: the same for the line from the rear "
        "contact point to the pivot (rear brake caliper on the swingarm); chain growth: change of the taut run from "
        "full extension; kickback: the wheel's backward turn it gives; leverage: wheel travel per spring travel",
        _COLUMNS,
        *(line for _, line in sorted(rows, key=lambda r: r[0])),
        f"at static sag: SR {sag['squat_ratio']:.3f}, anti-squat {sag['anti_squat_pct']:.0f} % ({verdict})",
    ]


def drive_lines(d: dict[str, Any]) -> list[str]:
    """The squat one simulation shows, beside the static prediction."""
    if d["status"] != "ok":
        return [f"simulation on {d['road']} failed: {d['reason']}"]
    squat = 1000 * d["squat_mean_m"]
    return [
        f"simulated on {d['road']} for {d['duration']:g} s ({d['distance_m']:.3f} m):",
        f"  rear travel {1000 * d['travel_static_m']:.1f} mm at the start, mean {1000 * d['travel_mean_m']:.1f} mm "
        f"({squat:+.2f} mm: {'compressed' if squat > 0 else 'extended'} under drive), "
        f"range {1000 * d['travel_min_m']:.1f} to {1000 * d['travel_max_m']:.1f} mm",
        f"  chassis pitch from the start: mean {d['pitch_mean_deg']:+.2f} deg (+ nose up), "
        f"range {d['pitch_min_deg']:+.2f} to {d['pitch_max_deg']:+.2f} deg",
    ]
