"""The engine's compiled code, built once per machine before any worker starts.

numba compiles a kernel at its first call and caches it on disk (engine.jit.kernel). Left to the
workers, every worker of a fresh machine would compile the same code at once, each for 30-50 s a
method. :func:`compile_engine` instead compiles each method once, in child processes (the caller
never imports numba), and leaves a marker per method in the cache directory; later processes
only load the cache.

With more than one CPU the fast method is built by several processes at once (up to
``_MAX_BUILDERS``): each runs the method briefly as plain Python, recording which kernel calls
which with what types (engine.jit.kernel.traced), then all compile those kernels between them, each
traced kernel once, callees first (engine.jit.parallel). A last brief compiled run, here,
loads them all (and compiles what no trace saw) before the marker is written. The reference method,
whose plain-Python run takes half a minute, is compiled by one run in one process (the kernels it
shares with the fast method's build may be written by both at once: numba writes each index and
data file whole, by rename).

    python -m finaldrive.engine.precompile fast [reference] [--nice] [--parent PID]  # compile_engine's
    python -m finaldrive.engine.precompile --builder DIR fast           # one more builder (for the above)
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from finaldrive.engine.jit.cache import cache_dir, plain

if TYPE_CHECKING:
    from finaldrive.engine.api import Design, SimSettings
    from finaldrive.engine.model.road import Road
    from finaldrive.engine.vehicle import Vehicle

#: Simulated time of the runs that compile a method's kernels (with series) [s].
_SIMULATED_S = 0.02
#: Simulated time of the fast method's plain-Python run with the two-run chain (the build's trace;
#: the paper's single run is traced for _SIMULATED_S) [s].
_TWO_RUN_TRACE_S = 0.005
#: A compilation whose lock is older than this [s] is taken as dead.
_LOCK_S = 600.0
#: How often a process waiting for another's compilation looks at the cache [s].
_POLL_S = 0.1
#: Most processes building the fast method at once: each pays its own start (~1.3 s: imports,
#: numba's registries, the trace), and the kernels' call graph narrows to one chain (the right-hand
#: side, a step, the integration: ~6 s here) at its end. A choice, measured with two only.
_MAX_BUILDERS = 4
#: How long a helper builder may take to exit once every kernel is built [s].
_HELPER_EXIT_S = 30.0
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
#: This module run as a program (its builders and methods are arguments).
_PROGRAM = (sys.executable, "-m", "finaldrive.engine.precompile")


def is_compiled(method: str) -> bool:
    """Whether this machine's cache holds the method's compiled code (for the current sources)."""
    return (cache_dir() / f"compiled-{method}").exists()


def _lock(method: str) -> Path:
    return cache_dir() / f"compiling-{method}"


def compile_progress(method: str) -> tuple[int, int] | None:
    """How far a compilation of the method under way on this machine is: (kernels compiled, kernels
    to compile) once its build has traced them, (0, 0) before; None when none is under way."""
    if not _compiling_elsewhere(method):
        return None
    with contextlib.suppress(OSError, ValueError):
        done, total = _lock(method).read_text().split()
        return int(done), int(total)
    return 0, 0


def _tell_progress(method: str, done: int, total: int) -> None:
    """Write the build's progress into the method's lock (refreshing it: the compilation is alive)."""
    with contextlib.suppress(OSError):
        _lock(method).write_text(f"{done} {total}")


def _compiling_elsewhere(method: str) -> bool:
    """Whether a process (this one's or another's) is compiling the method now: its lock is fresh."""
    with contextlib.suppress(FileNotFoundError):
        return time.time() - _lock(method).stat().st_mtime < _LOCK_S
    return False


@contextlib.contextmanager
def _deciding() -> Iterator[None]:
    """The machine's lock on deciding who compiles (an exclusive ``flock`` on ``<cache>/compile.lock``,
    held while a process looks for a compilation under way and, if none is, starts one): of the
    workers of a fresh Ray node, which all call :func:`compile_engine` at once (workers/evaluate.py),
    one compiles and the others wait for it, rather than each compiling for itself."""
    cache_dir().mkdir(parents=True, exist_ok=True)
    fd = os.open(cache_dir() / "compile.lock", os.O_CREAT | os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)   # releases the lock


def _start(method: str, nice: bool = False) -> subprocess.Popen[bytes]:
    """Lock the method and compile it in a child process (which removes the lock when it ends);
    ``nice``: in the background, in a session of its own (a terminal's Ctrl-C is not its), ended
    with its caller (:func:`_end_with`): a scheduler or a command leaves no compilation behind."""
    cache_dir().mkdir(parents=True, exist_ok=True)
    _lock(method).touch()
    command = [*_PROGRAM, method, *(["--nice", "--parent", str(os.getpid())] if nice else [])]
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
    with _deciding():
        children = {m: None if _compiling_elsewhere(m) else _start(m) for m in now if not is_compiled(m)}
        for method in later:
            if not is_compiled(method) and not _compiling_elsewhere(method):
                _start(method, nice=True)

    def wait() -> float:
        for method, child in children.items():
            _wait_for(method, child)
        return time.perf_counter() - start

    return wait


def _brief_run(method: str) -> tuple[Design, Road, SimSettings, Vehicle]:
    """The brief run (design, road, settings, vehicle) that calls every kernel of the method."""
    from finaldrive.engine.api import Design, SimSettings
    from finaldrive.engine.model.road import Road
    from finaldrive.engine.vehicle import default_vehicle

    settings = SimSettings(method="reference" if method == "reference" else "fast", duration=_SIMULATED_S,
                           series=True)
    return Design.from_deg(195.3, 0.037, 0.088), Road.parse("sine:0.04:3"), settings, default_vehicle()


def _compile_here(method: str) -> None:
    """Compile and cache (or load) every kernel of the method, by a brief run."""
    from finaldrive.engine.jit.kernel import load_registries
    from finaldrive.engine.simulation import simulate

    load_registries()
    result = simulate(*_brief_run(method))
    if not result.ok:
        raise RuntimeError(f"the {method} method failed while compiling: {result.reason}")


def _build_here(method: str, directory: Path, waiting: Callable[[], None],
                progress: Callable[[int, int], None] | None = None) -> None:
    """Trace the method's brief run as plain Python (and, briefer, with the two-run chain), then
    compile the kernels they called with the other builders sharing ``directory``
    (engine.jit.parallel; ``waiting`` and ``progress`` as there)."""
    from finaldrive.engine.jit.kernel import load_registries, traced
    from finaldrive.engine.jit.parallel import build, plan
    from finaldrive.engine.simulation import simulate

    load_registries()
    design, road, settings, vehicle = _brief_run(method)
    with traced() as trace:
        for run_settings, run_vehicle in ((settings, vehicle), (settings.with_(duration=_TWO_RUN_TRACE_S),
                                                               vehicle.replace(chain_runs=2.0))):
            # the trace only speeds the build up: plain Python raises where compiled code would go on
            # with an inf or a nan, and what the trace then misses is compiled by the run after the build
            with contextlib.suppress(ArithmeticError, ValueError):
                simulate(design, road, run_settings, run_vehicle)
    build(plan(trace), directory, waiting, progress)


def _cpus() -> int:
    """CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _give_up_after(seconds: float) -> Callable[[], None]:
    """A builder's ``waiting``: raise TimeoutError once ``seconds`` have passed."""
    deadline = time.monotonic() + seconds

    def waiting() -> None:
        if time.monotonic() > deadline:
            raise TimeoutError(f"the engine's build waited more than {seconds:g} s for another builder")
    return waiting


def _build(method: str, builders: int) -> None:
    """Build the method's kernels here and in ``builders - 1`` helper processes (the module's docstring).
    A helper that fails leaves its kernels to the others (the failure written to stderr); if this
    builder fails, the helpers are killed at once."""
    with tempfile.TemporaryDirectory(prefix="finaldrive-build-") as name:
        directory = Path(name)
        logs = [directory / f"builder-{i}.log" for i in range(1, builders)]
        helpers: list[subprocess.Popen[bytes]] = []
        try:
            for log in logs:
                with log.open("wb") as err:
                    helpers.append(subprocess.Popen([*_PROGRAM, "--builder", name, method],
                                                    stdout=subprocess.DEVNULL, stderr=err))
            _build_here(method, directory, _give_up_after(_LOCK_S),
                        lambda done, total: _tell_progress(method, done, total))
        except BaseException:
            for helper in helpers:
                helper.kill()
            raise
        finally:
            for helper in helpers:   # each is done once every kernel is: it exits within a poll
                with contextlib.suppress(subprocess.TimeoutExpired):
                    helper.wait(_HELPER_EXIT_S)
                helper.kill()
                helper.wait()
        for helper, log in zip(helpers, logs, strict=True):
            if helper.returncode != 0:
                print(f"a builder of the {method} method ended with code {helper.returncode} (the others built "
                      f"its kernels): {log.read_text(errors='replace')[-2000:]}", file=sys.stderr)


def _compile(method: str) -> None:
    """Compile the method (the fast one by several builders with more than one CPU: the module's
    docstring), then write its marker."""
    several = method == "fast" and sys.platform != "win32" and not plain()  # fcntl locks; traced kernels
    builders = min(_cpus(), _MAX_BUILDERS) if several else 1
    if builders > 1:
        _build(method, builders)
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


#: prctl(2)'s option that signals a process when the thread that started it ends (Linux)
_PR_SET_PDEATHSIG = 1


def _end_with(parent: int, methods: list[str]) -> None:
    """End this process at once, the locks of ``methods`` removed, when ``parent``, its caller, ends
    (SIGTERM: Linux's parent-death signal; where there is none, it ends once its compilation is done).

    The handler ends the process with ``os._exit``, not by raising SystemExit: raised where numba's
    compiler is called back from LLVM (a ctypes callback), the exception was printed and dropped,
    and the compilation went on for its remaining 10-40 s with no caller."""
    def end(*_: object) -> None:
        for method in methods:
            _lock(method).unlink(missing_ok=True)
        os._exit(1)

    signal.signal(signal.SIGTERM, end)
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent:   # the caller ended before the signal was armed
        end()


def main(argv: list[str]) -> None:
    """``[--nice] [--parent PID] method...``: compile the methods (each unlocked when done), ending
    with process PID if given; ``--builder DIR method``: one more builder of the method (for
    :func:`_compile`)."""
    if "--parent" in argv:
        at = argv.index("--parent")
        parent, argv = int(argv[at + 1]), argv[:at] + argv[at + 2:]
        _end_with(parent, [name for name in argv if name != "--nice"])
    if "--nice" in argv:
        _lower_priority()
    if "--builder" in argv:
        at = argv.index("--builder")
        if len(argv) < at + 3:
            raise SystemExit("usage: --builder DIR METHOD")
        parent = os.getppid()

        def waiting() -> None:   # a builder outlives no parent
            if os.getppid() != parent:
                raise SystemExit("the build's first process has ended")
        _build_here(argv[at + 2], Path(argv[at + 1]), waiting)
        return
    for name in argv:
        if name != "--nice":
            try:
                _compile(name)
            finally:
                _lock(name).unlink(missing_ok=True)


if __name__ == "__main__":
    main(sys.argv[1:])
