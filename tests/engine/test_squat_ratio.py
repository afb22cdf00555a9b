"""Squat ratio at the design pose against every SR value of Tables 11-14.

The issue speaks of 24 rows; the tables hold 25 (1 + 16 + 6 + 2): all are checked."""

from __future__ import annotations

import pytest

from finaldrive.engine import Design, SimSettings
from finaldrive.engine.model.kinematics import design_squat_ratio
from finaldrive.engine.simulation import pack_parameters


def _rows(tables: dict) -> list[tuple[float, float, float, float]]:
    rows = [(r["a2_deg"], r["L2_m"], r["R_WS_m"], r["SR"]) for r in tables["table11_flat"]]
    rows += [(r["a2_deg"], r["L2_m"], r["R_WS_m"], r["SR"]) for r in tables["table12_sine"]]
    rows += [(r["a2_deg"], r["L2_m"], r["R_WS_m"], r["SR"]) for r in tables["table13_gaussian"]]
    g1, g2 = tables["table14_geometries"]["geometry1"], tables["table14_geometries"]["geometry2"]
    rows.append((g1["a2_deg"], g1["L2_m"], g1["R_WS_m"], g1["SR"]))
    # docs/engine.md#reading-notes-extraction-faults: geometry 2's wheel sprocket is 50 mm (text), not 0.150 m (table)
    rows.append((g2["a2_deg"], g2["L2_m"], 0.050, g2["SR"]))
    return rows


def test_every_row_within_0_01(tables, vehicle):
    rows = _rows(tables)
    assert len(rows) == 25
    misses = []
    for a2, l2, rws, sr_paper in rows:
        p = pack_parameters(vehicle, Design.from_deg(a2, l2, rws), SimSettings())
        sr = design_squat_ratio(p)
        if abs(sr - sr_paper) > 0.01:
            misses.append((a2, l2, rws, sr_paper, round(sr, 4)))
    assert not misses, misses


@pytest.mark.parametrize("a2_deg", [0.0, 90.0, 180.0, 270.0])
def test_concentric_sprocket_sr_does_not_depend_on_angle(vehicle, a2_deg):
    """With L2 = 0 the engine sprocket sits on the pivot: a2 cannot matter."""
    ref = design_squat_ratio(pack_parameters(vehicle, Design.from_deg(0, 0.0, 0.093), SimSettings()))
    sr = design_squat_ratio(pack_parameters(vehicle, Design.from_deg(a2_deg, 0.0, 0.093), SimSettings()))
    assert sr == pytest.approx(ref, abs=1e-12)
