"""The compiled-code plumbing: kernels typed with plain argument types, the linear algebra, and
compile_engine's coordination between processes."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from finaldrive.engine import precompile
from finaldrive.engine.jit.kernel import Kernel, interpreted, jit
from finaldrive.engine.model.linalg import cholesky, dot, matmul, matvec, rmatvec, solve


@jit
def _scaled(x, k=1):
    return x * k


@jit
def _caller(x):
    return _scaled(x, 2) + _scaled(x)


def test_kernels_called_from_compiled_code_are_typed_with_plain_types() -> None:
    from numba import types

    assert _caller(1.5) == 4.5
    typed = [list(_scaled.callee.get_call_template(args, {})[2])
             for args in ([types.float64, types.IntegerLiteral(2)], [types.float64])]   # a constant; the default
    assert typed == [[types.float64, types.int64]] * 2


def test_the_cache_directory_is_named_after_the_sources_and_the_toolchain(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Another Python, or numba installed elsewhere or anew, gets a cache (and compile markers) of its own."""
    import importlib.machinery
    import importlib.util

    from finaldrive.engine.jit import cache as jit_module

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    here = jit_module.cache_dir()
    assert here.name.startswith("numba-") and here == jit_module.cache_dir()
    with monkeypatch.context() as m:
        m.setattr(sys, "version", sys.version + " (another build)")
        assert jit_module.cache_dir() != here
    elsewhere = tmp_path / "numba" / "__init__.py"
    elsewhere.parent.mkdir()
    elsewhere.write_text("")
    find_spec = importlib.util.find_spec
    spec = importlib.machinery.ModuleSpec("numba", None, origin=str(elsewhere))
    with monkeypatch.context() as m:
        m.setattr(importlib.util, "find_spec", lambda name, *a: spec if name == "numba" else find_spec(name, *a))
        moved = jit_module.cache_dir()
        assert moved != here
        os.utime(elsewhere, ns=(0, 10**18))  # the same place, installed anew
        assert jit_module.cache_dir() != moved


@jit
def _both_ways(x):
    return 2.0 * x


@jit
def _calls_both_ways(x):
    return _both_ways(x) + 1.0


@jit(one_form=True)
def _one_form(x):
    return x + 1.0


@jit
def _calls_one_form(x):
    return _one_form(x) * 2.0


def test_a_one_form_kernel_serves_python_and_compiled_callers_alike() -> None:
    assert _calls_one_form(1.0) == 4.0 and _one_form(1.0) == 2.0
    assert _one_form.callee is _one_form.dispatcher
    assert not _one_form.dispatcher.targetoptions.get("no_cpython_wrapper")


def test_compiled_code_calls_a_kernels_form_without_pythons_wrapper_cached_apart(tmp_path: Path) -> None:
    """Called from compiled code only, a kernel is compiled without numba's Python wrapper (nor the
    C-callable one: neither is ever used); called from Python too, it is compiled once more with the
    Python wrapper, in cache files of its own, and both forms give the same answers."""
    code = f"""
import sys; sys.path.insert(0, {str(Path(__file__).parent)!r})
from test_compiled import _both_ways, _calls_both_ways
assert _calls_both_ways(1.5) == 4.0
assert _both_ways._dispatcher is None                        # not made: nothing called it from Python
callee = _both_ways.callee
try:
    callee(1.5)                                              # its entry point is null: refused, not a crash
except TypeError:
    pass
else:
    raise AssertionError("the form for compiled callers ran from Python")
assert callee.targetoptions["no_cpython_wrapper"] and callee.targetoptions["no_cfunc_wrapper"]
assert _both_ways(1.5) == 3.0                                # now the form Python calls
assert not _both_ways.dispatcher.targetoptions.get("no_cpython_wrapper")
assert _both_ways.dispatcher.targetoptions["no_cfunc_wrapper"]
forms = (_calls_both_ways.dispatcher, callee, _both_ways.dispatcher)
print([sum(d.stats.cache_misses.values()) for d in forms], [sum(d.stats.cache_hits.values()) for d in forms])
"""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    runs = [subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True).stdout
            for _ in range(2)]
    # compiled by the first process; the second loads the caller (which holds its callee's code) and
    # the form Python calls
    assert runs == ["[1, 1, 1] [0, 0, 0]\n", "[0, 0, 0] [1, 0, 1]\n"]
    indexes = sorted(p.name.split("-")[0] for p in tmp_path.rglob("*test_compiled._both_ways-*.nbi"))
    assert indexes == ["callee", "test_compiled._both_ways"]


