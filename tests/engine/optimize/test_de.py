"""DifferentialEvolution on toy functions, bounds, failures, budgets and stopping rules."""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine.optimize import DifferentialEvolution

TWO_PI = 2.0 * np.pi
#: Optimum angle of the periodic first variable: close to 2 pi, so its basin wraps past 0.
ANGLE_OPT = 6.2


def wrap(u: np.ndarray) -> np.ndarray:
    """Signed angle difference in [-pi, pi)."""
    return np.mod(u + np.pi, TWO_PI) - np.pi


def neg_sphere(x: np.ndarray) -> np.ndarray:
    return -(wrap(x[:, 0] - ANGLE_OPT) ** 2 + x[:, 1] ** 2 + x[:, 2] ** 2)


def neg_rosenbrock(x: np.ndarray) -> np.ndarray:
    u = np.column_stack([1.0 + wrap(x[:, 0] - ANGLE_OPT), x[:, 1], x[:, 2]])
    return -np.sum(100.0 * (u[:, 1:] - u[:, :-1] ** 2) ** 2 + (1.0 - u[:, :-1]) ** 2, axis=1)


def neg_rastrigin(x: np.ndarray) -> np.ndarray:
    u = np.column_stack([wrap(x[:, 0] - ANGLE_OPT) * 5.12 / np.pi, x[:, 1], x[:, 2]])
    return -(30.0 + np.sum(u**2 - 10.0 * np.cos(2.0 * np.pi * u), axis=1))


# name: (function, lower, upper, optimum, max_iter, tolerance on x)
TOYS = {
    "sphere": (neg_sphere, [0, -5, -5], [TWO_PI, 5, 5], [ANGLE_OPT, 0, 0], 50, 1e-4),
    "rosenbrock": (neg_rosenbrock, [0, -2, -2], [TWO_PI, 3, 3], [ANGLE_OPT, 1, 1], 120, 1e-3),
    "rastrigin": (neg_rastrigin, [0, -5.12, -5.12], [TWO_PI, 5.12, 5.12], [ANGLE_OPT, 0, 0], 120, 1e-3),
}


def run(de: DifferentialEvolution, func) -> DifferentialEvolution:
    while not de.done:
        de.tell(func(de.ask()))
    return de


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
@pytest.mark.parametrize("name", sorted(TOYS))
def test_toy_functions_reach_the_optimum(name: str, seed: int) -> None:
    func, lower, upper, optimum, max_iter, tol = TOYS[name]
    de = run(DifferentialEvolution(lower, upper, periodic=[True, False, False],
                                   max_iter=max_iter, seed=seed), func)
    error = np.abs(de.best_x - optimum)
    error[0] = abs(wrap(de.best_x[0] - optimum[0]))
    assert np.all(error < tol), (name, seed, de.best_x)
    assert de.best_f > -1e-5
    assert de.best_f == pytest.approx(func(de.best_x[None])[0], abs=0)


def test_table10_defaults_cost_2550_evaluations() -> None:
    de = DifferentialEvolution([0, 0, 0.05], [TWO_PI, 0.2, 0.15], periodic=[True, False, False])
    assert (de.pop_size, de.f, de.cp, de.mp, de.mr_fraction, de.max_iter) == (50, 0.6, 0.6, 0.1, 0.2, 50)
    sizes = []
    while not de.done:
        x = de.ask()
        sizes.append(len(x))
        de.tell(-np.sum(x**2, axis=1))
    assert de.n_evals == sum(sizes) == 2550 == 50 + 50 * 50
    assert sizes == [50] * 51
    assert de.generation == 50 and de.stop_reason == "max_iter"
    assert [h["generation"] for h in de.history] == list(range(51))


def test_same_seed_is_bit_identical_and_generator_seed_works() -> None:
    a = run(DifferentialEvolution([0, -5, -5], [TWO_PI, 5, 5], periodic=[1, 0, 0], seed=7), neg_sphere)
    b = run(DifferentialEvolution([0, -5, -5], [TWO_PI, 5, 5], periodic=[1, 0, 0],
                                  seed=np.random.default_rng(7)), neg_sphere)
    c = run(DifferentialEvolution([0, -5, -5], [TWO_PI, 5, 5], periodic=[1, 0, 0], seed=8), neg_sphere)
    assert np.array_equal(a.population, b.population) and np.array_equal(a.fitness, b.fitness)
    assert not np.array_equal(a.population, c.population)


