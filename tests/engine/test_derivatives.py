"""Every hand derivative of the model against central differences.

- the magic formula's slope dF_x/dkappa' (eq. 45), inside and beyond the load range;
- the tyre's radial force is minus the derivative of its energy (eq. 36 with the bump stop);
- the fast path's chain terms (engine.fast.minimal.chain_terms): d(alpha)/dz, the velocity
  product alpha'' at z'' = 0, L_taut' and alpha', against alpha(z) and L_taut(z) from the
  natural-coordinate position analysis (engine.model.kinematics, eqs. 22-31);
- the fast path's linearly implicit terms: c_row = d(u')/dz', d(u')/du = -|V_x| / sigma*, and
  dz''/du = M^-1 b dF_x/du (b: the generalized force of a unit F_x with its lever arm).

Central differences with step h have error O(h^2); each tolerance is stated next to its check.
"""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import Design, Road, SimSettings
from finaldrive.engine.fast import bodies, minimal
from finaldrive.engine.model import params as P
from finaldrive.engine.model.coordinates import ALPHA
from finaldrive.engine.model.elements import AUX_FZ_REAR, AUX_SLOPE, AUX_TAUT, AUX_TAUT_RATE, AUX_VX, N_AUX
from finaldrive.engine.model.kinematics import pose_from_minimal, taut_length
from finaldrive.engine.model.tyre import magic_formula, magic_formula_slope, radial_energy, radial_force
from finaldrive.engine.simulation import MINIMAL_COORDS, pack_parameters, prepare

DESIGNS = [Design.from_deg(195.3, 0.037, 0.088), Design.from_deg(270, 0.15, 0.05), Design.from_deg(45, 0.2, 0.15),
           Design.from_deg(0, 0.0, 0.093)]


@pytest.fixture()
def p(vehicle):
    return pack_parameters(vehicle, DESIGNS[0], SimSettings())


@pytest.mark.parametrize("fz", [300.0, 1600.0, 4000.0, 6400.0, 9000.0, 30000.0])
def test_magic_formula_slope(p, fz):
    h = 1e-7
    for kappa in np.concatenate([np.linspace(-2, 2, 81), [1e-3, -1e-3, 0.5e-6]]):
        fx, slope = magic_formula_slope(fz, kappa, p)
        assert fx == magic_formula(fz, kappa, p)
        if abs(kappa) < 2 * h:
            continue  # E_x jumps with sgn(kappa') at 0 (eq. 49): one-sided there
        fd = (magic_formula(fz, kappa + h, p) - magic_formula(fz, kappa - h, p)) / (2 * h)
        assert slope == pytest.approx(fd, rel=1e-6, abs=1e-6 * fz)   # FD error ~ h^2 F''' ~ 1e-9 F_z


def test_radial_force_is_minus_the_gradient_of_its_energy(p):
    h = 1e-8
    args = (p[P.RT0], p[P.K_RT], p[P.RT_BOTTOMING], p[P.K_RT_BOTTOMING])
    for r in np.linspace(p[P.RT0] - 0.12, p[P.RT0] + 0.01, 263):
        f = radial_force(r, 0.0, p[P.RT0], p[P.K_RT], 0.0, p[P.RT_BOTTOMING], p[P.K_RT_BOTTOMING])
        fd = -(radial_energy(r + h, *args) - radial_energy(r - h, *args)) / (2 * h)
        assert f == pytest.approx(fd, abs=1e-3)  # N; the energy is piecewise quadratic (FD exact but for rounding)


def _alpha(z, p, road):
    return pose_from_minimal(z, p, road)[ALPHA]


def _rhs(y, p, kind, rp, sigma=0.05, longitudinal=True):
    geo = bodies.design_constants(p)
    out, aux, ws = np.zeros(minimal.N_STATE), np.zeros(N_AUX), np.zeros(bodies.N_WS)
    minimal.fast_rhs(y, p, geo, kind, rp, sigma, longitudinal, out, aux, ws)
    return out, aux, ws, geo


def _state(vehicle, design, spec, seed):
    road = Road.parse(spec)
    setup = prepare(design, road, SimSettings(), vehicle)
    rng = np.random.default_rng(seed)
    y = np.zeros(minimal.N_STATE)
    y[:6] = setup.q0[list(MINIMAL_COORDS)] + rng.normal(scale=[0.02, 0.002, 0.01, 0.005, 0.01, 1.0])
    y[1] -= 0.01                                 # both tyres pressed into the road
    y[6:12] = rng.normal(scale=[3.0, 0.3, 0.5, 1.0, 0.3, 20.0])
    y[6] += 8.0                                  # moving forward (V_x > 0)
    y[12] = rng.normal(scale=0.01)
    return setup.p, road, y


