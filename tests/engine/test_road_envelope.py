"""The rigid ring's envelope of a road against its definition and the geometry of a circle on a curve."""

from __future__ import annotations

import math

import numpy as np
import pytest

from finaldrive.engine.model.road import Road, RoadError
from finaldrive.engine.model.road_envelope import ENVELOPE_STEP_M, enveloped

R = 0.3


def accuracy(road: Road) -> float:
    """The envelope's documented accuracy on ``road`` (engine.model.road_envelope.ENVELOPE_STEP_M)."""
    x = np.linspace(-1.0, 3.0, 40001)
    y = road.height_at(x)
    kappa = float(np.max(np.abs(np.diff(y, 2))) / (x[1] - x[0]) ** 2)
    return (kappa + 1.5 / R) * ENVELOPE_STEP_M**2 / 8 + 1.5 * ENVELOPE_STEP_M**2 / (8 * R)


@pytest.mark.parametrize("spec", ["sine:0.04:2", "sine:0.04:0.5", "bump:0.04:0.05:1", "sine:0.01:0.2:45"])
def test_the_ring_rests_on_the_road_without_entering_it(spec: str) -> None:
    """At points of the enveloped road, a ring of radius R whose lowest point is there lies on or above the
    road at every offset (checked at 4,001 offsets, finer than the envelope's own) and touches it."""
    road = Road.parse(spec)
    env = enveloped(road, R, -0.5, 2.5)
    tol = accuracy(road)
    assert tol < 2.5e-5                                 # 20 micrometres on the sharpest of them
    u = np.linspace(-R, R, 4001)
    for x in np.linspace(0.0, 2.0, 37):
        centre = float(env.height_at(x)) + R
        gap = centre - np.sqrt(R * R - u * u) - road.height_at(x + u)
        assert gap.min() > -tol, (x, gap.min())         # never inside the road
        assert gap.min() < tol, (x, gap.min())          # resting on it


def test_a_sine_gentler_than_the_ring_keeps_its_crests_and_troughs() -> None:
    """sine:0.04:3 curves at most H (2 pi / lambda)^2 = 0.18 /m, below 1/R = 3.3 /m: the ring touches each
    crest and each trough at its extreme point, so the envelope has the road's heights there."""
    road = Road.parse("sine:0.04:3")
    env = enveloped(road, R, -1.0, 10.0)
    for crest in (0.75, 3.75, 6.75):
        assert float(env.height_at(crest)) == pytest.approx(0.04, abs=1e-6)
        assert float(env.height_at(crest + 1.5)) == pytest.approx(-0.04, abs=1e-6)


def test_a_trough_narrower_than_the_ring_is_bridged_where_a_circle_rests_on_both_flanks() -> None:
    """sine:0.04:0.5 curves 6.3 /m at a trough, sharper than the ring: the ring rests on the two flanks, and
    its lowest point is where a circle of radius R touching a sine at two symmetric points puts it."""
    road = Road.parse("sine:0.04:0.5")
    env = enveloped(road, R, -0.5, 1.5)
    trough = 0.375
    k = 2 * math.pi / 0.5
    # contact at trough +- d: the circle's slope there equals the road's, d / sqrt(R^2 - d^2) = y'(trough + d)
    lo, hi = 1e-9, 0.25
    for _ in range(200):
        d = 0.5 * (lo + hi)
        if d / math.sqrt(R * R - d * d) < 0.04 * k * math.cos(k * (trough + d)):
            lo = d
        else:
            hi = d
    lowest = float(road.height_at(trough + d)) + math.sqrt(R * R - d * d) - R
    assert float(env.height_at(trough)) == pytest.approx(lowest, abs=accuracy(road))
    assert lowest > -0.04 + 0.01                        # bridged by more than a centimetre


def test_flat_stays_flat_and_bad_input_is_refused() -> None:
    assert np.all(np.array(enveloped(Road(), R, 0.0, 5.0).ys) == 0.0)
    with pytest.raises(RoadError, match="radius"):
        enveloped(Road(), 0.0, 0.0, 5.0)
    with pytest.raises(RoadError, match="points"):
        enveloped(Road(), R, 0.0, 1e4)
