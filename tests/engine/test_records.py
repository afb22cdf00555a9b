"""The kernels' typed records (engine.jit.records): declared once, every field set, read by name."""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import DIAGNOSTICS, Design, Road, SimSettings, default_vehicle
from finaldrive.engine.fast import minimal, rosenbrock
from finaldrive.engine.jit import records
from finaldrive.engine.model import diagnostics as D
from finaldrive.engine.outcome import N_SERIES, PAUSED
from finaldrive.engine.setup import MINIMAL_COORDS, prepare
from finaldrive.engine.solver import reference

#: What the loops track that is not a result value (engine.model.diagnostics.TRACKED's docstring).
LOOPS_OWN = {"taut_min_m", "taut_max_m", "dampers_j", "chain_impacts_j"}


def test_tracked_names_are_the_results_diagnostics_or_the_loops_own():
    names = D.TRACKED.names
    assert len(set(names)) == len(names)
    assert set(names) - LOOPS_OWN <= set(DIAGNOSTICS)
    assert set(names) >= LOOPS_OWN


@pytest.mark.parametrize(("record", "loops_own"), [
    (rosenbrock.FAST_SETTINGS, {"dt_out", "keep_series", "chunk_steps"}),
    (reference.REFERENCE_SETTINGS, {"dt", "n_steps", "max_airborne_steps", "keep_series", "chunk_steps"})])
def test_settings_are_simsettings_names_or_the_loops_own(record, loops_own):
    """One vocabulary: a setting the caller takes from SimSettings has its name there (dt: the step that
    divides the duration, SimSettings.steps())."""
    assert set(record.names) - loops_own <= set(SimSettings.__dataclass_fields__)
    assert loops_own <= set(record.names)


@pytest.mark.parametrize("record", [rosenbrock.FAST_SETTINGS, reference.REFERENCE_SETTINGS])
def test_a_setting_left_out_or_unknown_is_refused_by_name(record):
    given = {name: kind(1) for name, kind, _ in record.fields}
    assert records.read(record.new(**given)) == given
    del given["chunk_steps"]
    with pytest.raises(TypeError, match=r"^record fields without a value: chunk_steps$"):
        record.new(**given)
    with pytest.raises(TypeError, match=r"^record fields unknown: tolerance$"):
        record.new(tolerance=1e-5, **given, chunk_steps=1)
    with pytest.raises(TypeError, match=r"another kind: chunk_steps$"):   # not cast to 4096
        record.new(**given, chunk_steps=4096.7)
    with pytest.raises(TypeError, match=r"another kind: keep_series$"):
        record.new(**{**given, "keep_series": 0.0}, chunk_steps=1)


def test_records_start_as_declared_and_are_aligned():
    tracked = records.read(D.TRACKED.new())
    assert tracked["fz_rear_max_n"] == -np.inf and tracked["fz_rear_min_n"] == np.inf
    assert tracked["drive_work_j"] == 0.0 and tracked["tyre_dissipation_min_w"] == np.inf
    state = rosenbrock.FAST_STATE.new()
    assert records.read(state) == {name: start for name, _, start in rosenbrock.FAST_STATE.fields}
    assert state.dtype.isalignedstruct and state.flags.aligned and state.flags.writeable


def test_the_loop_writes_through_the_records_it_is_given():
    """The kernel gets the records' elements (views): its state and what it tracked are in the arrays,
    and a paused run goes on from them."""
    road = Road.parse("sine:0.04:3")
    setup = prepare(Design(4.0, 0.08, 0.06), road, SimSettings(), default_vehicle())
    kind, rp = road.packed()
    y = np.zeros(minimal.N_STATE)
    y[:6] = setup.q0[list(MINIMAL_COORDS)]
    settings = rosenbrock.FAST_SETTINGS.new(
        tyre_longitudinal=True, duration=0.5, dt_out=0.01, fast_tolerance=5e-5, fast_max_step=8e-3, fast_ros2=False,
        max_airborne_time=0.5, keep_series=False, chunk_steps=50)
    state, tracked = rosenbrock.FAST_STATE.new(), D.TRACKED.new()
    empty = np.zeros((0, N_SERIES)), np.zeros((0, 12))
    assert rosenbrock.run_fast(y, setup.p, kind, rp, settings, state, tracked, *empty) == PAUSED
    paused = records.read(state)
    assert paused["started"] and 0.0 < paused["t"] < 0.5 and paused["h"] > 0.0
    while rosenbrock.run_fast(y, setup.p, kind, rp, settings, state, tracked, *empty) == PAUSED:
        pass
    assert records.read(state)["t"] == 0.5
    ends = records.read(tracked)
    assert ends["fz_rear_max_n"] > ends["fz_rear_min_n"] > 0.0 and ends["drive_work_j"] > 0.0
    assert ends["taut_max_m"] > ends["taut_min_m"] > 0.0
