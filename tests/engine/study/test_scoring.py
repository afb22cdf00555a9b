"""Scores over several roads and regret against each road's optimum."""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import aggregate, best_per_road, regret

NAN = np.nan
TABLE = np.array([
    [20.0, 19.0, 21.0, NAN],     # road 0
    [18.0, 19.5, 17.0, 20.0],    # road 1
])


def test_mean_and_worst() -> None:
    np.testing.assert_array_equal(aggregate(TABLE, "mean"), [19.0, 19.25, 19.0, NAN])
    np.testing.assert_array_equal(aggregate(TABLE, "worst"), [18.0, 19.0, 17.0, NAN])
    np.testing.assert_array_equal(aggregate(TABLE), aggregate(TABLE, "mean"))


def test_failed_on_any_road_is_failed() -> None:
    table = TABLE.copy()
    table[1, 0] = -np.inf
    score = aggregate(table, "worst")
    assert np.isnan(score[0]) and np.isnan(score[3]) and score[1] == 19.0


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="median"):
        aggregate(TABLE, "median")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        aggregate(np.zeros(3))


def test_best_per_road_ignores_failures() -> None:
    np.testing.assert_array_equal(best_per_road(TABLE), [21.0, 20.0])
    assert np.isnan(best_per_road([[NAN, NAN], [1.0, 2.0]])[0])


def test_regret_absolute_and_percent() -> None:
    r = regret(TABLE, best_per_road(TABLE))
    np.testing.assert_allclose(r.absolute_m, [[1.0, 2.0, 0.0, NAN], [2.0, 0.5, 3.0, 0.0]])
    np.testing.assert_allclose(r.percent, 100 * r.absolute_m / np.array([[21.0], [20.0]]))
    one = regret([20.0, 19.0], [20.708, 20.0])            # one design against the paper's rows
    np.testing.assert_allclose(one.absolute_m, [0.708, 1.0])
    np.testing.assert_allclose(one.percent, [100 * 0.708 / 20.708, 5.0])
    with pytest.raises(ValueError):
        regret(TABLE, [1.0, 2.0, 3.0])
