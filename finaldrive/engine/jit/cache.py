"""Where the engine's compiled code is cached, and the key that decides when it is stale.

numba's on-disk cache checks only the timestamp of the file that defines a compiled function,
yet a compiled function carries copies of every compiled function it calls, from any module, and
the values of the module-level constants it reads (the parameter indices of engine.model.params,
say), frozen in at compile time. Editing engine/model/tyre.py alone would leave the cached
right-hand sides of both solvers running the old tyre. So the cache lives in a directory named
after a hash of the toolchain and of the sources the kernels are made of: the modules that define
kernels (a ``@jit`` or ``@njit`` line) and every engine module they import, transitively
(:func:`kernel_sources`), and this package's kernel.py and cache.py. Any change to one of them
compiles everything afresh; a change elsewhere in the engine (its facade, the optimisers, the
study layer, the outputs' field table) compiles nothing. The toolchain is this Python's version and
where numba and llvmlite are installed and when: another venv on the same checkout, or numba
upgraded in place, has a cache of its own and compiles afresh rather than finding the compile
markers of code it cannot load. A NUMBA_CACHE_DIR set by the user is respected as it is.

The kernels use numba's internals (engine.jit.kernel) as tested with the numba versions of
:data:`TESTED_NUMBA`; with another numba, or FINALDRIVE_PLAIN_NUMBA=1, they are plain
``numba.njit(cache=True)`` functions (:func:`plain`), cached apart.
"""

from __future__ import annotations

import functools
import os
import re
import sys
from pathlib import Path

#: The engine's folder (the package finaldrive.engine).
ENGINE = Path(__file__).resolve().parents[1]
_PACKAGE = "finaldrive.engine"
#: A line that makes a kernel.
_KERNEL = re.compile(rb"^\s*@n?jit\b", re.M)
#: ``from finaldrive.engine.X import a, b`` (also parenthesised over lines) and ``import finaldrive.engine.X``.
_IMPORT = re.compile(rb"^\s*(?:from\s+(finaldrive\.engine[\w.]*)\s+import\s+(\([^)]*\)|[^\n#]*)"
                     rb"|import\s+(finaldrive\.engine[\w.]*))", re.M)
#: This package's modules whose content changes compiled code (the kernels' options and the key).
_OWN = ("jit/kernel.py", "jit/cache.py")

#: numba versions (major, minor) whose internals engine.jit.kernel is tested with: [first, past the last).
TESTED_NUMBA = ((0, 60), (0, 69))
#: Set to 1: plain numba.njit(cache=True) kernels whatever numba's version (for tests, and for a numba
#: whose internals changed within the tested versions).
PLAIN_ENV = "FINALDRIVE_PLAIN_NUMBA"


def _modules(root: Path) -> dict[str, Path]:
    """Every module of the engine under ``root``, by its dotted name."""
    out = {}
    for path in root.rglob("*.py"):
        parts = path.relative_to(root).with_suffix("").parts
        name = ".".join((_PACKAGE, *parts))
        out[name.removesuffix(".__init__")] = path
    return out


def imported(source: bytes, modules: dict[str, Path]) -> set[str]:
    """The engine modules a module's source imports (anywhere in it: inside functions too)."""
    out = set()
    for module, names, plain in _IMPORT.findall(source):
        if plain:
            out.add(plain.decode())
            continue
        out.add(module.decode())
        for name in re.findall(rb"\w+", re.sub(rb"#[^\n]*", b"", names)):
            if (sub := f"{module.decode()}.{name.decode()}") in modules:
                out.add(sub)
    return out & set(modules)


def kernel_sources(root: Path = ENGINE) -> list[Path]:
    """The files the compiled code is made of: the modules that define kernels, every engine module
    they import (transitively), and this package's kernel.py and cache.py; sorted."""
    modules = _modules(root)
    sources = {name: path.read_bytes() for name, path in modules.items()}
    todo = [name for name, text in sources.items() if _KERNEL.search(text)]
    todo += [name for name, path in modules.items() if path.relative_to(root).as_posix() in _OWN]
    seen: set[str] = set()
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            todo.extend(imported(sources[name], modules))
    return sorted(modules[name] for name in seen)


def fingerprint(root: Path = ENGINE) -> str:
    """sha256 (16 hex digits) of the toolchain (this Python's version, numba's and llvmlite's files:
    path, time) and of :func:`kernel_sources` (path and content; read once a process)."""
    import importlib.util

    toolchain = [sys.version]
    for name in ("numba", "llvmlite"):  # found, not imported
        spec = importlib.util.find_spec(name)
        origin = spec.origin if spec is not None and spec.origin else ""
        toolchain.append(f"{name}:{origin}:{os.stat(origin).st_mtime_ns if origin else 0}")
    return _fingerprint(root, "\n".join(toolchain))


@functools.cache
def _fingerprint(root: Path, toolchain: str) -> str:
    import hashlib

    digest = hashlib.sha256(toolchain.encode())
    for path in kernel_sources(root):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


@functools.cache
def plain() -> bool:
    """Whether the kernels are plain ``numba.njit(cache=True)`` functions: numba outside :data:`TESTED_NUMBA`,
    or FINALDRIVE_PLAIN_NUMBA=1 (read once a process)."""
    import importlib.metadata

    if os.environ.get(PLAIN_ENV) == "1":
        return True
    version = tuple(int(n) for n in re.findall(r"\d+", importlib.metadata.version("numba"))[:2])
    return not TESTED_NUMBA[0] <= version < TESTED_NUMBA[1]


def cache_dir() -> Path:
    """Where the compiled code is cached: NUMBA_CACHE_DIR if set, else engine/__pycache__/numba-<fingerprint>
    (numba-plain-<fingerprint> for plain kernels; in the temporary directory if the engine's folder
    is read-only)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    import tempfile  # here: it imports shutil, lzma, bz2 (~5 ms), which the static geometry never needs

    base = ENGINE / "__pycache__" if os.access(ENGINE, os.W_OK) else Path(tempfile.gettempdir()) / "finaldrive"
    return base / f"numba-{'plain-' if plain() else ''}{fingerprint()}"
