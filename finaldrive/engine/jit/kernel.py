"""The one place that configures numba for the engine: compiled at first use, cached on disk
(engine.jit.cache: where, and when the cache is stale), no Python fallback.

What follows uses numba's internals (a dispatcher's call typing, its cache's loading, the
``_nrt`` and wrapper options, the runtime's start), as tested with the numba versions of
engine.jit.cache.TESTED_NUMBA, which pyproject.toml allows. With another numba, or with
``FINALDRIVE_PLAIN_NUMBA=1``, every kernel is a plain ``numba.njit(cache=True)`` function
(engine.jit.cache.plain): the same results, compiled slower and once per argument type, by one
process, into a cache directory of their own.

``@jit`` makes a :class:`Kernel`: numba is imported, and the function compiled (or loaded from the
cache), at its first call, not when the engine is imported. Called from compiled code, a kernel is
compiled for the plain types of its arguments only: numba would otherwise compile one more
specialisation for every constant argument (``gap(y, 1, ...)``, ``False``) and every omitted
default, each optimising its callees again (fast_rhs was compiled five times). Inside
:func:`interpreted`, kernels Python has not yet called compiled run as plain Python: the static
geometry (one equilibrium, tens of milliseconds) needs neither numba nor its cache.

A kernel has two compiled forms, each cached apart: the one Python calls, with numba's wrapper that
unboxes Python's arguments, and the one compiled code calls, without it. numba would otherwise
build, optimise and cache that wrapper (and a C-callable one, which nothing here uses) for every
kernel, though most are only ever called from compiled code: a fifth of the fast method's
compilation (docs/performance-log.md). A kernel that both call on a method's path is marked
``one_form``: its form with Python's wrapper serves both (a test of the fast method's build checks
that none of its kernels is compiled in both forms, tests/engine/test_compiled.py).

Inside :func:`traced`, every kernel runs as plain Python, and each call is recorded with the
argument types numba would compile it for, in the form it would compile (a
:class:`Trace`): what engine.jit.parallel needs to compile those kernels in several processes
at once.

numba's cache also loads all of numba's typing and lowering registries before it loads anything
(~0.4 s of a fresh process's first result), which compiled code loaded from the cache does not
need: the kernels' cache skips that (_cache_class), and a process about to compile loads them
first (load_registries).
"""

from __future__ import annotations

import contextlib
import functools
import gc
import os
import threading
from collections.abc import Callable, Iterator
from typing import Any, overload

from finaldrive.engine.jit.cache import cache_dir, plain

_lock = threading.Lock()
_local = threading.local()
#: numba's options for the kernels (besides the on-disk cache): fast math off so the results are bit-reproducible
#: across runs on one machine; numpy's error model (a division by zero gives inf or nan, which the
#: loops report as NONFINITE) spares a zero test per division.
_OPTIONS: dict[str, Any] = {"nogil": True, "error_model": "numpy"}
#: A kernel that makes no array (nor a slice: a view is an array) is compiled without numba's
#: runtime, so the arrays it is given and passes on are not reference-counted at every call (the
#: fast path's loop 1.10-1.13x faster, results bit-identical). numba refuses to compile such a
#: kernel if it makes an array after all; ``jit(allocates=True)`` marks those that do.
_NO_RUNTIME: dict[str, Any] = {"_nrt": False}
#: No C-callable wrapper (for ctypes and numba's cfunc, which the engine does not use) in either form;
#: no Python wrapper in the form compiled code calls.
_FOR_PYTHON: dict[str, Any] = {"no_cfunc_wrapper": True}
_FOR_CALLERS: dict[str, Any] = {"no_cfunc_wrapper": True, "no_cpython_wrapper": True}


