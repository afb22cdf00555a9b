"""The sharpness of an optimum: the near-optimal set against brute force, angle arcs, and the
sensitivities against physics (a2 has no effect with the sprocket on the pivot) and a line fit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from finaldrive.engine import (
    SENSITIVITY_STEPS,
    Design,
    Road,
    SimSettings,
    angle_arc,
    default_vehicle,
    finite_differences,
    near_optimal,
    sensitivities,
    sensitivity_stencil,
    simulate,
    upper_limits,
)

SHORT = SimSettings(duration=0.5)


@pytest.mark.parametrize(("angles", "arc"), [([350.0, 10.0, 20.0], (350.0, 380.0)), ([10.0, 200.0], (200.0, 370.0)),
                                             ([-90.0], (270.0, 270.0)), ([0.0, 120.0, 240.0], (0.0, 240.0))])
def test_angle_arc_is_the_shortest_arc(angles, arc):
    assert angle_arc(np.array(angles)) == pytest.approx(arc)


def test_near_optimal_set_is_every_design_within_the_tolerance():
    """A field flat in a2 and R_WS, peaked in L2: a2 and R_WS are not decided, L2 is."""
    a2, l2, rws = np.meshgrid(np.radians(np.arange(0, 360, 10)), np.linspace(0, 0.2, 41), [0.08, 0.1, 0.12])
    designs = np.column_stack([a2.ravel(), l2.ravel(), rws.ravel()])
    fitness = 20.0 - 500.0 * (designs[:, 1] - 0.1) ** 2
    fitness[5] = np.nan                                        # a failed evaluation is never near
    near = near_optimal(designs, fitness, fitness + 0.1, tolerance_pct=0.1)
    inside = np.isfinite(fitness) & (fitness >= 20.0 - 0.02)   # brute force: 0.1 % of 20 m = 20 mm
    assert near["count"] == int(inside.sum()) and near["evaluated"] == len(designs) - 1
    assert near["tolerance_m"] == pytest.approx(0.02)
    assert near["ranges"]["l2_m"] == pytest.approx([designs[inside, 1].min(), designs[inside, 1].max()])
    assert near["ranges"]["distance_m"][1] == pytest.approx(20.1)
    assert near["verdicts"] == {"a2_deg": "undetermined", "l2_m": "decided", "rws_m": "undetermined"}
    assert any(s.startswith("a2 is not decided: any a2 from 0 to 350 deg") for s in near["sentences"])
    assert any(s.startswith("L2 is decided") for s in near["sentences"])


def test_tolerance_is_checked():
    with pytest.raises(ValueError, match="tolerance_pct"):
        near_optimal(np.zeros((1, 3)), np.ones(1), tolerance_pct=0.0)


def test_a2_has_no_effect_with_the_sprocket_on_the_pivot(vehicle):
    s = sensitivities(Design.from_deg(40.0, 0.0, 0.093), Road(), SHORT, vehicle)
    assert s["simulations"] == 7
    assert s["schemes"] == {"a2_deg": "central", "l2_m": "forward", "rws_m": "central"}
    assert s["ddistance_da2_m_per_deg"] == 0.0 and s["dfitness_da2_m_per_deg"] == 0.0


def test_sensitivity_is_the_slope_of_the_simulated_distance(vehicle):
    """Central differences at 1 mm against a least-squares line through 5 simulations over +-2 mm."""
    design = Design.from_deg(195.3, 0.037, 0.088)
    s = sensitivities(design, Road(), SHORT, vehicle)
    steps = np.linspace(-0.002, 0.002, 5)
    d = [simulate(Design(design.a2, design.l2 + h, design.rws), Road(), SHORT, vehicle).distance_m for h in steps]
    slope_per_mm = np.polyfit(1000 * steps, d, 1)[0]
    assert s["ddistance_dl2_m_per_m"] == pytest.approx(1000 * slope_per_mm, rel=0.05, abs=1e-3)
    assert math.isfinite(s["dfitness_drws_m_per_m"])


def test_the_stencil_steps_back_from_the_design_limits() -> None:
    """A best at the largest L2 and R_WS the vehicle allows: backward differences, no design beyond."""
    vehicle = default_vehicle()
    upper = upper_limits(vehicle)
    rows, schemes = sensitivity_stencil(Design(1.0, upper[0], upper[1]), upper=upper)
    assert schemes == {"a2_deg": "central", "l2_m": "backward", "rws_m": "backward"}
    assert (rows[:, 1] <= upper[0]).all() and (rows[:, 2] <= upper[1]).all()
    assert rows[3, 1] == upper[0] and rows[4, 1] == upper[0] - SENSITIVITY_STEPS["l2_m"]
    distance = fitness = rows[:, 1] * 3.0  # a linear function of L2: its slope, whatever the scheme
    assert finite_differences(schemes, distance, fitness)["ddistance_dl2_m_per_m"] == pytest.approx(3.0)
