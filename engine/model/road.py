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


class RoadError(ValueError):
    """A road spec that cannot be parsed or is not physical."""


@dataclass(frozen=True)
class Road:
    """One road profile.

    kind: ``flat`` (32c), ``sine`` (32a: H_y sin(2 pi x / lambda)), ``bump``
    (32b: H_y exp(-(x - mu)^2 / (2 sigma^2))) or ``profile`` (piecewise-linear
    through user points, constant beyond the ends).
    """

    kind: str = "flat"
    height: float = 0.0       # H_y [m]
    wavelength: float = 0.0   # lambda [m], sine only
    sigma: float = 0.0        # bump width [m]
    mu: float = DEFAULT_BUMP_CENTRE_M  # bump centre [m]
    xs: tuple[float, ...] = field(default=())  # profile only
    ys: tuple[float, ...] = field(default=())
    name: str = ""            # profile only: a label for the spec string

    def __post_init__(self) -> None:
        if self.kind not in _KIND_CODES:
            raise RoadError(f"unknown road kind {self.kind!r}")
        for key in ("height", "wavelength", "sigma", "mu"):
            if not math.isfinite(getattr(self, key)):
                raise RoadError(f"road {key} must be a finite number")
        if self.kind == "sine" and self.wavelength <= 0:
            raise RoadError("sine road: wavelength LAMBDA must be > 0")
        if self.kind == "bump" and self.sigma <= 0:
            raise RoadError("bump road: width SIGMA must be > 0")
        if self.kind == "profile":
            xs = np.asarray(self.xs, dtype=float)
            ys = np.asarray(self.ys, dtype=float)
            if xs.size < 2 or xs.size != ys.size:
                raise RoadError("profile road needs at least two (x, y) points")
            if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(ys))):
                raise RoadError("profile road points must be finite numbers")
            if np.any(np.diff(xs) <= 0):
                raise RoadError("profile road x values must be strictly increasing")

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
            return f"sine:{self.height:g}:{self.wavelength:g}"
        if self.kind == "bump":
            return f"bump:{self.height:g}:{self.sigma:g}:{self.mu:g}"
        return f"profile:{self.name or 'user'}"

    def packed(self) -> tuple[int, np.ndarray]:
        """(kind code, parameters) for the compiled road functions.

        flat: []; sine: [H, lambda]; bump: [H, sigma, mu]; profile: [n, x..., y...].
        """
        if self.kind == "flat":
            return FLAT, np.zeros(1)
        if self.kind == "sine":
            return SINE, np.array([self.height, self.wavelength])
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
            return self.height * np.sin(2.0 * np.pi * x / self.wavelength)
        if self.kind == "bump":
            return self.height * np.exp(-((x - self.mu) ** 2) / (2.0 * self.sigma**2))
        return np.asarray(np.interp(x, self.xs, self.ys), dtype=float)

    @classmethod
    def parse(cls, spec: str) -> Road:
        """Parse ``flat``, ``sine:H:LAMBDA`` or ``bump:H:SIGMA[:MU]`` (SI units).

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
        if kind == "sine" and len(nums) == 2:
            return cls("sine", height=nums[0], wavelength=nums[1])
        if kind == "bump" and len(nums) in (2, 3):
            mu = nums[2] if len(nums) == 3 else DEFAULT_BUMP_CENTRE_M
            return cls("bump", height=nums[0], sigma=nums[1], mu=mu)
        raise RoadError(
            f"unknown road {spec!r}: expected flat, sine:H:LAMBDA or bump:H:SIGMA[:MU]"
        )

    @classmethod
    def from_points(cls, xs: np.typing.ArrayLike, ys: np.typing.ArrayLike, name: str = "user") -> Road:
        """A piecewise-linear road through (x, y) points, x increasing."""
        return cls(
            "profile",
            xs=tuple(float(v) for v in np.asarray(xs, dtype=float).ravel()),
            ys=tuple(float(v) for v in np.asarray(ys, dtype=float).ravel()),
            name=name,
        )
