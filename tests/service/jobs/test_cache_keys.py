"""Result-cache keys: what changes a result changes the key, nothing else does."""

from __future__ import annotations

import numpy as np

from finaldrive.engine.api import SimSettings
from finaldrive.engine.model.road import Road
from finaldrive.engine.vehicle import Vehicle, default_vehicle
from finaldrive.service.jobs.cache import context_prefix, design_keys

ROW = np.array([[0.0, 0.1, 0.09]])


def key(
    design: np.ndarray = ROW, road: Road | None = None, settings: SimSettings | None = None,
    vehicle: Vehicle | None = None, engine: str = "1",
) -> str:
    prefix = context_prefix(road or Road("flat"), settings or SimSettings(), vehicle, engine)
    return design_keys(prefix, design)[0]


def test_inputs_that_change_results_change_the_key() -> None:
    base = key()
    assert key(design=ROW + np.array([[0, 0, 1e-6]])) != base
    assert key(road=Road.parse("sine:0.01:2")) != base
    assert key(settings=SimSettings(duration=1.0)) != base
    assert key(engine="2") != base
    first, value = default_vehicle().values[0]
    assert key(vehicle=default_vehicle().replace(**{first: value * 1.01})) != base
    assert key(vehicle=default_vehicle()) == base  # None means the default vehicle


def test_output_options_rounding_and_signed_zero_do_not() -> None:
    base = key()
    assert key(design=np.array([[-0.0, 0.1 + 1e-15, 0.09]])) == base
    assert key(settings=SimSettings(series=True)) == base
    # series rows come from dense output, so the stride does not move the steps; the wall-time
    # limit only decides whether a run finishes, never what it returns
    assert key(settings=SimSettings(series_stride=5)) == base
    assert key(settings=SimSettings(max_wall_s=1.0)) == base


def test_profiles_are_keyed_by_their_points() -> None:
    a = Road.from_points([0, 1, 2], [0, 0.01, 0], name="p")
    b = Road.from_points([0, 1, 2], [0, 0.02, 0], name="p")
    assert a.spec == b.spec and key(road=a) != key(road=b)