@pytest.mark.parametrize("design", DESIGNS, ids=lambda d: f"{d.a2_deg:.0f}-{d.l2}-{d.rws}")
@pytest.mark.parametrize("spec", ["flat", "sine:0.04:2"])
def test_chain_terms_against_the_position_analysis(vehicle, design, spec):
    p, road, y = _state(vehicle, design, spec, 1)
    geo = bodies.design_constants(p)
    z, zd = y[:6], y[6:12]
    th, ph = z[bodies.ZTHETA], z[bodies.ZPHI]
    ct, st, cp, sp = np.cos(th), np.sin(th), np.cos(ph), np.sin(ph)
    w2 = (ct * geo[bodies.G_P2_X] - st * geo[bodies.G_P2_Y], st * geo[bodies.G_P2_X] + ct * geo[bodies.G_P2_Y])
    w6 = (p[P.L_SA] * cp, p[P.L_SA] * sp)
    ja_t, ja_p, alpha_c, taut, taut_rate, alpha_dot = minimal.chain_terms(
        *w2, *w6, zd[bodies.ZTHETA], zd[bodies.ZPHI], zd[bodies.ZBETA], p)
    jalpha = np.zeros(6)
    jalpha[bodies.ZTHETA], jalpha[bodies.ZPHI], jalpha[bodies.ZBETA] = ja_t, ja_p, p[P.R_WS] / p[P.R_ES]
    h = 1e-6
    fd = np.array([(_alpha(z + h * e, p, road) - _alpha(z - h * e, p, road)) / (2 * h) for e in np.eye(6)])
    np.testing.assert_allclose(jalpha, fd, atol=1e-7)            # rad per (m, rad); FD error ~1e-10
    assert alpha_dot == pytest.approx(jalpha @ zd, rel=1e-12)
    assert taut == pytest.approx(taut_length(pose_from_minimal(z, p, road)), abs=1e-12)
    rate = (taut_length(pose_from_minimal(z + h * zd, p, road))
            - taut_length(pose_from_minimal(z - h * zd, p, road))) / (2 * h)
    assert taut_rate == pytest.approx(rate, abs=1e-7)            # m/s
    h2 = 1e-4  # second difference along z(t) = z + z' t (z'' = 0): error ~h^2 alpha'''' ~ 1e-6
    second = (_alpha(z + h2 * zd, p, road) - 2 * _alpha(z, p, road) + _alpha(z - h2 * zd, p, road)) / h2**2
    assert alpha_c == pytest.approx(second, abs=1e-4 * (1 + abs(second)))


@pytest.mark.parametrize("design", DESIGNS, ids=lambda d: f"{d.a2_deg:.0f}-{d.l2}-{d.rws}")
@pytest.mark.parametrize("spec", ["flat", "bump:0.04:0.2:0.2"])
@pytest.mark.parametrize("lever", [0.0, 1.0])
def test_linearly_implicit_terms(vehicle, design, spec, lever):
    """c_row, d(u')/du and dz''/du = M^-1 b dF_x/du of the W matrix (engine.fast.rosenbrock)."""
    p, road, y = _state(vehicle.replace(fx_lever_loaded=lever), design, spec, 2)
    kind, rp = road.packed()
    sigma = 0.05
    _, aux, ws, geo = _rhs(y, p, kind, rp, sigma)
    c_row = ws[bodies.W_C:bodies.W_C + 6]
    assert aux[AUX_FZ_REAR] > 0, "the rear tyre is on the road"
    h = 1e-6
    for k in range(6):  # d(u')/dz'_k: u' is linear in z' (eq. 42): central differences exact
        e = np.zeros(minimal.N_STATE)
        e[6 + k] = h
        fd = (_rhs(y + e, p, kind, rp, sigma)[0][12] - _rhs(y - e, p, kind, rp, sigma)[0][12]) / (2 * h)
        assert c_row[k] == pytest.approx(fd, abs=1e-6 * (1 + abs(fd))), k
    e = np.zeros(minimal.N_STATE)
    e[12] = h
    plus, minus = _rhs(y + e, p, kind, rp, sigma)[0], _rhs(y - e, p, kind, rp, sigma)[0]
    assert (plus[12] - minus[12]) / (2 * h) == pytest.approx(-abs(aux[AUX_VX]) / sigma, rel=1e-7)
    v = np.zeros(6)
    bodies.mass_solve(geo, ws, ws[bodies.W_B:bodies.W_B + 6].copy(), v)
    expected = v * aux[AUX_SLOPE] / sigma
    fd = (plus[6:12] - minus[6:12]) / (2 * h)
    np.testing.assert_allclose(expected, fd, rtol=1e-5, atol=1e-5 * np.max(np.abs(fd)))


def test_taut_rate_in_the_fast_state_is_the_time_derivative(vehicle):
    p, road, y = _state(vehicle, DESIGNS[1], "flat", 3)
    kind, rp = road.packed()
    aux = _rhs(y, p, kind, rp)[1]
    h = 1e-6
    y2 = y.copy()
    y2[:6] += h * y[6:12]
    y1 = y.copy()
    y1[:6] -= h * y[6:12]
    fd = (_rhs(y2, p, kind, rp)[1][AUX_TAUT] - _rhs(y1, p, kind, rp)[1][AUX_TAUT]) / (2 * h)
    assert aux[AUX_TAUT_RATE] == pytest.approx(fd, abs=1e-7)
