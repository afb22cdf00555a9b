"""Fixed-step integrators of section 3.2 for y' = f(t, y), eqs. (59)-(66).

- trapezoidal rule (62), implicit, 2nd order: used for the first steps (section 3.3);
- Adams-Bashforth 4 predictor (63) and Adams-Moulton 4 corrector (64), 4th order, with the
  corrector iterated under the under-relaxation factor nu (65) until the change of the first
  ``n_err`` components (the coordinates q) is below ``tol`` in the Euclidean norm (66).

``f(t, y, ctx, out) -> int`` writes y' into out and returns 0, or a non-zero failure code.
Each step returns the number of corrector iterations used, or a negative code:
-1 the iteration did not converge, -2 f failed (its code is in ``status[0]``).

The steps are built for a given compiled f by :func:`make_steppers` (a closure, so numba
compiles f inline and can cache the result on disk; a function-typed argument would not be
cacheable across processes).
"""

from __future__ import annotations

import math

import numpy as np

from finaldrive.engine.jit.kernel import jit, njit

# Adams-Bashforth (63) and Adams-Moulton (64) coefficients, over 24.
AB4 = (55.0, -59.0, 37.0, -9.0)
AM4 = (9.0, 19.0, -5.0, 1.0)

NOT_CONVERGED = -1
RHS_FAILED = -2


@jit
def _error(a: np.ndarray, b: np.ndarray, n_err: int) -> float:
    """Eq. (66): Euclidean norm of the change of the first n_err components."""
    s = 0.0
    for i in range(n_err):
        d = a[i] - b[i]
        s += d * d
    return math.sqrt(s)


def make_steppers(f, cache: bool = True):
    """(trapezoidal_step, abm_step) for the compiled right-hand side f.

    Pass cache=False for more than one f built in a process (test ODEs): cached closures
    are keyed by their source location, not by f.
    """

    @njit(cache=cache, nogil=True)
    def trapezoidal_step(ctx, t, y, fy, dt, nu, tol, max_iter, n_err, ynew, fnew, status):
        """One step of eq. (62), solved by under-relaxed fixed-point iteration from Euler's
        guess. On success ynew holds y_{n+1} and fnew = f(t + dt, y_{n+1})."""
        c_old = y + dt * fy
        for it in range(max_iter):
            code = f(t + dt, c_old, ctx, fnew)
            if code != 0:
                status[0] = code
                return RHS_FAILED
            c_star = y + 0.5 * dt * (fy + fnew)                      # (62)
            ynew[:] = nu * c_star + (1.0 - nu) * c_old               # (65)
            if _error(ynew, c_old, n_err) <= tol:                    # (66)
                code = f(t + dt, ynew, ctx, fnew)
                if code != 0:
                    status[0] = code
                    return RHS_FAILED
                return it + 1
            c_old[:] = ynew
        return NOT_CONVERGED

    @njit(cache=cache, nogil=True)
    def abm_step(ctx, t, y, f0, f1, f2, f3, dt, nu, tol, max_iter, n_err, ynew, fnew, status):
        """One Adams-Bashforth-Moulton step; f0..f3 are f at steps n, n-1, n-2, n-3.
        On success ynew holds y_{n+1} and fnew = f(t + dt, y_{n+1})."""
        h = dt / 24.0
        p = y + h * (AB4[0] * f0 + AB4[1] * f1 + AB4[2] * f2 + AB4[3] * f3)   # (63) predictor
        known = y + h * (AM4[1] * f0 + AM4[2] * f1 + AM4[3] * f2)
        c_old = p
        for it in range(max_iter):
            code = f(t + dt, c_old, ctx, fnew)
            if code != 0:
                status[0] = code
                return RHS_FAILED
            c_star = known + h * AM4[0] * fnew                                # (64) corrector
            ynew[:] = nu * c_star + (1.0 - nu) * c_old                         # (65)
            if _error(ynew, c_old, n_err) <= tol:                              # (66)
                code = f(t + dt, ynew, ctx, fnew)
                if code != 0:
                    status[0] = code
                    return RHS_FAILED
                return it + 1
            c_old = ynew.copy()
        return NOT_CONVERGED

    return trapezoidal_step, abm_step


def make_integrator(f, cache: bool = False):
    """integrate(ctx, t0, y0, dt, n_steps, n_trap, nu, tol, max_iter, n_err) -> (y_end, code):
    trapezoidal start for n_trap steps (at least 3, to fill the ABM history), then ABM.

    For verification on test ODEs; the motorcycle's driver loop (engine.solver.reference)
    uses the same two step functions.
    """
    trapezoidal_step, abm_step = make_steppers(f, cache)

    @njit(cache=cache)
    def integrate(ctx, t0, y0, dt, n_steps, n_trap, nu, tol, max_iter, n_err):
        n = y0.shape[0]
        hist = np.zeros((4, n))  # hist[k] = f at step n - k
        y = y0.copy()
        ynew = np.empty(n)
        fnew = np.empty(n)
        status = np.zeros(1, dtype=np.int64)
        code = f(t0, y, ctx, hist[0])
        if code != 0:
            return y, code
        t = t0
        for step in range(n_steps):
            if step < max(n_trap, 3):
                r = trapezoidal_step(ctx, t, y, hist[0], dt, nu, tol, max_iter, n_err, ynew, fnew, status)
            else:
                r = abm_step(ctx, t, y, hist[0], hist[1], hist[2], hist[3], dt, nu, tol, max_iter,
                             n_err, ynew, fnew, status)
            if r < 0:
                return y, r
            for k in range(3, 0, -1):
                hist[k] = hist[k - 1]
            hist[0] = fnew
            y[:] = ynew
            t += dt
        return y, 0

    return integrate