@functools.cache
def start_runtime() -> None:
    """Import numba, point its cache at cache_dir() and start its runtime (once); SciPy's LAPACK for
    it without scipy.linalg (engine.jit.lapack); then ``gc.freeze()`` (see load_registries): what
    loading compiled code needs, and what a kernel's first use does (a worker may do it beforehand,
    while the engine compiles: workers.make_executor).

    numba's typing and lowering registries are left to the first compilation (numba's compiler
    loads them itself): loading compiled code from the cache needs only the runtime."""
    from finaldrive.engine.jit import lapack

    lapack.load()
    from numba import config
    from numba.core.registry import cpu_target
    from numba.core.runtime.nrt import rtsys

    if not os.environ.get("NUMBA_CACHE_DIR"):
        config.CACHE_DIR = str(cache_dir())  # type: ignore[attr-defined]
    if not plain():
        rtsys.initialize(cpu_target.target_context)
    gc.freeze()


@functools.cache
def load_registries() -> None:
    """Load numba's typing and lowering registries now, then ``gc.freeze()``: for a process about to
    compile. They are some 100k objects that live as long as the process, and every full
    collection walks them again, the interpreter's at exit included (~0.5 s); frozen, the collector
    skips them and whatever else exists by then (the process's imports, mostly): only a reference
    cycle among those objects that is dropped later stays uncollected."""
    start_runtime()
    if plain():
        return
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.registry import cpu_target

    with global_compiler_lock:   # as numba's compiler refreshes them: not beside another thread's compilation
        cpu_target.typing_context.refresh()
        cpu_target.target_context.refresh()
    gc.freeze()


@functools.cache
def _dispatcher_class(callee: bool) -> Any:
    """numba's CPU dispatcher, typing calls from compiled code with the plain types of the arguments
    (a literal as its type, an omitted default as its value's type); ``callee``: one that refuses
    calls from Python (compiled without Python's wrapper, its entry point is null)."""
    from numba import typeof, types
    from numba.core.registry import CPUDispatcher

    def plain(t: Any) -> Any:
        return types.unliteral(typeof(t.value) if isinstance(t, types.Omitted) else t)

    class PlainDispatcher(CPUDispatcher):
        def get_call_template(self, args: Any, kws: Any) -> Any:
            _, folded = self._compiler.fold_argument_types(args, kws)  # type: ignore[attr-defined]
            return super().get_call_template([plain(t) for t in folded], {})

    if not callee:
        return PlainDispatcher

    class CalleeDispatcher(PlainDispatcher):
        def __call__(self, *args: Any, **kws: Any) -> Any:
            raise TypeError(f"{self.py_func.__qualname__}: this form is for compiled callers; Python calls "
                            "the kernel itself")

    return CalleeDispatcher


@functools.cache
def _cache_class(prefix: str) -> Any:
    """numba's on-disk cache of compiled functions, its files named ``<prefix><module>.<function>-<line>...``
    (the two forms of a kernel never share an index), loading without refreshing the registries."""
    from numba.core.caching import CompileResultCacheImpl, FunctionCache

    class Impl(CompileResultCacheImpl):
        def get_filename_base(self, fullname: str, abiflags: str) -> str:
            return prefix + super().get_filename_base(fullname, abiflags)

    class _Cache(FunctionCache):
        """numba's FunctionCache but for load_overload, which refreshes the target's registries
        first (numba 0.60-0.68): rebuilding cached code needs none of them, only the runtime."""

        _impl_class = Impl

        def load_overload(self, sig: Any, target_context: Any) -> Any:
            try:
                guard, load = self._guard_against_spurious_io_errors, self._load_overload
            except AttributeError:   # another numba's internals: its own way, registries and all
                return super().load_overload(sig, target_context)
            with guard():
                return load(sig, target_context)

    return _Cache


def njit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """numba's njit with the engine's cache directory (for functions built at run time)."""
    import numba

    load_registries()   # numba's own cache loads them anyway; frozen here
    return numba.njit(**options)