def test_evaluation_order_cannot_matter() -> None:
    """Results computed in a shuffled order but told by index give the identical run."""
    reference = run(DifferentialEvolution([0, -2, -2], [TWO_PI, 3, 3], periodic=[1, 0, 0],
                                          max_iter=20, seed=3), neg_rosenbrock)
    de = DifferentialEvolution([0, -2, -2], [TWO_PI, 3, 3], periodic=[1, 0, 0], max_iter=20, seed=3)
    shuffler = np.random.default_rng(99)
    while not de.done:
        x = de.ask()
        order = shuffler.permutation(len(x))
        fitness = np.empty(len(x))
        for i in order:  # "workers" finish in any order; each result goes back to its row
            fitness[i] = neg_rosenbrock(x[i : i + 1])[0]
        de.tell(fitness)
    assert np.array_equal(de.population, reference.population)
    assert np.array_equal(de.fitness, reference.fitness)
    assert de.history == reference.history


def test_ask_is_idempotent_until_tell() -> None:
    de = DifferentialEvolution([0, 0], [1, 1], pop_size=6, seed=0)
    assert np.array_equal(de.ask(), de.ask())
    first = de.ask()
    first[:] = 99.0  # the caller's copy; the optimiser is unaffected
    assert np.all(de.ask() <= 1.0)
    with pytest.raises(ValueError):
        de.tell(np.zeros(5))


def test_failed_region_is_never_best() -> None:
    """NaN (and -inf) where x1 > 0: the best finite point lies on the failure edge."""

    def func(x: np.ndarray) -> np.ndarray:
        f = x[:, 1] - 0.1 * wrap(x[:, 0] - 1.0) ** 2 - 0.1 * x[:, 2] ** 2
        f[x[:, 1] > 0.0] = np.nan
        f[x[:, 1] > 0.5] = -np.inf
        return f

    de = run(DifferentialEvolution([0, -1, -1], [TWO_PI, 1, 1], periodic=[1, 0, 0],
                                   max_iter=60, seed=5), func)
    assert np.isfinite(de.best_f)
    assert de.best_x[1] <= 0.0
    assert de.best_x[1] > -1e-3 and abs(de.best_x[0] - 1.0) < 0.05
    assert np.all(np.isfinite(de.fitness))  # survivors are finite once enough finite exist
    assert sum(h["n_failed"] for h in de.history) > 0


def test_all_failed_generation_keeps_running() -> None:
    de = DifferentialEvolution([0], [1], pop_size=4, max_iter=3, seed=0)
    de.tell([np.nan] * 4)
    assert np.isnan(de.best_f) and de.history[0]["n_failed"] == 4
    assert np.isnan(de.history[0]["mean_f"])
    de.tell([np.nan, 1.0, -np.inf, np.inf])  # +inf is a failure too
    assert de.best_f == 1.0
    assert np.isnan(de.fitness[1:]).all()


def test_bounds_are_respected_and_periodic_dimension_wraps() -> None:
    lower, upper = np.array([0.0, -1.0, 2.0]), np.array([TWO_PI, 1.0, 2.5])
    # A huge F and MR throw donors far outside the box every generation.
    de = DifferentialEvolution(lower, upper, periodic=[True, False, False], f=5.0, mp=0.9,
                               mr_fraction=3.0, pop_size=20, max_iter=30, seed=11)
    rng = np.random.default_rng(0)
    while not de.done:
        x = de.ask()
        assert np.all(x >= lower) and np.all(x <= upper)
        assert np.all(x[:, 0] < TWO_PI)  # [0, 2 pi): 2 pi itself wraps to 0
        de.tell(rng.normal(size=len(x)))


def test_bound_maps() -> None:
    de = DifferentialEvolution([0.0, 0.0, 5.0], [TWO_PI, 1.0, 5.0], periodic=[True, False, False], seed=0)
    x = np.array([
        [TWO_PI + 0.5, -0.25, 7.0],   # wrap; reflect at the lower bound; fixed dimension
        [-0.5, 1.25, 5.0],            # wrap from below; reflect at the upper bound
        [TWO_PI, 3.5, 5.0],           # 2 pi -> 0; fold twice: 3.5 -> -1.5 -> 0.5
        [-1e-17, 0.3, 5.0],           # a tiny negative angle must not round to 2 pi
    ])
    got = de._bound(x)
    want = np.array([[0.5, 0.25, 5.0], [TWO_PI - 0.5, 0.75, 5.0], [0.0, 0.5, 5.0], [0.0, 0.3, 5.0]])
    np.testing.assert_allclose(got, want, atol=1e-12)
    assert got[3, 0] < TWO_PI
    inside = np.array([[1.0, 0.3, 5.0]])
    assert np.array_equal(de._bound(inside), inside)  # in-bounds values are untouched


