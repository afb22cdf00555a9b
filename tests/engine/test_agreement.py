"""The fast path (minimal coordinates + Rosenbrock-W) against the paper's method.

20 random designs x 3 roads; the reference runs at a tight step. Distance within 2 mm, SR
within 1e-6, slack within 0.01 mm (0.1 mm on sine:0.04:2, where the trajectories of a few
sensitive designs differ by millimetres; slack enters the fitness as 0.1/m x slack, so
0.1 mm is 1e-5 of it), identical status. Where the reference itself is not
converged at that step (wheel hops and slip past the force peak make some designs sensitive,
mostly on sine:0.04:2), it is rerun at half the step, and halved again (down to an eighth) while
the fast path still misses: the fast path must then be within the bound plus twice the reference's
last change, of the reference at the finest step (docs/performance-log.md shows the figures).
"""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings, simulate

N_DESIGNS = 20
TIGHT = 2.5e-4
#: The finest reference step tried (three halvings of TIGHT).
FINEST = TIGHT / 8
DISTANCE_TOL = 2e-3
SLACK_TOL = {"flat": 1e-5, "bump:0.04:0.2": 1e-5, "sine:0.04:2": 1e-4}


def _designs() -> list[Design]:
    rng = np.random.default_rng(2024)
    return [Design(rng.uniform(0, 2 * np.pi), rng.uniform(0, 0.2), rng.uniform(0.05, 0.15))
            for _ in range(N_DESIGNS)]


def _misses(fast, ref, d_allow: float, s_allow: float) -> list[str]:
    out = []
    if abs(fast.distance_m - ref.distance_m) > d_allow:
        out.append(f"distance off by {(fast.distance_m - ref.distance_m) * 1e3:.3f} mm (allowed {d_allow * 1e3:.3f})")
    if abs(fast.slack_m - ref.slack_m) > s_allow:
        out.append(f"slack off by {(fast.slack_m - ref.slack_m) * 1e3:.4f} mm (allowed {s_allow * 1e3:.4f})")
    return out


@pytest.mark.slow
@pytest.mark.parametrize("spec", ["flat", "bump:0.04:0.2", "sine:0.04:2"])
def test_fast_path_matches_reference(vehicle, spec):
    road = Road.parse(spec)
    rows, failures = [], []
    for d in _designs():
        fast = simulate(d, road, SimSettings(method="fast"), vehicle)
        ref = simulate(d, road, SimSettings(method="reference", dt=TIGHT), vehicle)
        own_d = own_s = 0.0
        if fast.status != ref.status:
            failures.append(f"{d}: status {fast.status} vs {ref.status} ({ref.reason}{fast.reason})")
            continue
        if abs(fast.squat_ratio - ref.squat_ratio) > 1e-6:
            failures.append(f"{d}: SR {fast.squat_ratio} vs {ref.squat_ratio}")
        if not fast.ok:
            continue
        misses = _misses(fast, ref, DISTANCE_TOL, SLACK_TOL[spec])
        dt = TIGHT
        while misses and dt > FINEST:  # is the reference converged at this step?
            dt /= 2
            finer = simulate(d, road, SimSettings(method="reference", dt=dt), vehicle)
            own_d = abs(finer.distance_m - ref.distance_m)
            own_s = abs(finer.slack_m - ref.slack_m)
            ref = finer
            misses = _misses(fast, ref, DISTANCE_TOL + 2 * own_d, SLACK_TOL[spec] + 2 * own_s)
        failures += [f"{d}: {m}" for m in misses]
        rows.append((d.a2_deg, d.l2, d.rws, (fast.distance_m - ref.distance_m) * 1e3, own_d * 1e3,
                     (fast.slack_m - ref.slack_m) * 1e3, own_s * 1e3, dt))
    print(f"\n{spec}: a2_deg l2 rws | fast - ref: distance [mm] (reference's last change) | slack [mm] (last change)"
          " | reference's dt [ms]")
    for r in rows:
        print(f"  {r[0]:7.2f} {r[1]:.3f} {r[2]:.3f} | {r[3]:+8.3f} ({r[4]:.3f}) | {r[5]:+.5f} ({r[6]:.4f})"
              f" | {r[7] * 1e3:.4f}")
    assert not failures, failures