class Kernel:
    """A compiled model or solver function: numba's dispatchers of its two forms, each made at its first use.

    Kernels call each other in compiled code as dispatchers do (numba reads ``_numba_type_``), through
    the form without Python's wrapper (``callee``); Python calls ``dispatcher``'s. ``prepare`` runs
    before either form is made (to bind what it needs of numba; it may run twice); ``python`` runs
    instead of ``fn`` inside :func:`interpreted` (default: ``fn``).
    """

    def __init__(self, fn: Callable[..., Any], prepare: Callable[[], None] | None = None,
                 python: Callable[..., Any] | None = None, *, allocates: bool = False, one_form: bool = False,
                 plain_from_python: bool = False) -> None:
        functools.update_wrapper(self, fn)
        self.py_func = fn
        self._allocates = allocates
        self._one_form = one_form
        self._plain_from_python = plain_from_python
        self._prepare = prepare
        self._python = python or fn
        self._dispatcher: Any = None
        self._callee: Any = None

    @property
    def dispatcher(self) -> Any:
        """numba's dispatcher of the form Python calls (imports and configures numba the first time)."""
        if self._dispatcher is None:
            self._make(callee=False)
        return self._dispatcher

    @property
    def callee(self) -> Any:
        """numba's dispatcher of the form compiled code calls: without a Python wrapper, it must not
        be called from Python (``one_form``: the dispatcher Python calls)."""
        if self._one_form or plain():
            return self.dispatcher
        if self._callee is None:
            self._make(callee=True)
        return self._callee

    def _make(self, callee: bool) -> None:
        """Make the dispatcher of one form, once (another thread may have made it meanwhile)."""
        with _lock:
            if (self._callee if callee else self._dispatcher) is not None:
                return
            if self._prepare is not None:
                self._prepare()
            start_runtime()
            if plain():
                import numba

                self._dispatcher = numba.njit(cache=True, **_OPTIONS)(self.py_func)
                return
            options = {"nopython": True, **_OPTIONS, **({} if self._allocates else _NO_RUNTIME),
                       **(_FOR_CALLERS if callee else _FOR_PYTHON)}
            made = _dispatcher_class(callee)(py_func=self.py_func, targetoptions=options)
            made._cache = _cache_class("callee-" if callee else "")(self.py_func)  # as enable_caching() would
            if callee:
                self._callee = made
            else:
                self._dispatcher = made

    @property
    def _numba_type_(self) -> Any:
        return self.callee._numba_type_

    def compile(self, form: str, signature: tuple[Any, ...]) -> None:
        """Compile (or load from the cache) the form (PYTHON, CALLEE) for the argument types."""
        if form not in (PYTHON, CALLEE):
            raise ValueError(f"unknown form {form!r}: expected {PYTHON!r} or {CALLEE!r}")
        (self.dispatcher if form == PYTHON else self.callee).compile(signature)

    def __call__(self, *args: Any) -> Any:
        if getattr(_local, "interpreted", False):
            trace = getattr(_local, "trace", None)
            if trace is not None and (trace.inside or not self._plain_from_python):
                return trace.call(self, args)
            if self._dispatcher is None or self._plain_from_python:
                return self._python(*args)
        elif self._plain_from_python:
            return self._python(*args)
        return self.dispatcher(*args)


@overload
def jit(fn: Callable[..., Any], *, allocates: bool = False, one_form: bool = False,
        plain_from_python: bool = False) -> Kernel: ...
@overload
def jit(*, allocates: bool = False, one_form: bool = False,
        plain_from_python: bool = False) -> Callable[[Callable[..., Any]], Kernel]: ...
def jit(fn: Callable[..., Any] | None = None, *, allocates: bool = False, one_form: bool = False,
        plain_from_python: bool = False) -> Any:
    """Decorator for compiled model and solver functions (see the module's docstring):
    ``@jit``; ``allocates=True`` for a function that makes arrays or slices (it needs numba's
    runtime); ``one_form=True`` for one that Python and compiled code both call on a method's
    path (one form, with Python's wrapper, serves both); ``plain_from_python=True`` for a scalar
    function that Python's calls run as plain Python (a few microseconds, and no numba for code
    that needs none: engine.model.libm)."""
    if fn is None:
        return functools.partial(Kernel, allocates=allocates, one_form=one_form, plain_from_python=plain_from_python)
    return Kernel(fn, allocates=allocates, one_form=one_form, plain_from_python=plain_from_python)