def test_periodic_difference_goes_the_short_way_round() -> None:
    """A population straddling 0 = 2 pi makes small donor steps on the angle."""
    de = DifferentialEvolution([0.0], [TWO_PI], periodic=[True], pop_size=10, mp=0.0, cp=1.0, seed=0)
    angles = np.array([0.01, 0.02, 0.03, 0.04, 0.05, 6.24, 6.25, 6.26, 6.27, 6.28])
    de._pending = angles[:, None]
    de.tell(-np.abs(wrap(angles)))
    steps = wrap(de.ask()[:, 0] - de.best_x[0])
    assert np.all(np.abs(steps) <= 0.6 * 0.1 + 1e-12)


def test_max_evals_is_never_exceeded_and_last_generation_is_truncated() -> None:
    de = DifferentialEvolution([0, 0], [1, 1], pop_size=10, max_iter=100, max_evals=37, seed=2)
    sizes = []
    while not de.done:
        x = de.ask()
        sizes.append(len(x))
        de.tell(-np.sum((x - 0.5) ** 2, axis=1))
    assert sizes == [10, 10, 10, 7]
    assert de.n_evals == 37 and de.stop_reason == "max_evals"
    assert len(de.population) == 10
    with pytest.raises(RuntimeError):
        de.ask()
    with pytest.raises(ValueError):
        DifferentialEvolution([0], [1], pop_size=10, max_evals=9)


def test_patience_stops_on_a_plateau() -> None:
    de = DifferentialEvolution([0, 0], [1, 1], pop_size=8, max_iter=100, patience=4, seed=0)
    while not de.done:
        x = de.ask()
        de.tell(np.zeros(len(x)))  # nothing ever improves
    assert de.stop_reason == "patience" and de.generation == 4


def test_patience_counts_from_the_last_improvement() -> None:
    de = DifferentialEvolution([0], [1], pop_size=4, max_iter=100, patience=2, seed=0)
    de.tell([0.0] * 4)
    de.tell([1.0, 0, 0, 0])   # generation 1 improves
    de.tell([0.0] * 4)        # 2: stall 1
    assert not de.done
    de.tell([0.0] * 4)        # 3: stall 2
    assert de.stop_reason == "patience" and de.generation == 3


def test_max_iter_zero_evaluates_the_initial_population_only() -> None:
    de = DifferentialEvolution([0], [1], pop_size=5, max_iter=0, seed=0)
    de.tell(np.arange(5.0))
    assert de.done and de.stop_reason == "max_iter" and de.best_f == 4.0


def test_selection_keeps_the_best_of_parents_and_offspring() -> None:
    de = DifferentialEvolution([0], [1], pop_size=4, seed=0)
    parents = de.ask()
    de.tell([4.0, 3.0, 2.0, 1.0])
    offspring = de.ask()
    de.tell([2.5, 0.0, 5.0, 2.0])  # offspring 3 ties with a parent: the offspring wins
    assert de.fitness.tolist() == [5.0, 4.0, 3.0, 2.5]
    np.testing.assert_array_equal(de.population[:, 0], [offspring[2, 0], parents[0, 0], parents[1, 0], offspring[0, 0]])
    de.ask()
    de.tell([2.0, 2.0, 2.0, 2.0])
    assert de.fitness.tolist() == [5.0, 4.0, 3.0, 2.5]


@pytest.mark.parametrize(
    "kwargs",
    [
        {"pop_size": 1},
        {"cp": 1.5},
        {"mp": -0.1},
        {"f": float("nan")},
        {"max_iter": -1},
        {"patience": 0},
        {"periodic": [True]},
        {"pop_size": 2.5},
    ],
)
def test_bad_configuration_is_rejected(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        DifferentialEvolution([0, 0], [1, 1], **kwargs)


def test_bad_bounds_are_rejected() -> None:
    with pytest.raises(ValueError):
        DifferentialEvolution([0, 1], [1, 0])
    with pytest.raises(ValueError):
        DifferentialEvolution([0, 0], [0, 1], periodic=[True, False])
    with pytest.raises(ValueError):
        DifferentialEvolution([], [])


def test_optimiser_imports_numpy_and_stdlib_only() -> None:
    import ast
    from pathlib import Path

    import finaldrive.engine.optimize.de as module
    tree = ast.parse(Path(module.__file__).read_text())
    roots = {alias.name.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.Import)
             for alias in node.names}
    roots |= {node.module.split(".")[0] for node in ast.walk(tree)
              if isinstance(node, ast.ImportFrom) and node.module}
    assert roots <= {"__future__", "math", "collections", "typing", "numpy", "finaldrive"}
    assert {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
            and node.module and node.module.startswith("finaldrive")} <= {"finaldrive.engine.optimize.common"}
