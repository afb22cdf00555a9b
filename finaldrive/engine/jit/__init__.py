"""How the engine's kernels are compiled with numba, apart from the model and the solvers.

- :mod:`~finaldrive.engine.jit.kernel`: the ``@jit`` decorator (a :class:`Kernel`, compiled at its
  first call and cached on disk), plain-Python runs and traces of the kernels;
- :mod:`~finaldrive.engine.jit.cache`: where the compiled code is cached, keyed by the sources of
  the kernels' modules and the toolchain;
- :mod:`~finaldrive.engine.jit.parallel`: compiling traced kernels in several processes at once;
- :mod:`~finaldrive.engine.jit.lapack`: SciPy's LAPACK for numba without ``scipy.linalg``.

numba's internals the build relies on are tested with the numba versions pyproject.toml allows;
with another numba (or ``FINALDRIVE_PLAIN_NUMBA=1``) the kernels are plain ``numba.njit(cache=True)``
functions (:func:`~finaldrive.engine.jit.cache.plain`). What to compile, and when (the engine's
methods, once per machine) is engine.precompile's: this package knows no model.
"""