@contextlib.contextmanager
def interpreted() -> Iterator[None]:
    """In this thread, run as plain Python (no numba) the kernels whose form Python calls is not made yet."""
    before = getattr(_local, "interpreted", False)
    _local.interpreted = True
    try:
        yield
    finally:
        _local.interpreted = before


#: The two forms of a kernel (Kernel.dispatcher, Kernel.callee), as a Trace names them.
PYTHON, CALLEE = "python", "callee"
#: A traced call: the kernel, its form, the argument types of that form's compiled specialisation.
Call = tuple[Kernel, str, tuple[Any, ...]]


class Trace:
    """The kernels called inside :func:`traced`: ``calls``, each (kernel, form, argument types) once in
    the order first made, and ``callees``, the calls each made (from its plain-Python run).

    The argument types are those numba compiles the form for: for a call from Python, numba's types of
    the values given and ``omitted`` for each default left out (as numba's dispatcher types a call);
    for a call from a kernel, their types with the defaults filled in (_dispatcher_class). Those of a
    call from compiled code are the types its caller's compilation infers, which the values' types
    matched for every kernel of the fast method (tests/engine/test_compiled.py); a branch the traced
    run does not take is not traced."""

    def __init__(self) -> None:
        from numba import typeof, types
        from numba.core.typing.typeof import Purpose

        self._typeof = functools.partial(typeof, purpose=Purpose.argument)
        self._omitted = types.Omitted
        self.callees: dict[Call, list[Call]] = {}
        self._stack: list[Call] = []

    @property
    def inside(self) -> bool:
        """Whether a kernel's plain-Python run is in progress (a call now is compiled code's)."""
        return bool(self._stack)

    @property
    def calls(self) -> list[Call]:
        return list(self.callees)

    def _types(self, kernel: Kernel, args: tuple[Any, ...]) -> tuple[Any, ...]:
        import inspect

        defaults = _defaults(kernel.py_func)[len(args):]
        if any(d is inspect.Parameter.empty for d in defaults):
            raise TypeError(f"{kernel.py_func.__qualname__}() called with {len(args)} arguments: too few")
        if not self._stack:   # from Python
            return tuple(map(self._typeof, args)) + tuple(self._omitted(d) for d in defaults)
        return tuple(map(self._typeof, args + defaults))

    def call(self, kernel: Kernel, args: tuple[Any, ...]) -> Any:
        """Record the call, then run the kernel as plain Python (its own calls recorded inside)."""
        form = PYTHON if not self._stack or kernel._one_form else CALLEE
        call = (kernel, form, self._types(kernel, args))
        self.callees.setdefault(call, [])
        if self._stack and call not in self.callees[self._stack[-1]]:
            self.callees[self._stack[-1]].append(call)
        self._stack.append(call)
        try:
            return kernel._python(*args)
        finally:
            self._stack.pop()


@functools.cache
def _defaults(fn: Callable[..., Any]) -> tuple[Any, ...]:
    """The default of every positional parameter (``inspect.Parameter.empty`` for none)."""
    import inspect

    return tuple(p.default for p in inspect.signature(fn).parameters.values()
                 if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD))


@contextlib.contextmanager
def traced() -> Iterator[Trace]:
    """In this thread, run every kernel as plain Python (compiled or not), recording the calls in the
    Trace yielded (imports numba, for its types)."""
    trace = Trace()
    before = getattr(_local, "trace", None)
    _local.trace = trace
    try:
        with interpreted():
            yield trace
    finally:
        _local.trace = before
