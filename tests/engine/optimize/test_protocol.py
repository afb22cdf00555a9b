"""Every registered optimiser through the protocol: toy optima, exact resume, budgets, stopping."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from finaldrive.engine.optimize import CMAES, OPTIMISERS, DifferentialEvolution, Optimiser, restore

TWO_PI = 2.0 * np.pi
LOWER, UPPER, PERIODIC = [0.0, -5.0, -5.0], [TWO_PI, 5.0, 5.0], [True, False, False]
ANGLE_OPT = 6.2  # close to 2 pi: the optimum's basin wraps past 0


def neg_sphere(x: np.ndarray) -> np.ndarray:
    da = np.mod(x[:, 0] - ANGLE_OPT + np.pi, TWO_PI) - np.pi
    return -(da**2 + (x[:, 1] - 1.0) ** 2 + (x[:, 2] + 2.0) ** 2)


def make(method: str, **kwargs: Any) -> Optimiser:
    return OPTIMISERS[method](LOWER, UPPER, periodic=PERIODIC, **kwargs)


def run(opt: Optimiser, f: Any = neg_sphere) -> Optimiser:
    while not opt.done:
        opt.tell(f(opt.ask()))
    return opt


def test_both_methods_are_registered_and_follow_the_protocol() -> None:
    assert {"de": DifferentialEvolution, "cmaes": CMAES} == OPTIMISERS
    for method in OPTIMISERS:
        opt = make(method, seed=0)
        assert isinstance(opt, Optimiser) and opt.method == method
        assert opt.state()["method"] == method


@pytest.mark.parametrize("method", list(OPTIMISERS))
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_optimum_is_found_across_the_periodic_seam(method: str, seed: int) -> None:
    opt = run(make(method, seed=seed, max_iter=150, pop_size=20))
    assert opt.best_f > -1e-4
    assert abs(np.mod(opt.best_x[0] - ANGLE_OPT + np.pi, TWO_PI) - np.pi) < 1e-2
    np.testing.assert_allclose(opt.best_x[1:], [1.0, -2.0], atol=1e-2)


@pytest.mark.parametrize("method", list(OPTIMISERS))
def test_rows_stay_in_the_box(method: str) -> None:
    opt = make(method, seed=4, max_iter=40, sigma=1.0) if method == "cmaes" else make(method, seed=4, max_iter=40)
    while not opt.done:
        x = opt.ask()
        assert np.all(x >= LOWER) and np.all(x[:, 1:] <= UPPER[1:]) and np.all(x[:, 0] < TWO_PI)
        opt.tell(-np.abs(x[:, 1] - 5.0))  # the optimum on the upper bound of x1


@pytest.mark.parametrize("method", list(OPTIMISERS))
def test_a_json_round_trip_of_the_state_continues_bit_for_bit(method: str) -> None:
    """Restored after every round (through JSON, as the store keeps it), the run asks exactly the
    rows of an uninterrupted one; for CMA-ES across its restarts too (a flat function converges)."""
    def f(x: np.ndarray) -> np.ndarray:
        return np.round(neg_sphere(x), 2)  # plateaus: cmaes converges and restarts

    whole, resumed = make(method, seed=7, max_iter=150), make(method, seed=7, max_iter=150)
    while not whole.done:
        x = whole.ask()
        np.testing.assert_array_equal(x, resumed.ask())
        whole.tell(f(x))
        resumed.tell(f(x))
        resumed = restore(json.loads(json.dumps(resumed.state(history=False), allow_nan=False)))
    assert resumed.done and resumed.best_f == whole.best_f and resumed.n_evals == whole.n_evals
    if method == "cmaes":
        assert isinstance(whole, CMAES) and whole.restarts >= 1


def test_a_state_without_a_method_is_the_des_and_an_unknown_method_is_refused() -> None:
    state = make("de", seed=1).state()
    del state["method"]
    assert isinstance(restore(state), DifferentialEvolution)
    with pytest.raises(ValueError, match="unknown optimiser 'nope'"):
        restore({**state, "method": "nope"})


@pytest.mark.parametrize("method", list(OPTIMISERS))
def test_max_evals_is_never_exceeded(method: str) -> None:
    opt = run(make(method, seed=3, max_iter=1000, max_evals=101, pop_size=10))
    assert opt.n_evals == 101 and opt.stop_reason == "max_evals"
    assert opt.history[-1]["n_evals"] == 101


@pytest.mark.parametrize("method", list(OPTIMISERS))
def test_gains_below_tol_are_not_progress(method: str) -> None:
    """Fitness within 1e-6 of 0: with tol 1e-3 no round is progress, so the run stops exactly
    ``patience`` rounds after the first; with tol 0 the same run keeps improving past that."""
    def tiny(x: np.ndarray) -> np.ndarray:
        return 1e-8 * neg_sphere(x)

    stopped = run(make(method, seed=5, max_iter=200, patience=6, tol=1e-3), tiny)
    assert stopped.stop_reason == "patience" and stopped.generation == 6
    going = run(make(method, seed=5, max_iter=200, patience=6, tol=0.0), tiny)
    assert going.generation > 20


@pytest.mark.parametrize("method", list(OPTIMISERS))
def test_failed_evaluations_are_never_best(method: str) -> None:
    def holes(x: np.ndarray) -> np.ndarray:
        f = neg_sphere(x)
        return np.where(x[:, 1] > 0.5, np.nan, f)  # the true optimum (x1 = 1) fails

    opt = run(make(method, seed=2, max_iter=60), holes)
    assert np.isfinite(opt.best_f) and opt.best_x[1] <= 0.5
    assert sum(h["n_failed"] for h in opt.history) > 0


def test_cmaes_restarts_double_the_population() -> None:
    opt = make("cmaes", seed=0, max_iter=300, pop_size=6)
    sizes = []
    while not opt.done:
        x = opt.ask()
        sizes.append(len(x))
        opt.tell(np.round(neg_sphere(x), 1))
    assert sizes[0] == 6 and 12 in sizes and max(sizes) >= 24


def test_a_cmaes_state_with_non_finite_history_is_strict_json_and_resumes() -> None:
    """cmaes starts its history of values with np.empty (garbage, overwritten before it is read): a
    NaN there is stored as null (PostgreSQL's JSON refuses NaN) and the run continues exactly."""
    opt = make("cmaes", seed=9, max_iter=40)
    opt.tell(neg_sphere(opt.ask()))
    assert isinstance(opt, CMAES)
    opt._cma._funhist_values[-2:] = [np.nan, np.inf]
    resumed = restore(json.loads(json.dumps(opt.state(), allow_nan=False)))
    while not opt.done:
        x = opt.ask()
        np.testing.assert_array_equal(x, resumed.ask())
        opt.tell(neg_sphere(x))
        resumed.tell(neg_sphere(x))
    assert resumed.best_f == opt.best_f
