"""The integrator loops run in chunks: a paused loop continues exactly (bit-identical results
whatever the chunk size); the wall-time limit and should_stop end a run as a failed result; the
series (stride, on or off) changes nothing of the run; the extremes are the integrator's own."""

from __future__ import annotations

import math

import numpy as np
import pytest

import finaldrive.engine.simulation as sim
from finaldrive.engine import DIAGNOSTICS, STATUS_FAILED, Design, Road, SimSettings, evaluate, simulate

TABLE11 = Design.from_deg(195.3, 0.037, 0.088)
GEOMETRY1 = Design.from_deg(0, 0.0, 0.093)
GEOMETRY2 = Design.from_deg(270, 0.15, 0.050)


def _values(r) -> dict[str, float]:
    values = {k: v for k, v in r.summary().items() if k != "wall_s"}
    assert len(values) > 20  # status, reason and every value of the record
    return values


def _same(a, b) -> None:
    va, vb = _values(a), _values(b)
    for key in va:
        x, y = va[key], vb[key]
        assert x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)), (key, x, y)


@pytest.mark.parametrize("chunk", [1, 3, 50])
def test_fast_run_is_bit_identical_whatever_the_chunk_size(vehicle, monkeypatch, chunk):
    road = Road.parse("sine:0.04:2")
    settings = SimSettings(series=True, max_airborne_time=3.5)  # geometry 2 hops there: see it all
    whole = simulate(GEOMETRY2, road, settings, vehicle)
    assert whole.ok, whole.reason
    monkeypatch.setattr(sim, "FAST_CHUNK_STEPS", chunk)
    pieces = simulate(GEOMETRY2, road, settings, vehicle)
    _same(whole, pieces)
    for key in whole.series:
        np.testing.assert_array_equal(whole.series[key], pieces.series[key], err_msg=key)


@pytest.mark.parametrize("chunk", [1, 7])
def test_reference_run_is_bit_identical_whatever_the_chunk_size(vehicle, monkeypatch, chunk):
    road = Road.parse("bump:0.04:0.2:0.3")
    settings = SimSettings(method="reference", duration=0.4, series=True, series_stride=3)
    whole = simulate(TABLE11, road, settings, vehicle)
    monkeypatch.setattr(sim, "REFERENCE_CHUNK_STEPS", chunk)
    pieces = simulate(TABLE11, road, settings, vehicle)
    _same(whole, pieces)
    for key in whole.series:
        np.testing.assert_array_equal(whole.series[key], pieces.series[key], err_msg=key)


def test_series_stride_and_series_change_nothing_of_the_fast_run(vehicle):
    road = Road.parse("sine:0.04:3")
    base = simulate(TABLE11, road, SimSettings(), vehicle)
    for settings in (SimSettings(series=True, series_stride=1), SimSettings(series=True, series_stride=7),
                     SimSettings(series_stride=50)):
        _same(base, simulate(TABLE11, road, settings, vehicle))


def test_dense_output_rows_sit_on_their_times_and_end_at_the_run(vehicle):
    r = simulate(TABLE11, Road.parse("sine:0.04:3"), SimSettings(series=True, series_stride=7), vehicle)
    t = r.series["t_s"]
    np.testing.assert_allclose(np.diff(t), 3.5 / (len(t) - 1), rtol=1e-12)
    assert t[-1] == 3.5
    assert r.series["distance_m"][-1] == r.distance_m


def test_time_limit_and_cancel_end_the_run_as_failed(vehicle):
    road = Road.parse("flat")
    limited = simulate(TABLE11, road, SimSettings(method="reference", max_wall_s=1e-9), vehicle)
    assert limited.status == STATUS_FAILED and limited.reason.startswith("time limit"), limited.reason
    assert math.isnan(limited.distance_m)
    calls = []

    def stop() -> bool:
        calls.append(1)
        return len(calls) > 2

    cancelled = simulate(TABLE11, road, SimSettings(method="reference"), vehicle, should_stop=stop)
    assert cancelled.status == STATUS_FAILED and cancelled.reason == "cancelled"
    assert len(calls) == 3
    batch = evaluate(np.array([TABLE11.row(), TABLE11.row()]), road, SimSettings(), vehicle, should_stop=lambda: True)
    assert batch.reason == ("cancelled", "cancelled")


def test_limits_that_are_not_reached_change_nothing(vehicle):
    road = Road.parse("bump:0.04:0.2")
    base = simulate(TABLE11, road, SimSettings(max_wall_s=None), vehicle)
    _same(base, simulate(TABLE11, road, SimSettings(max_wall_s=600.0), vehicle, should_stop=lambda: False))


