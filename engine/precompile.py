"""The engine's compiled code, built once per machine before any worker starts.

numba compiles a kernel at its first call and caches it on disk (engine.model.jit). Left to the
workers, every worker of a fresh machine would compile the same code at once, each for 30-50 s a
method. :func:`compile_engine` instead compiles each method once, in child processes (the caller
never imports numba), and leaves a marker per method in the cache directory; later processes
only load the cache.

    python -m finaldrive.engine.precompile fast [reference] [--nice]    # what compile_engine runs
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from finaldrive.engine.model.jit import cache_dir

#: Simulated time of the runs that compile a method's kernels (with series) [s].
_SIMULATED_S = 0.02
#: A compilation whose lock is older than this [s] is taken as dead.
_LOCK_S = 600.0
#: How often a process waiting for another's compilation looks at the cache [s].
_POLL_S = 0.1
#: The niceness of a method compiled in the background: the lowest priority, below Ray's workers
#: (15), so it takes only idle time.
_BACKGROUND_NICENESS = 19
#: Linux's autogroup of the calling process's session (sched(7)). With autogroups on (most desktop
#: and many server kernels), CPU time is shared fairly between sessions first and by niceness only
#: within one: a compilation in a session of its own at niceness 19 took half a core from the
#: first job's compilation (the fast method's 22 s of CPU in 34 s of wall time, against 22.6 s
#: in the starting session). So the background compilation lowers its session's share as well.
_AUTOGROUP = Path("/proc/self/autogroup")


def is_compiled(method: str) -> bool:
    """Whether this machine's cache holds the method's compiled code (for the current sources)."""
    return (cache_dir() / f"compiled-{method}").exists()


def _lock(method: str) -> Path:
    return cache_dir() / f"compiling-{method}"


def _compiling_elsewhere(method: str) -> bool:
    """Whether a process (this one's or another's) is compiling the method now: its lock is fresh."""
    with contextlib.suppress(FileNotFoundError):
        return time.time() - _lock(method).stat().st_mtime < _LOCK_S
    return False


def _start(method: str, nice: bool = False) -> subprocess.Popen[bytes]:
    """Lock the method and compile it in a child process (which removes the lock when it ends);
    ``nice``: in the background, in a session of its own (it outlives its caller)."""
    cache_dir().mkdir(parents=True, exist_ok=True)
    _lock(method).touch()
    command = [sys.executable, "-m", "finaldrive.engine.precompile", method, *(["--nice"] if nice else [])]
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL if nice else subprocess.PIPE,
                            start_new_session=nice)


def _wait_for(method: str, child: subprocess.Popen[bytes] | None) -> None:
    """Wait until the method is compiled: by ``child``, else by another process (if that one ends
    without the method compiled, compile it here)."""
    while child is None:
        if is_compiled(method):
            return
        if not _compiling_elsewhere(method):
            child = _start(method)
        else:
            time.sleep(_POLL_S)
    _, err = child.communicate()
    if child.returncode != 0:
        raise RuntimeError(f"compiling the engine failed: {err.decode(errors='replace')[-2000:]}")


def compile_engine(now: tuple[str, ...] = ("fast",),
                   later: tuple[str, ...] = ("reference",)) -> Callable[[], float]:
    """Start compiling the kernels of the methods ``now`` into the on-disk cache, unless already
    there or being compiled by another process, and those of ``later`` in a background process at
    the lowest priority; return ``wait``, which waits for ``now`` (the seconds since the start) and
    raises RuntimeError if a compilation failed.

    Callers may call it as early as they like (``finaldrive demo`` and ``serve`` do, at their
    start, so the compilation overlaps their imports and Ray's start); ``make_executor`` waits
    for it. A reference run that starts before its background compilation has finished compiles
    for itself."""
    start = time.perf_counter()
    children = {m: None if _compiling_elsewhere(m) else _start(m) for m in now if not is_compiled(m)}
    for method in later:
        if not is_compiled(method) and not _compiling_elsewhere(method):
            _start(method, nice=True)

    def wait() -> float:
        for method, child in children.items():
            _wait_for(method, child)
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


def _lower_priority() -> None:
    """Run at the lowest priority, this process and its session's autogroup (where there is one)."""
    os.nice(_BACKGROUND_NICENESS)
    with contextlib.suppress(OSError):
        _AUTOGROUP.write_text(str(_BACKGROUND_NICENESS))


if __name__ == "__main__":
    if "--nice" in sys.argv:
        _lower_priority()
    for name in sys.argv[1:]:
        if name != "--nice":
            try:
                _compile_here(name)
            finally:
                _lock(name).unlink(missing_ok=True)
