"""Design grids for sweeps: the paper's Table 9 grid and user grids from a spec string.

A design is a row (a2 [rad], L2 [m], R_WS [m]). Every grid here is the Cartesian product
of one value list per variable, in row-major order over (a2, l2, rws): a2 varies
slowest and rws fastest, so ``grid.reshape(n_a2, n_l2, n_rws, 3)`` recovers the axes.

Table 9 (paper section 5.1): L2 = 0, 0.02, ..., 0.2 m (11 values) x a2 = 0, 2, ..., 358
deg (180 values; 360 deg is 0 deg again) = 1,980 designs a road, 45,540 for the 23
roads. The sweep optimises a2 and L2 only and the paper does not say which wheel sprocket
radius it used. The default, ``TABLE9_DEFAULT_RWS_M = 0.093`` m, is the mean of the 23
DE optima that the paper itself uses for its geometry 1 (section 5.3, Table 14).

Grid spec syntax (``parse_grid``): comma-separated ``name=values`` items, where name is

- ``a2_deg`` (degrees), ``l2_m`` (m), ``rws_m`` (m) (docs/fields.md);

and values is one of

- ``start:stop:step``: start, start + step, ... up to stop; stop is included when it
  lands on the grid within 1e-9 steps (``0:0.2:0.02`` gives 11 values, ending at 0.2);
- ``a|b|c``: an explicit list, kept in the given order;
- ``v``: a single value.

A variable not named takes its Table 9 value (a2_deg = 0:358:2, l2_m = 0:0.2:0.02,
rws_m = 0.093), so ``"rws_m=0.08"`` is Table 9 at R_WS = 80 mm and the empty spec is Table 9.
Range values are rounded to 12 decimals (0.06, not 0.06000000000000001).
Example: ``"a2_deg=0:358:2,l2_m=0:0.2:0.02,rws_m=0.093"`` == Table 9.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

#: R_WS of the Table 9 sweep [m]: not stated in the paper; the mean of its 23 DE optima (section 5.3).
TABLE9_DEFAULT_RWS_M = 0.093
#: Table 9 axes.
TABLE9_A2_DEG = (0.0, 358.0, 2.0)
TABLE9_L2_M = (0.0, 0.2, 0.02)
#: Largest grid parse_grid builds (a guard against typos such as a step of 1e-6).
MAX_GRID_DESIGNS = 1_000_000

_VARIABLES = ("a2_deg", "l2_m", "rws_m")
_GRID_TOL = 1e-9


def table9_grid(rws: float = TABLE9_DEFAULT_RWS_M) -> np.ndarray:
    """Table 9's 1,980 designs (n, 3): a2 [rad], L2 [m], R_WS = ``rws`` [m]."""
    return product_grid(
        np.radians(_range("a2_deg", *TABLE9_A2_DEG)),
        _range("l2_m", *TABLE9_L2_M),
        _check("rws_m", np.array([float(rws)])),
    )


def product_grid(a2_rad: npt.ArrayLike, l2_m: npt.ArrayLike, rws_m: npt.ArrayLike) -> np.ndarray:
    """Cartesian product (n, 3) of value lists, a2 slowest, rws fastest."""
    axes = np.meshgrid(np.asarray(a2_rad, float), np.asarray(l2_m, float),
                       np.asarray(rws_m, float), indexing="ij")
    return np.stack([a.ravel() for a in axes], axis=1)


def parse_grid(spec: str) -> np.ndarray:
    """Designs (n, 3) from a grid spec (module docstring); ValueError names the variable."""
    if not isinstance(spec, str):
        raise ValueError("grid spec must be a string")
    values: dict[str, np.ndarray] = {}
    for raw in spec.split(",") if spec.strip() else []:
        name, sep, text = (part.strip() for part in raw.partition("="))
        name = name.lower()
        if not sep:
            raise ValueError(f"grid item {raw.strip()!r}: expected name=values")
        if name not in _VARIABLES:
            raise ValueError(f"unknown grid variable {name!r}: expected one of {', '.join(_VARIABLES)}")
        if name in values:
            raise ValueError(f"{name}: grid variable given twice")
        values[name] = _check(name, _values(name, text))
    a2 = np.radians(values.get("a2_deg", _range("a2_deg", *TABLE9_A2_DEG)))
    l2 = values.get("l2_m", _range("l2_m", *TABLE9_L2_M))
    rws = values.get("rws_m", np.array([TABLE9_DEFAULT_RWS_M]))
    n = a2.size * l2.size * rws.size
    if n > MAX_GRID_DESIGNS:
        raise ValueError(f"grid has {n:,} designs, more than {MAX_GRID_DESIGNS:,}")
    return product_grid(a2, l2, rws)


# ---------------------------------------------------------------------- helpers
def _values(name: str, text: str) -> np.ndarray:
    parts = text.split(":") if ":" in text else text.split("|")
    try:
        numbers = [float(p) for p in parts]
    except ValueError:
        numbers = []
    if not numbers or (":" in text and len(numbers) != 3):
        raise ValueError(
            f"{name}: bad values {text!r}: expected start:stop:step, a|b|c or a number"
        )
    return _range(name, *numbers) if ":" in text else np.array(numbers)


def _range(name: str, start: float, stop: float, step: float) -> np.ndarray:
    """start, start + step, ..., stop included when it lands on the grid within 1e-9 steps."""
    if not all(math.isfinite(v) for v in (start, stop, step)):
        raise ValueError(f"{name}: start, stop and step must be finite")
    if step <= 0:
        raise ValueError(f"{name}: step must be > 0, got {step:g}")
    if stop < start:
        raise ValueError(f"{name}: stop {stop:g} is below start {start:g}")
    count = math.floor((stop - start) / step + _GRID_TOL) + 1
    if count > MAX_GRID_DESIGNS:
        raise ValueError(f"{name}: {count:,} values, more than {MAX_GRID_DESIGNS:,}")
    v = np.round(start + step * np.arange(count), 12)  # 0.06, not 0.06000000000000001
    if abs(v[-1] - stop) <= _GRID_TOL * step:
        v[-1] = stop  # land exactly on stop
    return v


def _check(name: str, v: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: values must be finite numbers")
    if name == "l2_m" and np.any(v < 0):
        raise ValueError(f"l2_m: L2 must be >= 0 m, got {v.min():g}")
    if name == "rws_m" and np.any(v <= 0):
        raise ValueError(f"rws_m: R_WS must be > 0 m, got {v.min():g}")
    if np.unique(v).size != v.size:
        raise ValueError(f"{name}: repeated values")
    return v