@jit
def _fill(x):
    for i in range(x.shape[0]):
        x[i] = i


@jit
def _makes_an_array(n):
    return np.zeros(n)


@jit(allocates=True)
def _marked_as_making_one(n):
    x = np.zeros(n)
    _fill(x)
    return x


def test_kernels_run_without_numbas_runtime_unless_they_make_arrays() -> None:
    from numba.core.errors import NumbaError

    assert _marked_as_making_one(3).tolist() == [0.0, 1.0, 2.0]   # a runtime-less kernel called from one with it
    assert _fill.callee.targetoptions["_nrt"] is False   # the form that ran, called from compiled code
    assert "_nrt" not in _marked_as_making_one.dispatcher.targetoptions
    with pytest.raises(NumbaError):   # refused, loudly, rather than leaking or crashing
        _makes_an_array(3)


def _matrices(rng: np.random.Generator) -> list[np.ndarray]:
    out = []
    for n in (1, 2, 4, 6):
        for _ in range(40):
            out.append(rng.normal(size=(n, n)))
            u, _, vt = np.linalg.svd(rng.normal(size=(n, n)))  # condition numbers up to 1e14
            out.append(u @ np.diag(np.logspace(0, -rng.uniform(6, 14), n)) @ vt)
    return out


def test_solve_is_as_accurate_as_lapack() -> None:
    """Own elimination (the same bits on every CPU): its residual within a small factor of LAPACK's."""
    rng = np.random.default_rng(5)
    for a in _matrices(rng):
        b = rng.normal(size=a.shape[0])
        x = np.empty_like(b)
        solve(a.copy(), b, x)
        lapack = np.linalg.solve(a, b)
        scale = np.abs(a).max() * np.abs(lapack).max() * a.shape[0] * np.finfo(float).eps
        assert np.abs(a @ x - b).max() <= 100 * scale + np.abs(a @ lapack - b).max()
        assert np.allclose(x, lapack, rtol=0, atol=1e3 * np.finfo(float).eps * np.linalg.cond(a) * np.abs(lapack).max())


def test_products_and_cholesky_against_numpy() -> None:
    rng = np.random.default_rng(6)
    J, v, w = rng.normal(size=(5, 7)), rng.normal(size=7), rng.normal(size=5)
    out5, out7, out57 = np.empty(5), np.empty(7), np.empty((5, 5))
    matvec(J, v, out5)
    rmatvec(J, w, out7)
    matmul(J, J.T.copy(), out57)
    assert np.allclose(out5, J @ v, rtol=1e-14) and np.allclose(out7, J.T @ w, rtol=1e-14)
    assert np.allclose(out57, J @ J.T, rtol=1e-14) and dot(v, v) == pytest.approx(v @ v, rel=1e-14)
    A = J.T @ J + np.eye(7)
    L = np.full((7, 7), np.nan)
    cholesky(A, L)
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-12, atol=1e-14)
    with pytest.raises(np.linalg.LinAlgError):
        cholesky(-A, L)


def test_solve_raises_as_np_linalg_solve_does() -> None:
    x = np.empty(2)
    with pytest.raises(np.linalg.LinAlgError):
        solve(np.array([[1.0, 2.0], [2.0, 4.0]]), np.ones(2), x)
    with pytest.raises(np.linalg.LinAlgError):
        solve(np.array([[1.0, np.nan], [0.0, 1.0]]), np.ones(2), x)


