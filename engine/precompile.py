"""The engine's compiled code, built once per machine before any worker starts.

numba compiles a kernel at its first call and caches it on disk (engine.model.jit). Left to the
workers, every worker of a fresh machine would compile the same code at once, each for 15-40 s.
:func:`compile_engine` instead compiles everything once, in a child process (the caller never
imports numba), and leaves a marker in the cache directory; later processes only load the cache.

    python -m finaldrive.engine.precompile      # what compile_engine runs when the marker is missing
"""

from __future__ import annotations

import subprocess
import sys
import time

from finaldrive.engine.model.jit import cache_dir

#: File in the cache directory that says every kernel is compiled there.
MARKER = "compiled"
#: Simulated time of the runs that compile the kernels (both methods, with series) [s].
_SIMULATED_S = 0.02


def is_compiled() -> bool:
    """Whether this machine's cache holds the engine's compiled code (for the current sources)."""
    return (cache_dir() / MARKER).exists()


def compile_engine() -> float:
    """Compile the engine's kernels into the on-disk cache unless already there; the seconds spent.

    Runs ``python -m finaldrive.engine.precompile`` and waits for it; raises
    subprocess.CalledProcessError with its output if it fails."""
    if is_compiled():
        return 0.0
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "finaldrive.engine.precompile"], check=True, capture_output=True)
    return time.perf_counter() - start


def _compile_here() -> None:
    """Simulate briefly with each method (every kernel a run calls gets compiled and cached), then
    write the marker."""
    from finaldrive.engine.api import Design, SimSettings
    from finaldrive.engine.model.road import Road
    from finaldrive.engine.simulation import simulate

    design = Design.from_deg(195.3, 0.037, 0.088)
    road = Road.parse("sine:0.04:3")
    for settings in (SimSettings(method="fast", duration=_SIMULATED_S, series=True),
                     SimSettings(method="reference", duration=_SIMULATED_S, series=True)):
        result = simulate(design, road, settings)
        if not result.ok:
            raise RuntimeError(f"the {settings.method} method failed while compiling: {result.reason}")
    cache_dir().mkdir(parents=True, exist_ok=True)
    (cache_dir() / MARKER).touch()


if __name__ == "__main__":
    _compile_here()
