"""Table 9 grid, grid specs and sweep plans."""

from __future__ import annotations

import numpy as np
import pytest

from finaldrive.engine import (
    TABLE9_DEFAULT_RWS_M,
    parse_grid,
    product_grid,
    table9_grid,
)


def test_table9_grid_has_1980_designs_in_row_major_order() -> None:
    grid = table9_grid()
    assert grid.shape == (1980, 3)
    cube = grid.reshape(180, 11, 1, 3)
    np.testing.assert_allclose(np.degrees(cube[:, 0, 0, 0]), np.arange(0, 360, 2), atol=1e-12)
    np.testing.assert_allclose(cube[0, :, 0, 1], np.linspace(0, 0.2, 11), atol=1e-15)
    assert cube[0, -1, 0, 1] == 0.2 and cube[0, 3, 0, 1] == 0.06
    assert TABLE9_DEFAULT_RWS_M == 0.093 and np.all(grid[:, 2] == 0.093)
    assert len({tuple(row) for row in grid}) == 1980
    assert np.all(table9_grid(rws=0.05)[:, 2] == 0.05)


def test_table9_spec_and_defaults() -> None:
    grid = table9_grid()
    assert np.array_equal(parse_grid("a2_deg=0:358:2,l2_m=0:0.2:0.02,rws_m=0.093"), grid)
    assert np.array_equal(parse_grid(""), grid)
    assert np.array_equal(parse_grid(" l2_m = 0:0.2:0.02 "), grid)
    assert np.array_equal(parse_grid("rws_m=0.08"), table9_grid(rws=0.08))


def test_grid_syntax() -> None:
    grid = parse_grid("a2_deg=90|0,l2_m=0.1,rws_m=0.05:0.15:0.05")
    expected = product_grid(np.radians([90.0, 0.0]), [0.1], [0.05, 0.1, 0.15])
    np.testing.assert_allclose(grid, expected, rtol=0, atol=1e-15)
    assert grid.shape == (6, 3) and grid[2, 2] == 0.15
    np.testing.assert_allclose(parse_grid("a2_deg=90,l2_m=0,rws_m=0.1"), [[np.pi / 2, 0.0, 0.1]], rtol=1e-15)
    # stop is included only when it lands on the grid (within 1e-9 steps)
    assert parse_grid("a2_deg=0,l2_m=0:0.05:0.02,rws_m=0.1")[:, 1].tolist() == [0.0, 0.02, 0.04]
    assert parse_grid("a2_deg=0,l2_m=0:0.3:0.1,rws_m=0.1")[:, 1].tolist() == [0.0, 0.1, 0.2, 0.3]


@pytest.mark.parametrize("spec, variable", [
    ("l2_m=-0.02", "l2_m"),
    ("l2_m=0.1|-0.1", "l2_m"),
    ("rws_m=0", "rws_m"),
    ("rws_m=-0.1:0.1:0.05", "rws_m"),
    ("a2_deg=0:10:0", "a2_deg"),
    ("a2_deg=0:10:-2", "a2_deg"),
    ("l2_m=0.2:0:0.02", "l2_m"),
    ("l2_m=abc", "l2_m"),
    ("l2_m=0:1", "l2_m"),
    ("rws_m=0.1|0.1", "rws_m"),
    ("rws_m=nan", "rws_m"),
    ("theta=1", "theta"),
    ("l2_m", "l2_m"),
    ("a2_deg=1,a2_deg=2", "a2_deg"),
    ("l2=0.1", "l2"),  # every variable carries its unit
    ("a2_deg=0:1000000:0.0001", "a2_deg"),
])
def test_bad_specs_name_the_variable(spec: str, variable: str) -> None:
    with pytest.raises(ValueError, match=variable):
        parse_grid(spec)