#: A fresh process's fast result, then its values (the wall time aside) printed as hex floats.
_FAST_RESULT = ("import sys; from finaldrive.engine import Design, Road, SimSettings, simulate; "
                "r = simulate(Design.from_deg(195.3, 0.037, 0.088), Road.parse('sine:0.04:3'), "
                "SimSettings(duration=0.5)); "
                "assert r.ok, r.reason; ")
_PRINT_RESULT = ("print([v.hex() for k, v in r.summary().items() if isinstance(v, float) and k != 'wall_s']); "
                 "assert len(r.summary()) > 20")


def test_a_fast_result_loads_neither_scipy_linalg_nor_the_reference_solver() -> None:
    """Nor numba's typing and lowering registries (some 100k objects, ~0.4 s), which loading compiled
    code from the cache does not need; what it imports before is frozen (jit.start_runtime)."""
    precompile.compile_engine(later=())()   # a process with the cache filled: it loads, compiles nothing
    registries_only = "numba.np.polynomial.polynomial_core"   # imported by the target's registries alone
    code = _FAST_RESULT + ("heavy = {'scipy.linalg', 'finaldrive.engine.solver.reference', "
                           f"{registries_only!r}}} & set(sys.modules); "
                           "assert not heavy, sorted(heavy); import gc; "
                           "assert gc.get_freeze_count() > len(gc.get_objects()), gc.get_freeze_count()")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_scipy_linalg_imported_after_its_lapack_was_loaded_alone_is_whole() -> None:
    """engine.jit.lapack loads SciPy's LAPACK without scipy.linalg: the same functions (results
    bit-identical to a process that imported scipy.linalg first), and scipy.linalg imported later
    as after a plain import (its LAPACK modules its attributes)."""
    later = ("import scipy.linalg.cython_lapack, scipy.linalg.cython_blas; "
             "assert scipy.linalg.cython_lapack is sys.modules['scipy.linalg.cython_lapack']; "
             "assert scipy.linalg.cython_blas is sys.modules['scipy.linalg.cython_blas']; "
             "assert scipy.linalg.solve([[2.0]], [1.0]).tolist() == [0.5]; ")
    outs = [subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
            for code in ("import scipy.linalg; " + _FAST_RESULT + _PRINT_RESULT, _FAST_RESULT + later + _PRINT_RESULT)]
    assert outs[0] == outs[1] and outs[0].count("0x") > 20


def test_interpreted_kernels_run_their_python_version() -> None:
    kernel = Kernel(lambda x: x + 1, python=lambda x: x - 1)
    with interpreted():
        assert kernel(1) == 0
    assert kernel(1) == 2


