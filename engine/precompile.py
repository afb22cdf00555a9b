"""The engine's compiled code, built once per machine before any worker starts.

numba compiles a kernel at its first call and caches it on disk (engine.model.jit). Left to the
workers, every worker of a fresh machine would compile the same code at once, each for 30-50 s a
method. :func:`compile_engine` instead compiles each method once, in child processes (the caller
never imports numba), and leaves a marker per method in the cache directory; later processes
only load the cache.

With more than one CPU the fast method is compiled in stages, the second in two processes at once:
first what a run's setup and its integration both call, the right-hand side (through the end
state's kinetic energy, which calls it) and the pose (``assemble``); then, from the cache, a run's
setup (``prepare``: the static equilibrium) here and the integration in a child, whose own setup
is computed as plain Python (``interpreted``); then one whole run here, which loads the child's
kernels (and compiles anything missing) before the marker is written. The kernels both halves
call are in the cache before either starts, so the two do not write one kernel's cache index at
once (the reference method's background compilation may, as before: numba writes each index and
data file whole, by rename).

    python -m finaldrive.engine.precompile fast [reference] [--nice]    # what compile_engine runs
    python -m finaldrive.engine.precompile --part rhs|setup|run fast    # one stage (for the above)
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
#: Linux takes one unprivileged autogroup change per 0.1 s, machine-wide (EAGAIN otherwise): tries, pause [s].
_AUTOGROUP_TRIES = (5, 0.1)
#: This module run as a program (its stages and methods are arguments).
_PROGRAM = (sys.executable, "-m", "finaldrive.engine.precompile")
#: The stages of the fast method's compilation (module docstring); "whole" compiles all at once.
_PARTS = ("rhs", "setup", "run", "whole")


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
    command = [*_PROGRAM, method, *(["--nice"] if nice else [])]
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


def _compile_here(method: str, part: str = "whole") -> None:
    """Compile and cache every kernel the method's runs call, by a brief run; ``part``: only the
    fast method's right-hand side and pose ("rhs", no run), a run's setup ("setup", no run), or the
    run from a setup computed as plain Python ("run")."""
    if part not in _PARTS:
        raise ValueError(f"unknown part {part!r}: expected one of {', '.join(_PARTS)}")
    import numpy as np

    from finaldrive.engine.api import Design, SimSettings
    from finaldrive.engine.fast.bodies import N_DOF
    from finaldrive.engine.fast.minimal import N_STATE, UPPER, kinetic_energy
    from finaldrive.engine.model.jit import interpreted, load_registries
    from finaldrive.engine.model.kinematics import assemble
    from finaldrive.engine.model.road import Road
    from finaldrive.engine.setup import MINIMAL_COORDS
    from finaldrive.engine.simulation import prepare, simulate, simulate_prepared
    from finaldrive.engine.vehicle import default_vehicle

    settings = SimSettings(method="reference" if method == "reference" else "fast", duration=_SIMULATED_S,
                           series=True)
    design, road, vehicle = Design.from_deg(195.3, 0.037, 0.088), Road.parse("sine:0.04:3"), default_vehicle()
    load_registries()
    if part == "setup":
        prepare(design, road, settings, vehicle)
        return
    if part in ("rhs", "run"):
        with interpreted():
            setup = prepare(design, road, settings, vehicle)
        if part == "rhs":
            z = setup.q0[list(MINIMAL_COORDS)]
            y = np.zeros(N_STATE)
            y[:N_DOF] = z
            kinetic_energy(y, setup.p, *road.packed(), UPPER)
            x1, y1, theta, phi, fs = (float(v) for v in z[:N_DOF - 1])
            assemble(setup.p, road, x1, y1, theta, phi, fs, 0.0, 0.0)   # as simulate_prepared, for the end pose
            return
        result = simulate_prepared(setup, road, settings)
    else:
        result = simulate(design, road, settings, vehicle)
    if not result.ok:
        raise RuntimeError(f"the {method} method failed while compiling: {result.reason}")


def _cpus() -> int:
    """CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _compile(method: str) -> None:
    """Compile the method (the fast one in stages with more than one CPU: the module's docstring),
    then write its marker."""
    if method == "fast" and _cpus() > 1:
        _compile_here(method, "rhs")
        run = subprocess.Popen([*_PROGRAM, "--part", "run", method], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
        try:
            _compile_here(method, "setup")
        except BaseException:
            run.kill()
            raise
        finally:
            _, err = run.communicate()
        if run.returncode != 0:
            raise RuntimeError(f"compiling the {method} method's integration failed: "
                               f"{err.decode(errors='replace')[-2000:]}")
    _compile_here(method)
    cache_dir().mkdir(parents=True, exist_ok=True)
    (cache_dir() / f"compiled-{method}").touch()


def _lower_priority() -> None:
    """Run at the lowest priority: this process, and its session's autogroup if it leads the session
    (a background compilation does; a shell's session is left alone)."""
    os.nice(_BACKGROUND_NICENESS)
    if os.getsid(0) != os.getpid():
        return
    tries, pause = _AUTOGROUP_TRIES
    for _ in range(tries):
        try:
            _AUTOGROUP.write_text(str(_BACKGROUND_NICENESS))
            return
        except BlockingIOError:   # another autogroup changed within the last 0.1 s
            time.sleep(pause)
        except OSError:           # no autogroups here
            return


def main(argv: list[str]) -> None:
    """``[--nice] method...``: compile the methods (each unlocked when done); ``--part part method``:
    one stage of one method's compilation (for :func:`_compile`)."""
    if "--nice" in argv:
        _lower_priority()
    if "--part" in argv:
        at = argv.index("--part")
        if len(argv) < at + 3:
            raise SystemExit("usage: --part rhs|setup|run METHOD")
        _compile_here(argv[at + 2], argv[at + 1])
        return
    for name in argv:
        if name != "--nice":
            try:
                _compile(name)
            finally:
                _lock(name).unlink(missing_ok=True)


if __name__ == "__main__":
    main(sys.argv[1:])
