"""DifferentialEvolution.state(): JSON round trip and exact resume."""

from __future__ import annotations

import json

import numpy as np
import pytest

from finaldrive.engine.optimize import DifferentialEvolution, plain_json

TWO_PI = 2.0 * np.pi
LOWER, UPPER, PERIODIC = [0.0, 0.0, 0.05], [TWO_PI, 0.2, 0.15], [True, False, False]


def fitness(x: np.ndarray) -> np.ndarray:
    """A bumpy landscape with a failed region, like a simulation that sometimes diverges."""
    f = np.cos(x[:, 0] - 3.4) + np.sin(40.0 * x[:, 1]) - 50.0 * (x[:, 2] - 0.09) ** 2
    f[(x[:, 1] > 0.15) & (x[:, 2] < 0.07)] = np.nan
    return f


def make(**kwargs) -> DifferentialEvolution:
    config = {"periodic": PERIODIC, "pop_size": 12, "max_iter": 15, "seed": 2024} | kwargs
    return DifferentialEvolution(LOWER, UPPER, **config)


def finish(de: DifferentialEvolution) -> DifferentialEvolution:
    while not de.done:
        de.tell(fitness(de.ask()))
    return de


def through_json(de: DifferentialEvolution) -> DifferentialEvolution:
    return DifferentialEvolution.from_state(json.loads(json.dumps(de.state(), allow_nan=False)))


def assert_same(a: DifferentialEvolution, b: DifferentialEvolution) -> None:
    assert np.array_equal(a.population, b.population)
    assert np.array_equal(a.fitness, b.fitness, equal_nan=True)
    assert np.array_equal(a.best_x, b.best_x) and a.best_f == b.best_f
    assert (a.generation, a.n_evals, a.stop_reason) == (b.generation, b.n_evals, b.stop_reason)
    assert json.dumps(a.state()) == json.dumps(b.state())


def test_state_is_strict_json() -> None:
    de = make()
    for _ in range(4):
        de.tell(fitness(de.ask()))
    text = json.dumps(de.state(), allow_nan=False)  # NaN fitness is stored as null
    state = json.loads(text)
    assert set(state) >= {"config", "population", "fitness", "generation", "n_evals",
                          "pending", "rng", "history"}
    assert state["generation"] == 3 and state["n_evals"] == 48
    assert len(state["pending"]) == 12


@pytest.mark.parametrize("stop_at", [0, 1, 7, 14])
def test_resume_after_generation_k_is_bit_identical(stop_at: int) -> None:
    reference = finish(make())
    de = make()
    de.tell(fitness(de.ask()))         # initial population = generation 0
    while de.generation < stop_at:
        de.tell(fitness(de.ask()))
    resumed = finish(through_json(de))
    assert_same(resumed, reference)  # compares state() too: history, RNG state


def test_a_state_without_its_history_resumes_the_same_run_and_stays_small() -> None:
    reference = finish(make(max_iter=40))
    de = make(max_iter=40)
    sizes = []
    while de.generation < 20:
        de.tell(fitness(de.ask()))
        state = de.state(history=False)
        assert "history" not in state
        sizes.append(len(json.dumps(state)))
    assert max(sizes[1:]) - min(sizes[1:]) < 100, sizes  # O(NP), not growing with the generations
    resumed = finish(DifferentialEvolution.from_state(json.loads(json.dumps(state))))
    assert np.array_equal(resumed.population, reference.population)
    assert np.array_equal(resumed.fitness, reference.fitness, equal_nan=True)
    assert json.dumps(resumed.state(history=False)) == json.dumps(reference.state(history=False))
    assert resumed.history == reference.history[21:]  # the records told after the resume


def test_a_state_taken_as_arrays_stores_as_the_plain_state() -> None:
    """The scheduler takes states with arrays (cheap to hand to the writer's process), which makes them
    JSON: the text must be the plain state's (failed fitness null), and a run resumed from it the same."""
    reference = finish(make())
    de, failed = make(), 0
    for _ in range(5):
        de.tell(fitness(de.ask()))
        taken = de.state(history=False, arrays=True)
        assert isinstance(taken["population"], np.ndarray) and isinstance(taken["fitness"], np.ndarray)
        failed += int(np.isnan(taken["fitness"]).sum())
        assert json.dumps(plain_json(taken), allow_nan=False) == json.dumps(de.state(history=False))
    assert failed  # the landscape's failed region: NaN stored as null
    de.ask()
    taken = de.state(arrays=True)   # with the pending designs and the history
    assert isinstance(taken["pending"], np.ndarray)
    text = json.dumps(plain_json(taken), allow_nan=False)
    assert text == json.dumps(de.state())
    assert_same(finish(DifferentialEvolution.from_state(json.loads(text))), reference)


def test_resume_before_the_first_tell_and_between_ask_and_tell() -> None:
    reference = finish(make())
    fresh = through_json(make())       # nothing evaluated yet: the initial population is pending
    assert np.array_equal(fresh.ask(), make().ask())
    assert_same(finish(fresh), reference)

    de = make()
    de.tell(fitness(de.ask()))
    asked = de.ask()                    # a crash here: rows asked, never told
    restored = through_json(de)
    assert np.array_equal(restored.ask(), asked)
    assert_same(finish(restored), reference)


def test_resume_with_budget_patience_and_a_finished_run() -> None:
    reference = finish(make(max_iter=100, max_evals=150, patience=30))
    de = make(max_iter=100, max_evals=150, patience=30)
    for _ in range(5):
        de.tell(fitness(de.ask()))
    assert_same(finish(through_json(de)), reference)
    done = through_json(reference)
    assert done.done and done.stop_reason == reference.stop_reason
    with pytest.raises(RuntimeError):
        done.ask()


def test_other_bit_generators_round_trip() -> None:
    for bit_generator in (np.random.MT19937(5), np.random.Philox(5), np.random.SFC64(5)):
        de = make(seed=np.random.Generator(bit_generator))
        de.tell(fitness(de.ask()))
        copy = through_json(de)
        assert_same(finish(copy), finish(de))


def test_unknown_state_version_is_rejected() -> None:
    state = make().state()
    state["version"] = 99
    with pytest.raises(ValueError):
        DifferentialEvolution.from_state(state)