class _Child:
    returncode = 0

    def communicate(self) -> tuple[bytes, bytes]:
        return b"", b""


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """An empty cache directory; compilations recorded instead of run."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    started: list[str] = []

    def start(method: str, nice: bool = False) -> subprocess.Popen[bytes]:
        started.append(method + " nice" * nice)
        (tmp_path / f"compiling-{method}").touch()
        return _Child()  # type: ignore[return-value]

    monkeypatch.setattr(precompile, "_start", start)
    monkeypatch.setattr(precompile, "_POLL_S", 0.01)
    return started


def test_compile_engine_compiles_what_is_missing(cache: list[str], tmp_path: Path) -> None:
    precompile.compile_engine()()
    assert cache == ["fast", "reference nice"]
    cache.clear()
    (tmp_path / "compiled-fast").touch()
    (tmp_path / "compiled-reference").touch()
    precompile.compile_engine()()
    assert cache == []


def test_compile_engine_waits_for_another_process_compiling(cache: list[str], tmp_path: Path) -> None:
    (tmp_path / "compiling-fast").touch()
    wait = precompile.compile_engine(later=())
    (tmp_path / "compiled-fast").touch()      # the other process finishes
    wait()
    assert cache == []


def test_compile_engine_compiles_if_the_other_process_failed(cache: list[str], tmp_path: Path) -> None:
    (tmp_path / "compiling-fast").touch()
    wait = precompile.compile_engine(later=())
    (tmp_path / "compiling-fast").unlink()    # the other process ended without the marker
    wait()
    assert cache == ["fast"]


def test_of_many_callers_at_once_one_compiles(cache: list[str], tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """The workers of a fresh Ray node call compile_engine at once (workers/evaluate.py): one
    compiles, the others wait for it. Each caller opens the lock file itself, so the callers'
    flocks exclude each other here as across processes; a slow start widens the race."""
    started = precompile._start

    def slow_start(method: str, nice: bool = False) -> subprocess.Popen[bytes]:
        time.sleep(0.05)      # between looking for a compilation under way and marking its own
        return started(method, nice)

    monkeypatch.setattr(precompile, "_start", slow_start)
    waits: list[Callable[[], float]] = []
    callers = [threading.Thread(target=lambda: waits.append(precompile.compile_engine(later=())))
               for _ in range(8)]
    for caller in callers:
        caller.start()
    for caller in callers:
        caller.join()
    assert cache == ["fast"]
    (tmp_path / "compiled-fast").touch()
    for wait in waits:
        wait()


@pytest.mark.skipif(not Path("/proc/self/autogroup").exists(), reason="no Linux autogroups on this machine")
def test_the_background_compilation_runs_at_the_lowest_priority_its_session_included() -> None:
    """With autogroups, niceness alone orders processes within a session only: the background
    compilation's session of its own (``_start(nice=True)``) must be lowered too."""
    code = ("import os; from finaldrive.engine.precompile import _lower_priority; _lower_priority(); "
            "print(os.nice(0), open('/proc/self/autogroup').read().split()[-1])")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True,
                         start_new_session=True).stdout.split()
    assert out == ["19", "19"]


#: A fresh process's runs with both steppers (a smooth road: ROS34PW2; a measured profile: ROS2), series
#: and both chains, printing the kernels numba compiled for them (none when the cache holds everything).
_COMPILED_BY_A_RUN = """
from numba.core import event
compiled = []
class Listener(event.Listener):
    def on_start(self, ev): pass
    def on_end(self, ev): compiled.append(ev.data["dispatcher"].py_func.__qualname__)
event.register("numba:compile", Listener())
from finaldrive.engine import Design, Road, SimSettings, default_vehicle, simulate
for road in (Road.parse("sine:0.04:3"), Road.from_points([-5.0, 0.0, 5.0, 50.0], [0.0, 0.01, 0.0, 0.0])):
    for vehicle in (default_vehicle(), default_vehicle().replace(chain_runs=2.0)):
        r = simulate(Design.from_deg(250.0, 0.1, 0.1), road, SimSettings(duration=0.05, series=True), vehicle)
        assert r.ok, r.reason
print(compiled)
"""


