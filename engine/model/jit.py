"""The one place that configures numba for the engine (on-disk cache, no Python fallback).

numba's on-disk cache checks only the timestamp of the file that defines a compiled function,
yet a compiled function carries copies of every compiled function it calls, from any module (and
the integrator steps built by engine.solver.integrators.make_steppers carry the right-hand side
they close over). Editing engine/model/tyre.py alone would leave the cached right-hand sides of
both solvers running the old tyre. So the cache lives in a directory named after a hash of the
engine's source files: any change to any of them compiles everything afresh. A NUMBA_CACHE_DIR
set by the user is respected as it is.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

from numba import config, njit

_ENGINE = Path(__file__).resolve().parents[1]


def _source_fingerprint() -> str:
    """sha256 (16 hex digits) of the engine's Python sources, path and content."""
    digest = hashlib.sha256()
    for path in sorted(_ENGINE.rglob("*.py")):
        digest.update(path.relative_to(_ENGINE).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


if not os.environ.get("NUMBA_CACHE_DIR"):
    _base = _ENGINE / "__pycache__" if os.access(_ENGINE, os.W_OK) else Path(tempfile.gettempdir()) / "finaldrive"
    config.CACHE_DIR = str(_base / f"numba-{_source_fingerprint()}")  # type: ignore[attr-defined]

#: Decorator for compiled model and solver functions: cached on disk, fast math off so the
#: results are bit-reproducible across runs on one machine; numpy's error model (a division by
#: zero gives inf or nan, which the loops report as NONFINITE) spares a zero test per division.
jit = njit(cache=True, nogil=True, error_model="numpy")
