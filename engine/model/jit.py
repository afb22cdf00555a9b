"""The one place that configures numba for the engine (on-disk cache, no Python fallback)."""

from __future__ import annotations

from numba import njit

#: Decorator for compiled model and solver functions: cached on disk, fast math off so the
#: results are bit-reproducible across runs on one machine.
jit = njit(cache=True, nogil=True)
