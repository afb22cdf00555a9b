"""How well the numerics decide a result: a design's numerical band, and ties between designs.

The band of a design on a road is how far its fitness (eq. 67) and distance move when the same
run is integrated otherwise: with the production method's error control :data:`TIGHT_FACTOR` times
tighter, and with the reference method (the paper's augmented Lagrangian with the ABM
predictor-corrector, eqs. 57-66, at its own step; not for a vehicle only the fast method models, the two-run
or the elastic chain: :func:`reference_refusal`). It is the largest difference from the
production value; a band above :data:`BAND_LIMIT_M` is flagged. Two designs whose fitness differs
by less than the sum of their bands are a tie: the numerics do not say which is better.
See docs/optimisation.md#numerical-bands-and-ties.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from finaldrive.engine.api import STATUS_OK, SimSettings
from finaldrive.engine.simulation import evaluate

if TYPE_CHECKING:
    from finaldrive.engine.model.road import Road
    from finaldrive.engine.vehicle import Vehicle

#: The tight re-run's local error tolerance is the production one divided by this.
TIGHT_FACTOR = 100.0
#: A band wider than this [m] is flagged (``exceeds_limit``): a difference of 1 mm between two
#: designs is then not decided by the numerics.
BAND_LIMIT_M = 1.0e-3
#: Designs given a band to look for ties with the best (the best included; :func:`best_distinct`).
TIE_CANDIDATES = 5


def reference_refusal(vehicle: Vehicle | None) -> str | None:
    """Why a band cannot have its reference re-run for ``vehicle`` (a model the fast method alone
    simulates), or None."""
    if vehicle is None:
        return None
    try:
        vehicle.check_method("reference")
    except ValueError as exc:
        return f"not run: {exc}"
    return None


def band_settings(settings: SimSettings, vehicle: Vehicle | None = None) -> dict[str, SimSettings]:
    """The re-runs of a band: label -> settings (the production ones' duration, drive and limits); the
    reference re-run only where ``vehicle`` allows it (:func:`reference_refusal`)."""
    out = {"tight": settings.with_(method="fast", fast_tolerance=settings.fast_tolerance / TIGHT_FACTOR)}
    if reference_refusal(vehicle) is None:
        out["reference"] = settings.with_(method="reference")
    return out


def numerical_bands(designs: np.ndarray, road: Road, settings: SimSettings,
                    vehicle: Vehicle | None = None) -> list[dict[str, Any]]:
    """Each design row's (a2 [rad], L2 [m], R_WS [m]) fitness and distance at ``settings`` and its
    band: ``band_m`` (fitness) and ``distance_band_m``, the largest difference to a re-run of
    :func:`band_settings`, ``exceeds_limit`` when ``band_m`` > :data:`BAND_LIMIT_M`, and each re-run's
    values. A re-run that fails, or that the vehicle does not allow (:func:`reference_refusal`), is left
    out of the band and named in ``failed`` with its reason (the band is then of the re-runs that
    finished); a design whose production run fails, or whose every re-run fails, has no band (None)."""
    rows = np.asarray(designs, dtype=float).reshape(-1, 3)
    runs = {"production": evaluate(rows, road, settings, vehicle),
            **{label: evaluate(rows, road, s, vehicle) for label, s in band_settings(settings, vehicle).items()}}
    refusal = reference_refusal(vehicle)
    out = []
    for i in range(len(rows)):
        failed = {label: batch.reason[i] for label, batch in runs.items() if batch.status[i] != STATUS_OK}
        if refusal is not None:
            failed["reference"] = refusal
        out.append(band_of(
            {label: (batch.fitness_m[i], batch.distance_m[i]) for label, batch in runs.items()
             if batch.status[i] == STATUS_OK}, failed))
    return out


def band_of(values: dict[str, tuple[float, float]], failed: dict[str, str]) -> dict[str, Any]:
    """A design's band from its runs: ``values`` label -> (fitness [m], distance [m]) of the runs that
    finished ("production" and the re-runs of :func:`band_settings`), ``failed`` label -> reason of
    the others (:func:`numerical_bands`' record)."""
    fitness, distance = values.get("production", (math.nan, math.nan))
    whole = "production" in values and len(values) > 1
    band = max(abs(f - fitness) for f, _ in values.values()) if whole else math.nan
    distance_band = max(abs(d - distance) for _, d in values.values()) if whole else math.nan
    return {
        "fitness_m": _plain(fitness), "distance_m": _plain(distance), "band_m": _plain(band),
        "distance_band_m": _plain(distance_band), "exceeds_limit": None if not whole else bool(band > BAND_LIMIT_M),
        "runs": {label: {"fitness_m": _plain(f), "distance_m": _plain(d)} for label, (f, d) in values.items()},
        "failed": failed,
    }


def tie_flags(bands: list[dict[str, Any]]) -> list[bool]:
    """Which designs tie with the first (the best): fitness closer to it than the two bands together.
    The first ties with itself; a design without a band (a failed re-run) ties with none."""
    if not bands or bands[0]["band_m"] is None:
        return [False] * len(bands)
    best = bands[0]
    return [b["band_m"] is not None and abs(best["fitness_m"] - b["fitness_m"]) <= best["band_m"] + b["band_m"]
            for b in bands]


#: Two designs are distinct when apart by at least this much in one variable: a2 [rad], L2 [m], R_WS [m]
#: (1 deg, 1 mm, 1 mm: the sensitivities' steps, engine.study.sharpness), so the ties compare other
#: designs, not a converged DE's copies of the best a micrometre apart.
DISTINCT = (math.radians(1.0), 1.0e-3, 1.0e-3)


def best_distinct(designs: np.ndarray, score: np.ndarray, n: int = TIE_CANDIDATES) -> np.ndarray:
    """Indices of the ``n`` best design rows by ``score`` (NaN never), best first, each
    :data:`DISTINCT` from every better one (the first of equals)."""
    order = np.argsort(np.where(np.isfinite(score), -score, np.inf), kind="stable")
    out: list[int] = []
    for i in order:
        if not np.isfinite(score[i]) or len(out) == n:
            break
        if all(_apart(designs[i], designs[kept]) for kept in out):
            out.append(int(i))
    return np.array(out, dtype=int)


def _apart(a: np.ndarray, b: np.ndarray) -> bool:
    turn = abs((a[0] - b[0] + math.pi) % (2.0 * math.pi) - math.pi)   # a2 on the circle
    return bool(turn >= DISTINCT[0] or abs(a[1] - b[1]) >= DISTINCT[1] or abs(a[2] - b[2]) >= DISTINCT[2])


def _plain(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None
