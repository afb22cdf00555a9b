"""Static equilibrium against Table 3 and against statics itself."""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings
from finaldrive.engine.calibrate import static_loads
from finaldrive.engine.fast.equilibrium import static_equilibrium
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import FT, RT
from finaldrive.engine.simulation import pack_parameters
from finaldrive.engine.solver.equilibrium import reference_equilibrium, rest_forces
from finaldrive.engine.solver.reference import constraint_residual


def test_table3_rear_share_and_cog_height(vehicle):
    loads = static_loads(vehicle)
    assert loads.rear_share == pytest.approx(0.507, abs=0.002)
    assert loads.cog_height == pytest.approx(0.623, abs=0.005)
    assert loads.total_mass == pytest.approx(269.2)  # Table 2 masses


def test_tyre_loads_carry_the_weight_and_balance_moments(vehicle):
    """Sum of vertical forces and moments about the rear contact point vanish."""
    loads = static_loads(vehicle)
    weight = loads.total_mass * vehicle["gravity"]
    assert loads.rear_load + loads.front_load == pytest.approx(weight, rel=1e-7)
    assert loads.front_load * loads.wheelbase == pytest.approx(weight * loads.cog_x, rel=1e-7)


def test_wheelbase_is_the_model_geometry(vehicle):
    """Table 4 gives about 1.38 m at static equilibrium, not Table 3's 1.424 m.

    See docs/engine.md#reading-notes-reference-choices."""
    assert static_loads(vehicle).wheelbase == pytest.approx(1.38, abs=0.01)


@pytest.mark.parametrize("spec", ["flat", "sine:0.04:2", "sine:0.02:5", "bump:0.04:0.2:0.7"])
def test_equilibrium_satisfies_constraints_on_every_road(vehicle, spec):
    road = Road.parse(spec)
    p = pack_parameters(vehicle, Design.from_deg(195.3, 0.037, 0.088), SimSettings())
    q = static_equilibrium(p, road)
    kind, rp = road.packed()
    res = constraint_residual(q, p, kind, rp)
    res[29] = 0.0  # eq. (30) is closed by choosing L (69) from this pose
    assert np.max(np.abs(res)) < 1e-10
    assert q[RT] < p[P.RT0] and q[FT] < p[P.FT0]


@pytest.mark.parametrize("spec", ["flat", "sine:0.04:2", "bump:0.04:0.2:0.7"])
@pytest.mark.parametrize("design", [(195.3, 0.037, 0.088), (270, 0.15, 0.05), (45, 0.2, 0.15)])
def test_reference_finds_its_own_equilibrium_and_it_is_the_fast_paths(vehicle, spec, design):
    """The reference model's equilibrium (natural coordinates, forces by virtual work through Phi_q)
    and the fast path's (minimal coordinates) are found independently and agree."""
    road = Road.parse(spec)
    p = pack_parameters(vehicle, Design.from_deg(*design), SimSettings())
    q_ref = reference_equilibrium(p, road)
    q_fast = static_equilibrium(p, road)
    kind, rp = road.packed()
    res = constraint_residual(q_ref, p, kind, rp)
    res[29] = 0.0  # eq. (30) is closed by choosing L (69) from this pose
    assert np.max(np.abs(res)) < 1e-10
    np.testing.assert_allclose(q_ref, q_fast, atol=1e-9)
    free = np.array([q_ref[1], q_ref[34], q_ref[38], q_ref[31]])   # y1, theta, phi, fs
    assert np.max(np.abs(rest_forces(free, p, road))) < 1e-9        # no virtual work of the forces at rest