def test_extremes_are_those_of_every_step(vehicle):
    """Reference (fixed steps) with a row at every step: the tracked extremes are the series'."""
    r = simulate(GEOMETRY2, Road.parse("sine:0.04:3"), SimSettings(method="reference", series=True,
                                                                      series_stride=1), vehicle)
    s = r.series
    assert r.chain_tension_max_n == s["chain_tension_n"].max()
    assert r.chain_tension_min_n == s["chain_tension_n"].min()
    assert r.fz_rear_max_n == s["fz_rear_n"].max() and r.fz_rear_min_n == s["fz_rear_n"].min()
    assert r.fz_front_max_n == s["fz_front_n"].max() and r.fz_front_min_n == s["fz_front_n"].min()
    assert r.slip_max == np.abs(s["kappa"]).max()
    rt = s["q"][:, 32]
    assert r.tyre_compression_rear_max_m == pytest.approx(0.3 - rt.min(), abs=1e-15)
    dt = 1e-3
    assert r.chain_compression_s == pytest.approx(dt * np.sum(s["chain_tension_n"][:-1] < 0), abs=1e-9)
    assert r.airborne_rear_s == pytest.approx(dt * np.sum(s["fz_rear_n"][:-1] <= 0), abs=1e-9)


def test_fast_extremes_do_not_depend_on_the_series_stride(vehicle):
    """The issue's figures: the peak chain tension read off a series moved with the stride."""
    road = Road.parse("sine:0.04:3")
    fine = simulate(GEOMETRY1, road, SimSettings(series=True, series_stride=1), vehicle)
    coarse = simulate(GEOMETRY1, road, SimSettings(series=True, series_stride=20), vehicle)
    assert fine.chain_tension_max_n == coarse.chain_tension_max_n
    assert fine.chain_tension_max_n >= fine.series["chain_tension_n"].max() - 1.0  # N: the steps see the peak
    assert coarse.series["chain_tension_n"].max() <= coarse.chain_tension_max_n + 1.0


def _as_printed(vehicle):
    """The tyre as the paper prints it: no load range, F_x's lever arm rt, no bump stop."""
    return vehicle.replace(Fz_max=1e9, fx_lever_loaded=1.0, k_rt_bottoming=0.0)


def test_overrun_and_bottoming_diagnostics(vehicle):
    """Table 14 on sine:0.04:3 with the tyre as printed (the issue's figures): geometry 2's rear
    load goes past 11.4 kN, where eq. (50)'s slip stiffness turns negative, the tyre pushes
    backwards, the upper chain run is pushed (down to about -8 kN, for about 5 ms) and the rear tyre
    compresses past where its rim bottoms. With the load range and the bump stop (the defaults),
    the deep push is gone (what is left: dips of a few hundred N for a few ms in the slip
    transients after a landing) and the bump stop carries the bottomed tyre."""
    road = Road.parse("sine:0.04:3")
    printed = simulate(GEOMETRY2, road, SimSettings(), _as_printed(vehicle))
    g1 = simulate(GEOMETRY1, road, SimSettings(), vehicle)
    g2 = simulate(GEOMETRY2, road, SimSettings(), vehicle)
    for r in (printed, g1, g2):
        assert r.ok, r.reason
        assert all(math.isfinite(getattr(r, name)) for name in DIAGNOSTICS)
        # eq. (36) as printed: the tyre's damper c_rt r' may pull a little as the wheel lifts (r' < 10 m/s)
        assert r.fz_rear_max_n > vehicle["Fz0"] and -10.0 * vehicle["c_rt"] < r.fz_rear_min_n < r.fz_rear_max_n
        assert 0.0 < r.tyre_compression_front_max_m < 0.05
        assert 0.0 < r.airborne_rear_s < 0.5
    assert printed.fz_rear_max_n > 11405.0
    assert printed.chain_tension_min_n < -5000.0 and 0.001 < printed.chain_compression_s < 0.02
    assert printed.tyre_compression_rear_max_m > vehicle["rt_bottoming"]
    for r in (g1, g2):
        assert r.chain_tension_min_n > -1000.0 and r.chain_compression_s < 0.005
    assert g2.tyre_compression_rear_max_m > g1.tyre_compression_rear_max_m
    # the bottomed tyre: the bump stop takes what the sidewall cannot
    assert g2.tyre_compression_rear_max_m < vehicle["rt_bottoming"] + g2.fz_rear_max_n / vehicle["k_rt_bottoming"]
