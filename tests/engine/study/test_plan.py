"""Study plans and runs: what each kind evaluates, resumption, and order independence."""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import (
    PAPER_SWEEP_STEP,
    PRESETS,
    SWEEP_RUN,
    Bounds,
    DERun,
    DESettings,
    PlanError,
    SpaceError,
    SweepRun,
    default_vehicle,
    plan_study,
)


def sphere(designs: np.ndarray, road: int) -> np.ndarray:
    """A toy fitness (maximised) that differs by road; NaN for one design to exercise failures."""
    f = -np.sum((designs - [3.0, 0.1, 0.1]) ** 2, axis=1) - 0.01 * road
    f[designs[:, 1] > 0.19] = np.nan
    return f


def drive(runs: list, *, shuffle: np.random.Generator | None = None, split: int = 0) -> None:
    """Evaluate every run to the end, optionally telling results in random order and in pieces."""
    while requests := [q for run in runs if not run.done for q in run.take()]:
        parts = []
        for q in requests:
            rows = np.arange(len(q))
            pieces = np.array_split(rows, max(1, len(q) // split)) if split else [rows]
            parts += [q.part(p) for p in pieces]
        if shuffle is not None:
            parts = [parts[i] for i in shuffle.permutation(len(parts))]
        by_index = {r.index: r for r in runs}
        for part in parts:
            by_index[part.run].tell(part.road, part.step, part.candidates, sphere(part.designs, part.road))


def test_paper_study_plans_the_papers_104190_simulations() -> None:
    plan = plan_study("paper-study", ["paper"])
    assert (len(plan.roads), plan.n_de_runs, plan.sweep_total(), plan.de_total()) == (23, 23, 45540, 58650)
    assert plan.total() == 104190
    runs = plan.runs()
    assert isinstance(runs[0], SweepRun) and runs[0].index == SWEEP_RUN and runs[0].step == PAPER_SWEEP_STEP
    assert [r.index for r in runs[1:]] == list(range(23)) and all(isinstance(r, DERun) for r in runs[1:])


def test_defaults_are_the_papers_tables_and_the_paper_study_runs_table10() -> None:
    plan = plan_study("de", ["flat"])
    assert plan.bounds == Bounds() and plan.de == DESettings()
    assert Bounds().a2_deg == (0.0, 360.0) and Bounds().l2_m == (0.0, 0.2) and Bounds().rws_m == (0.05, 0.15)
    table10 = DESettings.paper()
    assert (table10.np, table10.f, table10.cp, table10.mp, table10.mr_fraction, table10.iters) == (50, 0.6, 0.6, 0.1,
                                                                                                   0.2, 50)
    assert table10.patience is None and table10.optimiser == "de" and table10.evals_per_run() == 2550
    assert plan_study("paper-study", ["flat"]).de == table10
    assert plan_study("robust-de", ["flat,sine:0.04:3"], de=table10).de_total() == 2 * 2550


def test_the_default_stops_once_converged_and_presets_take_given_fields() -> None:
    """New runs stop early (docs/optimisation.md): DE NP 16, F 0.8, patience 15 rounds of 0.2 mm."""
    default = DESettings()
    assert (default.optimiser, default.np, default.f, default.patience, default.tol_m) == ("de", 16, 0.8, 15, 2e-4)
    assert DESettings.preset("paper", np=20, patience=None) == DESettings(np=20, f=0.6, iters=50, patience=None,
                                                                          tol_m=0.0)
    with pytest.raises(SpaceError, match="optimiser: unknown method 'bfgs'"):
        DESettings(optimiser="bfgs")
    with pytest.raises(SpaceError, match="preset: unknown preset"):
        DESettings.preset("fast")
    with pytest.raises(SpaceError, match="max_evals: must be >= np"):
        DESettings.preset("paper", max_evals=20)
    cma = DESettings(optimiser="cmaes", np=8, sigma=0.2, patience=None).build(Bounds(), seed=3)
    assert cma.method == "cmaes" and len(cma.ask()) == 8



@pytest.mark.parametrize(("kind", "roads", "parts", "field"), [
    ("nope", ["flat"], {}, "kind"),
    ("de", ["flat", "mars"], {}, "roads.1"),
    ("de", ["flat"], {"grid": "table9"}, "grid"),
    ("sweep", ["flat"], {"de": DESettings()}, "de"),
    ("sweep", ["flat"], {"grid": "l2_m=0:oops"}, "grid"),
    ("de", ["flat"], {"aggregate": "mean"}, "aggregate"),
    ("sweep", ["flat"], {"grid": "a2_deg=0,l2_m=0.1|0.25,rws_m=0.09"}, "grid"),      # beyond l2_max
    ("de", ["flat"], {"bounds": Bounds(rws_m=(0.05, 0.21))}, "bounds.rws_m"),    # beyond rt0 - margin
    ("de", ["flat"], {"bounds": Bounds(l2_m=(0.0, 0.3))}, "bounds.l2_m"),
    ("de", ["flat"], {"bounds": Bounds(rws_m=(0.04, 0.15))}, "bounds.rws_m"),    # a 7.7-tooth engine sprocket
    ("sweep", ["flat"], {"grid": "a2_deg=0,l2_m=0.1,rws_m=0.04|0.09"}, "grid"),
    ("sweep", ["sine:0.6:3"], {}, "roads.0"),                                  # higher than the limit
])
def test_plan_errors_name_the_field(kind: str, roads: list[str], parts: dict, field: str) -> None:
    with pytest.raises(PlanError) as info:
        plan_study(kind, roads, **parts)
    assert ".".join(map(str, info.value.loc)) == field


def test_the_vehicle_sets_the_design_limits() -> None:
    roomy = default_vehicle().replace(l2_max=0.3)
    assert plan_study("de", ["flat"], bounds=Bounds(l2_m=(0.0, 0.3)), vehicle=roomy).bounds == Bounds(l2_m=(0.0, 0.3))
    with pytest.raises(PlanError, match=r"limit of 0\.15 m"):
        plan_study("de", ["flat"], vehicle=default_vehicle().replace(l2_max=0.15))


def test_the_smallest_wheel_sprocket_follows_the_chain_and_the_fewest_teeth() -> None:
    """R = p / (2 sin(pi / N)): Table 8's smallest R_WS (0.05 m) gives a 9.7-tooth engine sprocket of a
    520 chain, allowed by the default 9 teeth; 13 teeth (a buildable one) move the bound to 0.0663 m."""
    from finaldrive.engine import Design, DesignError
    from finaldrive.engine.vehicle import sprocket_teeth

    v = default_vehicle()
    assert sprocket_teeth(0.025, 0.015875) == pytest.approx(9.7235, abs=1e-4)
    assert sprocket_teeth(v.rws_min() / v["sprocket_ratio"], v["chain_pitch"]) == pytest.approx(9.0)
    buildable = v.replace(min_sprocket_teeth=13.0)
    assert buildable.rws_min() == pytest.approx(0.06633, abs=1e-5)
    with pytest.raises(PlanError, match=r"smallest R_WS of 0\.0663"):
        plan_study("de", ["flat"], vehicle=buildable)
    with pytest.raises(DesignError, match=r"would have 7\.7 teeth"):
        v.check_design(Design.from_deg(0.0, 0.0, 0.04))
    with pytest.raises(DesignError, match=r"less than half the 15\.875 mm chain pitch: no sprocket fits"):
        v.check_design(Design.from_deg(0.0, 0.0, 0.01))


@pytest.mark.parametrize(("make", "field"), [
    (lambda: Bounds(l2_m=(0.2, 0.1)), "l2_m"),
    (lambda: Bounds(a2_deg=(0.0, 400.0)), "a2_deg"),
    (lambda: Bounds(rws_m=(0.0, 0.1)), "rws_m"),
    (lambda: Bounds(l2_m=(0.0, float("inf"))), "l2_m"),
    (lambda: Bounds.parse("l2_m=1"), "l2_m"),
    (lambda: Bounds.parse("theta=0:1"), "theta"),
    (lambda: DESettings(np=3), "np"),
    (lambda: DESettings(np=10, max_evals=5), "max_evals"),
    (lambda: DESettings(cp=1.5), "cp"),
    (lambda: DESettings(iters=10**400), "iters"),
])
def test_space_errors_name_the_field(make, field: str) -> None:
    with pytest.raises(SpaceError) as info:
        make()
    assert info.value.field == field


def test_a_de_is_bit_identical_whatever_the_order_and_splitting_of_its_work() -> None:
    def final(**how) -> np.ndarray:
        plan = plan_study("de", ["flat,sine:0.04:3"], de=DESettings(np=12, iters=8), seed=5)
        runs = plan.runs()
        drive(runs, **how)
        return np.stack([r.optimiser.population for r in runs])

    reference = final()
    np.testing.assert_array_equal(final(shuffle=np.random.default_rng(1), split=5), reference)
    np.testing.assert_array_equal(final(shuffle=np.random.default_rng(2), split=1), reference)


def test_a_resumed_de_continues_exactly() -> None:
    plan = plan_study("robust-de", ["flat,sine:0.04:3"], de=DESettings(np=8, iters=6), aggregate="worst", seed=3)
    whole = plan.runs()
    drive(whole)
    first = plan.runs()
    run = first[0]
    for _ in range(3):  # three generations, then "stop" and keep the state
        requests = run.take()
        for q in requests:
            run.tell(q.road, q.step, q.candidates, sphere(q.designs, q.road))
    resumed = plan.runs(de_states={0: (run.optimiser.state(), run.generation)})
    assert resumed[0].generation == 3
    drive(resumed)
    np.testing.assert_array_equal(resumed[0].optimiser.population, whole[0].optimiser.population)
    assert resumed[0].optimiser.best_f == whole[0].optimiser.best_f


def test_a_resumed_sweep_hands_out_only_what_is_missing() -> None:
    plan = plan_study("sweep", ["flat,sine:0.04:3"], grid="a2_deg=0:90:30,l2_m=0|0.1,rws_m=0.093")
    assert plan.sweep_total() == 2 * 8
    run = plan.runs(sweep_done={(0, 0), (0, 1), (1, 7)})[0]
    requests = run.take()
    assert [(q.road, q.candidates.tolist()) for q in requests] == [(0, [2, 3, 4, 5, 6, 7]), (1, list(range(7)))]
    assert run.take() == [] and not run.done
    for q in requests:
        run.tell(q.road, q.step, q.candidates, np.zeros(len(q)))
    assert run.done


def test_spec_roads_equal_to_a_preset_carry_the_paper_row() -> None:
    plan = plan_study("sweep", ["sine:0.04:3", "flat,sine:0.04:3"])
    assert [r.name for r in plan.roads] == ["sine:0.04:3", "flat"]
    assert plan.roads[0].paper == PRESETS["sine:0.04:3"].paper