@pytest.mark.slow
@pytest.mark.skipif(precompile._cpus() < 2, reason="one CPU: the fast method is built by one process")
def test_a_method_built_by_several_processes_is_whole_in_the_cache(tmp_path: Path) -> None:
    """The fast method compiled as compile_engine does (by several builders at once, two on a machine of
    two CPUs, from a trace of its plain-Python runs: engine.jit.parallel): a fresh process's
    runs, with either chain, then compile nothing; every kernel
    was compiled for one signature only (a traced type unlike the one numba infers would add a
    second); and none in both forms (one Python calls, one compiled code calls: engine.jit.kernel),
    which would compile it twice."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    (tmp_path / "compiling-fast").touch()   # locked, as compile_engine does before starting it
    subprocess.run([sys.executable, "-m", "finaldrive.engine.precompile", "fast"], env=env, check=True)
    assert (tmp_path / "compiled-fast").exists() and not (tmp_path / "compiling-fast").exists()
    indexes = {path.name.rsplit("-", 1)[0] for path in tmp_path.rglob("*.nbi")}
    data = {path.name for path in tmp_path.rglob("*.nbc")}
    assert len(data) == len(indexes) and all(name.endswith(".1.nbc") for name in data)
    for_python = {name for name in indexes if not name.startswith("callee-")}
    assert len(for_python) >= 3 and len(indexes) > 3 * len(for_python)
    assert not {name for name in for_python if "callee-" + name in indexes}
    out = subprocess.run([sys.executable, "-c", _COMPILED_BY_A_RUN], env=env, check=True, capture_output=True,
                         text=True).stdout
    assert out.strip() == "[]"


def _descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` (from /proc's parent links)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError):
            fields = stat.read_text().rsplit(")", 1)[1].split()
            children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = set(), [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.add(child)
            todo.append(child)
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="walks /proc")
def test_a_background_compilation_ends_with_its_caller(tmp_path: Path) -> None:
    """The reference method's background compilation (in a session of its own) does not outlive the
    process that started it, even one SIGKILLed (a scheduler's, issue 30): nothing of it is left
    within 5 s, and its lock is removed, so the next process compiles rather than waits."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    below: set[int] = set()
    caller = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from finaldrive.engine import precompile; "
                               "precompile._start('reference', nice=True); print('started', flush=True); "
                               "time.sleep(60)"],
        env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert caller.stdout is not None and caller.stdout.readline().strip() == "started"
        deadline = time.monotonic() + 10
        while not (below := _descendants(caller.pid)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert below, "no background compilation started"
        time.sleep(1.0)   # well into its work (imports, the lock held)
        below = _descendants(caller.pid)
        assert (tmp_path / "compiling-reference").exists() and not (tmp_path / "compiled-reference").exists()
        caller.kill()
        caller.wait()
        deadline = time.monotonic() + 5
        while (left := {p for p in below if Path(f"/proc/{p}").exists() and not _zombie(p)}) and \
                time.monotonic() < deadline:
            time.sleep(0.05)
        assert not left, f"left behind: {sorted(left)}"
        assert not (tmp_path / "compiling-reference").exists()
    finally:
        caller.kill()
        for pid in below:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def _zombie(pid: int) -> bool:
    with contextlib.suppress(OSError):
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    return True


_TERM_IN_A_CALLBACK = """
import ctypes, os, signal, sys, time
from finaldrive.engine import precompile
precompile.cache_dir().mkdir(parents=True, exist_ok=True)
precompile._lock("reference").touch()
precompile._end_with(os.getppid(), ["reference"])

@ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)
def compare(a, b):   # called back from C, as LLVM calls numba's compiler back
    os.kill(os.getpid(), signal.SIGTERM)   # the caller's death, as Linux signals it
    time.sleep(0.5)
    return 0

numbers = (ctypes.c_int * 2)(2, 1)
ctypes.CDLL(None).qsort(numbers, 2, ctypes.sizeof(ctypes.c_int), compare)
print("went on", flush=True)
time.sleep(5)
"""


def test_a_background_compilation_ends_at_once_even_inside_a_callback_from_c(tmp_path: Path) -> None:
    """The caller's death arriving while numba is called back from LLVM (a ctypes callback, where an
    exception is printed and dropped): the compilation ends at once, its lock removed, rather than
    going on (the cause of Ray's test finding a 'python' process alive 10 s after its driver ended)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", _TERM_IN_A_CALLBACK], env=env, capture_output=True, text=True,
                          timeout=60)
    assert (proc.returncode, proc.stdout) == (1, ""), proc.stderr[-2000:]
    assert time.monotonic() - start < 4.5   # not through the 5 s it would sleep had it gone on
    assert not (tmp_path / "compiling-reference").exists()


def _imports_by_ast(path: Path, modules: set[str]) -> set[str]:
    """The engine modules a file imports, read with Python's parser (the regex's check)."""
    import ast

    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out |= {f"{node.module}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
    return out & modules


def test_the_cache_key_covers_the_kernels_modules_and_everything_they_import() -> None:
    from finaldrive.engine.jit import cache

    modules = cache._modules(cache.ENGINE)
    names = set(modules)
    for name, path in modules.items():
        assert cache.imported(path.read_bytes(), modules) == _imports_by_ast(path, names), name
    sources = set(cache.kernel_sources())
    closure = {modules[n] for n in names if "@jit" in modules[n].read_text() or "@njit" in modules[n].read_text()}
    todo = list(closure)
    while todo:
        path = todo.pop()
        for name in _imports_by_ast(path, names):
            if modules[name] not in closure:
                closure.add(modules[name])
                todo.append(modules[name])
    assert closure <= sources
    assert {"model/tyre.py", "model/params.py", "fast/rosenbrock.py", "jit/kernel.py"} <= {
        p.relative_to(cache.ENGINE).as_posix() for p in sources}


@pytest.mark.parametrize(("module", "recompiles"), [
    ("fields.py", False), ("study/presets.py", False), ("optimize/de.py", False), ("precompile.py", False),
    ("__init__.py", False), ("model/tyre.py", True), ("model/params.py", True), ("solver/integrators.py", True),
    ("jit/kernel.py", True),
])
def test_a_comment_appended_to_a_module_without_kernels_recompiles_nothing(
        tmp_path: Path, module: str, recompiles: bool) -> None:
    """The compiled code's cache directory (engine.jit.cache) is named after the kernels' sources: a
    comment appended to a module the kernels do not import keeps it (nothing recompiles); one appended
    to a kernel module, or to a module whose constants a kernel reads, moves it."""
    import shutil

    from finaldrive.engine.jit import cache

    copy = tmp_path / "engine"
    shutil.copytree(cache.ENGINE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    before = cache.fingerprint(copy)
    cache._fingerprint.cache_clear()   # sources are read once a process
    with (copy / module).open("a") as f:
        f.write("# a comment\n")
    assert (cache.fingerprint(copy) != before) is recompiles
    cache._fingerprint.cache_clear()


def test_an_untested_numba_makes_plain_kernels_cached_apart(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.metadata

    from finaldrive.engine.jit import cache

    monkeypatch.delenv(cache.PLAIN_ENV, raising=False)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    tested = cache.cache_dir()
    for version, plain in (("0.60.0", False), ("0.68.1", False), ("0.69.0", True), ("0.59.1", True)):
        cache.plain.cache_clear()
        monkeypatch.setattr(importlib.metadata, "version", lambda name, v=version: v)
        assert cache.plain() is plain
        assert (cache.cache_dir() == tested.with_name("numba-plain-" + tested.name[6:])) is plain
    cache.plain.cache_clear()


@pytest.mark.slow
def test_plain_kernels_give_the_same_results(tmp_path: Path) -> None:
    """FINALDRIVE_PLAIN_NUMBA=1 (what an untested numba gets): every kernel a plain numba.njit(cache=True)
    function, compiled afresh into a cache of its own; the fast method's results equal this process's (the
    reference method's kernels are made the same way: compiling them too would double the test's minute)."""
    import json

    from finaldrive.engine import Design, Road, SimSettings, simulate

    code = ("import json, sys; from finaldrive.engine import Design, Road, SimSettings, simulate, is_compiled; "
            "from finaldrive.engine.jit import cache; assert cache.plain(); "
            "d = Design.from_deg(270, 0.15, 0.15); "
            "print(json.dumps([simulate(d, Road.parse('sine:0.04:3'), SimSettings(method=m, duration=0.5)).summary() "
            "for m in ('fast',)]))")
    env = {**os.environ, "FINALDRIVE_PLAIN_NUMBA": "1", "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    plain = json.loads(out.stdout)
    design = Design.from_deg(270, 0.15, 0.15)
    here = [simulate(design, Road.parse("sine:0.04:3"), SimSettings(method=m, duration=0.5)).summary()
            for m in ("fast",)]
    assert [p.pop("wall_s") >= 0 for p in plain] and [h.pop("wall_s") >= 0 for h in here]
    assert plain == json.loads(json.dumps(here))
    assert any(tmp_path.rglob("*.nbi"))   # numba's own cache, in the directory given
