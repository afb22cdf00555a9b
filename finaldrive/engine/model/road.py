"""Road profiles, eqs. (32)-(33): flat, sinusoidal, Gaussian bump, and a user profile.

The road is the height y(x) under both tyre contact points (points 14 and 15).
x = 0 is the rear tyre's initial contact point (reference choice, docs/engine.md#reading-notes-reference-choices).

A road is described by a frozen, picklable :class:`Road`; the compiled model reads it
as a kind code plus a flat parameter array (see :meth:`Road.packed`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

FLAT, SINE, BUMP, PROFILE = 0, 1, 2, 3
_KIND_CODES = {"flat": FLAT, "sine": SINE, "bump": BUMP, "profile": PROFILE}

#: Gaussian bump centre when the spec gives none (reference choice, docs/engine.md#reading-notes-reference-choices).
DEFAULT_BUMP_CENTRE_M = 5.0


#: Limits of road parameters [m] (docs/engine.md#road-limits): beyond them a road is not one this
#: model can drive (a height above the tyre's radius, a wave shorter than the contact patch) or
#: no different from a flat one over any run (a wave or bump longer than 10 km).
MAX_HEIGHT_M = 0.5
MIN_WAVELENGTH_M = 0.05
MIN_SIGMA_M = 0.01
MAX_LENGTH_M = 10_000.0
#: A measured profile: 2 to PROFILE_MAX_POINTS points, x within +-MAX_LENGTH_M, y within +-PROFILE_MAX_Y_M.
PROFILE_MIN_POINTS = 2
PROFILE_MAX_POINTS = 100_000
PROFILE_MAX_Y_M = 1_000.0


class RoadError(ValueError):
    """A road spec that cannot be parsed or is not physical; ``row`` is the profile point at fault (0-based)."""

    def __init__(self, msg: str, row: int | None = None) -> None:
        super().__init__(msg if row is None else f"row {row}: {msg}")
        self.msg = msg
        self.row = row


@dataclass(frozen=True)
class Road:
    """One road profile.

    kind: ``flat`` (32c), ``sine`` (32a: H_y sin(2 pi x / lambda + phi); the paper's phi = 0), ``bump``
    (32b: H_y exp(-(x - mu)^2 / (2 sigma^2))) or ``profile`` (piecewise-linear
    through user points, constant beyond the ends).
    """

    kind: str = "flat"
    height: float = 0.0       # H_y [m]
    wavelength: float = 0.0   # lambda [m], sine only
    phase_deg: float = 0.0    # phi [deg], sine only: where in its period the road starts (beyond the paper)
    sigma: float = 0.0        # bump width [m]
    mu: float = DEFAULT_BUMP_CENTRE_M  # bump centre [m]
    xs: tuple[float, ...] = field(default=())  # profile only
    ys: tuple[float, ...] = field(default=())
    name: str = ""            # profile only: a label for the spec string

    def __post_init__(self) -> None:
        if self.kind not in _KIND_CODES:
            raise RoadError(f"unknown road kind {self.kind!r}")
        for key in ("height", "wavelength", "phase_deg", "sigma", "mu"):
            if not math.isfinite(getattr(self, key)):
                raise RoadError(f"road {key} must be a finite number")
        if abs(self.height) > MAX_HEIGHT_M:
            raise RoadError(f"road height H must be within +-{MAX_HEIGHT_M:g} m, got {self.height:g}")
        if abs(self.mu) > MAX_LENGTH_M:
            raise RoadError(f"bump centre MU must be within +-{MAX_LENGTH_M:g} m, got {self.mu:g}")
        if self.kind == "sine" and not MIN_WAVELENGTH_M <= self.wavelength <= MAX_LENGTH_M:
            raise RoadError(f"sine road: wavelength LAMBDA must be in [{MIN_WAVELENGTH_M:g}, {MAX_LENGTH_M:g}] m, "
                            f"got {self.wavelength:g}")
        if abs(self.phase_deg) > 360.0:
            raise RoadError(f"sine road: PHASE_DEG must be within +-360 deg, got {self.phase_deg:g}")
        if self.kind == "bump" and not MIN_SIGMA_M <= self.sigma <= MAX_LENGTH_M:
            raise RoadError(f"bump road: width SIGMA must be in [{MIN_SIGMA_M:g}, {MAX_LENGTH_M:g}] m, "
                            f"got {self.sigma:g}")
        if self.kind == "profile":
            _check_profile(self.xs, self.ys)

    @property
    def code(self) -> int:
        """Integer kind code for the compiled model."""
        return _KIND_CODES[self.kind]

    @property
    def spec(self) -> str:
        """Canonical spec string (parses back to an equal road, profiles excepted)."""
        if self.kind == "flat":
            return "flat"
        if self.kind == "sine":
            phase = f":{self.phase_deg:g}" if self.phase_deg else ""
            return f"sine:{self.height:g}:{self.wavelength:g}{phase}"
        if self.kind == "bump":
            return f"bump:{self.height:g}:{self.sigma:g}:{self.mu:g}"
        return f"profile:{self.name or 'user'}"

    def packed(self) -> tuple[int, np.ndarray]:
        """(kind code, parameters) for the compiled road functions.

        flat: []; sine: [H, lambda, phi [rad]]; bump: [H, sigma, mu]; profile: [n, x..., y...].
        """
        if self.kind == "flat":
            return FLAT, np.zeros(1)
        if self.kind == "sine":
            return SINE, np.array([self.height, self.wavelength, math.radians(self.phase_deg)])
        if self.kind == "bump":
            return BUMP, np.array([self.height, self.sigma, self.mu])
        n = len(self.xs)
        return PROFILE, np.concatenate(([float(n)], self.xs, self.ys))

    def height_at(self, x: np.ndarray | float) -> np.ndarray:
        """Road height y(x) (vectorised, for plots and reports)."""
        x = np.asarray(x, dtype=float)
        if self.kind == "flat":
            return np.zeros_like(x)
        if self.kind == "sine":
            return self.height * np.sin(2.0 * np.pi * x / self.wavelength + math.radians(self.phase_deg))
        if self.kind == "bump":
            return self.height * np.exp(-((x - self.mu) ** 2) / (2.0 * self.sigma**2))
        return np.asarray(np.interp(x, self.xs, self.ys), dtype=float)

    def uncovered(self, start_m: float, end_m: float) -> str:
        """Why a run whose rear tyre starts at ``start_m`` and whose front tyre ends at ``end_m`` is not
        all on this road ("" if it is): beyond a profile's ends the model holds its end heights
        (engine.model.road_height), a flat road nobody measured."""
        if self.kind != "profile":
            return ""
        name = self.name or "user"
        if start_m < self.xs[0]:
            return (f"road profile {name!r} starts at x = {self.xs[0]:g} m, ahead of the rear tyre's contact point "
                    f"at x = {start_m:.3f} m: a profile must cover the whole run")
        if end_m > self.xs[-1]:
            return (f"the front tyre reached x = {end_m:.3f} m, past the end of road profile {name!r} at "
                    f"x = {self.xs[-1]:g} m: a profile must cover the whole run")
        return ""

    @classmethod
    def parse(cls, spec: str) -> Road:
        """Parse ``flat``, ``sine:H:LAMBDA[:PHASE_DEG]`` or ``bump:H:SIGMA[:MU]`` (SI units, the phase in degrees).

        User profiles are built with :meth:`from_points` (the engine does no file I/O).
        """
        if not isinstance(spec, str) or not spec.strip():
            raise RoadError("road spec must be a non-empty string")
        parts = spec.strip().split(":")
        kind = parts[0].lower()
        try:
            nums = [float(p) for p in parts[1:]]
        except ValueError:
            raise RoadError(f"road {spec!r}: parameters must be numbers") from None
        if kind == "flat" and not nums:
            return cls("flat")
        if kind == "sine" and len(nums) in (2, 3):
            return cls("sine", height=nums[0], wavelength=nums[1], phase_deg=nums[2] if len(nums) == 3 else 0.0)
        if kind == "bump" and len(nums) in (2, 3):
            mu = nums[2] if len(nums) == 3 else DEFAULT_BUMP_CENTRE_M
            return cls("bump", height=nums[0], sigma=nums[1], mu=mu)
        raise RoadError(
            f"unknown road {spec!r}: expected flat, sine:H:LAMBDA[:PHASE_DEG] or bump:H:SIGMA[:MU]"
        )

    @classmethod
    def from_points(cls, xs: np.typing.ArrayLike, ys: np.typing.ArrayLike, name: str = "user") -> Road:
        """A piecewise-linear road through (x, y) points, x strictly increasing (RoadError names the row)."""
        return cls(
            "profile",
            xs=tuple(float(v) for v in np.asarray(xs, dtype=float).ravel()),
            ys=tuple(float(v) for v in np.asarray(ys, dtype=float).ravel()),
            name=name,
        )


def _check_profile(xs: tuple[float, ...], ys: tuple[float, ...]) -> None:
    """Refuse a profile that is not a road, naming the first row at fault."""
    if len(xs) != len(ys):
        raise RoadError(f"profile road: {len(xs)} x values but {len(ys)} y values")
    if not PROFILE_MIN_POINTS <= len(xs) <= PROFILE_MAX_POINTS:
        raise RoadError(f"profile road needs {PROFILE_MIN_POINTS} to {PROFILE_MAX_POINTS} points, got {len(xs)}")
    x = np.asarray(xs, dtype=float)
    y = np.asarray(ys, dtype=float)
    for values, name, limit in ((x, "x", MAX_LENGTH_M), (y, "y", PROFILE_MAX_Y_M)):
        bad = np.flatnonzero(~(np.abs(values) <= limit))  # NaN too
        if bad.size:
            i = int(bad[0])
            raise RoadError(f"{name} must be a finite number within +-{limit:g} m, got {float(values[i])!r}", i)
    back = np.flatnonzero(np.diff(x) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise RoadError(f"x must be strictly increasing, got {x[i]:g} m after {x[i - 1]:g} m", i)
