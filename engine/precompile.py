"""The engine's compiled code, built once per machine before any worker starts.

numba compiles a kernel at its first call and caches it on disk (engine.model.jit). Left to the
workers, every worker of a fresh machine would compile the same code at once, each for 30-50 s a
method. :func:`compile_engine` instead compiles each method once, in child processes (the caller
never imports numba), and leaves a marker per method in the cache directory; later processes
only load the cache.

    python -m finaldrive.engine.precompile fast [reference] [--nice]    # what compile_engine runs
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable

from finaldrive.engine.model.jit import cache_dir

#: Simulated time of the runs that compile a method's kernels (with series) [s].
_SIMULATED_S = 0.02
#: A background compilation younger than this [s] is taken as still running.
_LOCK_S = 600.0
#: Added to the niceness of a method compiled in the background.
_BACKGROUND_NICENESS = 10


def is_compiled(method: str) -> bool:
    """Whether this machine's cache holds the method's compiled code (for the current sources)."""
    return (cache_dir() / f"compiled-{method}").exists()


def _command(method: str) -> list[str]:
    return [sys.executable, "-m", "finaldrive.engine.precompile", method]


def compile_engine(now: tuple[str, ...] = ("fast",),
                   later: tuple[str, ...] = ("reference",)) -> Callable[[], float]:
    """Start compiling the kernels of the methods ``now`` into the on-disk cache, unless already
    there, and those of ``later`` in a niced background process; return ``wait``, which waits for
    ``now`` (the seconds since the start) and raises RuntimeError if a compilation failed.

    The caller may start its workers' pool meanwhile, as long as no task runs before ``wait()``.
    A reference run that starts before its background compilation has finished compiles for itself."""
    start = time.perf_counter()
    children = [subprocess.Popen(_command(m), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                for m in now if not is_compiled(m)]
    for method in later:
        lock = cache_dir() / f"compiling-{method}"
        if is_compiled(method) or (lock.exists() and time.time() - lock.stat().st_mtime < _LOCK_S):
            continue
        cache_dir().mkdir(parents=True, exist_ok=True)
        lock.touch()
        subprocess.Popen([*_command(method), "--nice"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True)

    def wait() -> float:
        for child in children:
            _, err = child.communicate()
            if child.returncode != 0:
                raise RuntimeError(f"compiling the engine failed: {err.decode(errors='replace')[-2000:]}")
        return time.perf_counter() - start

    return wait


def _compile_here(method: str) -> None:
    """Simulate briefly (every kernel a run of the method calls gets compiled and cached), then
    write the method's marker."""
    from finaldrive.engine.api import Design, SimSettings
    from finaldrive.engine.model.road import Road
    from finaldrive.engine.simulation import simulate

    settings = SimSettings(method="reference" if method == "reference" else "fast", duration=_SIMULATED_S,
                           series=True)
    result = simulate(Design.from_deg(195.3, 0.037, 0.088), Road.parse("sine:0.04:3"), settings)
    if not result.ok:
        raise RuntimeError(f"the {method} method failed while compiling: {result.reason}")
    cache_dir().mkdir(parents=True, exist_ok=True)
    (cache_dir() / f"compiled-{method}").touch()


if __name__ == "__main__":
    if "--nice" in sys.argv:
        os.nice(_BACKGROUND_NICENESS)
    for name in sys.argv[1:]:
        if name != "--nice":
            _compile_here(name)
