"""SciPy's BLAS and LAPACK for numba, without the scipy.linalg package around them.

numba imports ``scipy.linalg.cython_blas`` when it sets up its compiler (numba.np.arraymath checks
for BLAS on import), though no kernel calls BLAS or LAPACK (engine.model.linalg solves in loops of
its own, the same bits on every CPU), and numba's compiled ``np.linalg`` finds LAPACK in
``scipy.linalg.cython_lapack``. Importing either runs ``scipy.linalg``'s ``__init__`` first:
about 0.3 s (most of SciPy's linear algebra, and numpy.f2py through SciPy's array-API layer), a
third of what a fresh process needs to load the compiled engine, for code it never calls. The two
are self-contained extension modules (the same functions whoever loads them): :func:`load` loads
them alone (a few ms) into ``sys.modules``, where numba's ``import`` finds them. Should
``scipy.linalg`` be imported later, its ``__init__`` runs as usual and the two become its
attributes again (:class:`_Rebind`), as after a plain import.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from importlib.abc import Loader

_PACKAGE = "scipy.linalg"
_MODULES = ("cython_blas", "cython_lapack")


class _Rebind:
    """A meta path finder and loader (not importlib.abc's: it imports importlib.resources, ~10 ms):
    finds scipy.linalg once, runs its own loader, then binds the modules loaded alone to it."""

    def __init__(self) -> None:
        self._loader: Loader | None = None

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if fullname != _PACKAGE:
            return None
        sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is None or spec.loader is None:
            return spec
        self._loader, spec.loader = spec.loader, cast("Loader", self)
        return spec

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        assert self._loader is not None
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        assert self._loader is not None and module.__spec__ is not None
        module.__loader__ = module.__spec__.loader = self._loader
        self._loader.exec_module(module)
        for name in _MODULES:
            if f"{_PACKAGE}.{name}" in sys.modules:
                setattr(module, name, sys.modules[f"{_PACKAGE}.{name}"])


def load() -> None:
    """Load scipy.linalg.cython_blas and cython_lapack without scipy.linalg's ``__init__``, unless
    scipy.linalg is imported already (then nothing to save). If SciPy or either module cannot be
    found or loaded, numba is left to its plain import (and its own error)."""
    if _PACKAGE in sys.modules or all(f"{_PACKAGE}.{name}" in sys.modules for name in _MODULES):
        return
    try:
        package = importlib.util.find_spec(_PACKAGE)  # imports scipy (numba does), not scipy.linalg
    except ImportError:
        return
    if package is None or not package.submodule_search_locations:
        return
    loaded = []
    try:
        for name in _MODULES:
            spec = importlib.machinery.PathFinder.find_spec(f"{_PACKAGE}.{name}", package.submodule_search_locations)
            if spec is None or spec.loader is None:
                raise ImportError(f"{_PACKAGE}.{name} not found")
            module = importlib.util.module_from_spec(spec)
            sys.modules[spec.name] = module
            loaded.append(spec.name)
            spec.loader.exec_module(module)
    except ImportError:
        for full in loaded:
            del sys.modules[full]
        return
    sys.meta_path.insert(0, _Rebind())
