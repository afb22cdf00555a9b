"""The transcendental functions the kernels call, from one fixed implementation.

numba compiles ``math.sin`` (and cos, exp, atan, atan2, asin, acos, ``**``) to calls into the C
library, and glibc picks its implementation by the CPU: with FMA and AVX2 one variant, without them
another, which round differently in the last bit. Those bits reach every step of a run, so one
design simulated on two x86-64 machines gave distances up to 20 um apart, and a seeded DE ended at
another design (issue 30). The functions here are FreeBSD's msun (Sun's fdlibm, freely
redistributable with its notice: "Developed at SunPro, a Sun Microsystems, Inc. business.
Permission to use, copy, modify, and distribute this software is freely granted, provided that this
notice is preserved.") written with IEEE double additions, multiplications, divisions and square
roots only, each correctly rounded on every x86-64 CPU (numba compiles without fast math, so LLVM
neither fuses nor reorders them): the same bits on every machine, whatever its libm or CPU. Each is
within 1 ulp of the correctly rounded value (tests/engine/test_libm.py checks them against the C
library's over random arguments). Bit access (fdlibm's high words) is replaced by comparisons with
the same thresholds, by a table of powers of 2 and by Veltkamp's split, all exact.

Python's calls run the functions as plain Python (``plain_from_python``: the same bits, microseconds a
call, no numba for code that needs none); compiled code calls them compiled.

Outside the engine's use: ``sin``/``cos`` of |x| > 2^19 pi/2 (823,550 rad) give NaN (a run that gets
there fails as non-finite), and ``hypot`` is sqrt(x^2 + y^2), without fdlibm's guard against
overflow beyond 1e154 (lengths here are metres).
"""

from __future__ import annotations

import math
import struct

import numpy as np

from finaldrive.engine.jit.kernel import jit


def _f(bits: int) -> float:
    """The double with these IEEE 754 bits (fdlibm's constants are given by their bits)."""
    return float(struct.unpack("<d", struct.pack("<Q", bits))[0])


_NAN = math.nan
_INF = math.inf

# --- sin and cos: k_sin.c, k_cos.c, e_rem_pio2.c ------------------------------------------------
_S1 = _f(0xBFC5555555555549)
_S2 = _f(0x3F8111111110F8A6)
_S3 = _f(0xBF2A01A019C161D5)
_S4 = _f(0x3EC71DE357B1FE7D)
_S5 = _f(0xBE5AE5E68A2B9CEB)
_S6 = _f(0x3DE5D93A5ACFD57C)
_C1 = _f(0x3FA555555555554C)
_C2 = _f(0xBF56C16C16C15177)
_C3 = _f(0x3EFA01A019CB1590)
_C4 = _f(0xBE927E4F809C52AD)
_C5 = _f(0x3E21EE9EBDB4B1C4)
_C6 = _f(0xBDA8FAE9BE8838D4)
_INVPIO2 = _f(0x3FE45F306DC9C883)
_PIO2_1 = _f(0x3FF921FB54400000)
_PIO2_1T = _f(0x3DD0B4611A626331)
_PIO2_2 = _f(0x3DD0B4611A600000)
_PIO2_2T = _f(0x3BA3198A2E037073)
_PIO2_3 = _f(0x3BA3198A2E000000)
_PIO2_3T = _f(0x397B839A252049C1)
#: |x| below this is within pi/4 (fdlibm: high word <= 0x3fe921fb).
_PIO4_BOUND = _f(0x3FE921FC00000000)
#: The largest |x| reduced here (fdlibm's "medium" range, high word <= 0x413921fb).
_MEDIUM = _f(0x413921FC00000000)
_TWO_M15 = 2.0 ** -15
_TWO_M48 = 2.0 ** -48
_TWO_M26 = 2.0 ** -26
_TWO_M27 = 2.0 ** -27


@jit(plain_from_python=True)
def _ksin(x: float, y: float, iy: int) -> float:
    """sin(x + y) for |x| <= pi/4, y the tail of x (iy = 0: y is 0)."""
    z = x * x
    w = z * z
    r = _S2 + z * (_S3 + z * _S4) + z * w * (_S5 + z * _S6)
    v = z * x
    if iy == 0:
        return x + v * (_S1 + z * r)
    return x - ((z * (0.5 * y - v * r) - y) - v * _S1)


@jit(plain_from_python=True)
def _kcos(x: float, y: float) -> float:
    """cos(x + y) for |x| <= pi/4, y the tail of x."""
    z = x * x
    w = z * z
    r = z * (_C1 + z * (_C2 + z * _C3)) + w * w * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


@jit(plain_from_python=True)
def _rem_pio2(ax: float) -> tuple[int, float, float]:
    """ax = n pi/2 + (y0 + y1) with |y0 + y1| <= pi/4, for pi/4 <= ax <= _MEDIUM: Cody and Waite's
    reduction by pi/2 in three parts, a second and third when the first cancels."""
    fn = float(math.floor(ax * _INVPIO2 + 0.5))
    r = ax - fn * _PIO2_1
    w = fn * _PIO2_1T
    y0 = r - w
    if abs(y0) < ax * _TWO_M15:   # fdlibm: y0's exponent 16 or more below ax's (no frexp: a libm call)
        t = r
        w = fn * _PIO2_2
        r = t - w
        w = fn * _PIO2_2T - ((t - r) - w)
        y0 = r - w
        if abs(y0) < ax * _TWO_M48:
            t = r
            w = fn * _PIO2_3
            r = t - w
            w = fn * _PIO2_3T - ((t - r) - w)
            y0 = r - w
    return int(fn), y0, (r - y0) - w


@jit(plain_from_python=True)
def sin(x: float) -> float:
    """sin(x) (s_sin.c)."""
    ax = abs(x)
    if ax < _PIO4_BOUND:
        if ax < _TWO_M26:
            return x
        return float(_ksin(x, 0.0, 0))
    if not ax <= _MEDIUM:   # also inf and nan
        return _NAN
    n, y0, y1 = _rem_pio2(ax)
    q = n & 3
    if q == 0:
        s = _ksin(y0, y1, 1)
    elif q == 1:
        s = _kcos(y0, y1)
    elif q == 2:
        s = -_ksin(y0, y1, 1)
    else:
        s = -_kcos(y0, y1)
    return float(s if x > 0.0 else -s)


@jit(plain_from_python=True)
def cos(x: float) -> float:
    """cos(x) (s_cos.c)."""
    ax = abs(x)
    if ax < _PIO4_BOUND:
        if ax < _TWO_M27:
            return 1.0
        return float(_kcos(x, 0.0))
    if not ax <= _MEDIUM:
        return _NAN
    n, y0, y1 = _rem_pio2(ax)
    q = n & 3
    if q == 0:
        return float(_kcos(y0, y1))
    if q == 1:
        return float(-_ksin(y0, y1, 1))
    if q == 2:
        return float(-_kcos(y0, y1))
    return float(_ksin(y0, y1, 1))


@jit(plain_from_python=True)
def sincos(x: float) -> tuple[float, float]:
    """(sin(x), cos(x)), bit for bit those of sin and cos, with one reduction (LLVM makes one call
    of C's sin and cos of the same angle, so the C library's pair cost one reduction too)."""
    ax = abs(x)
    if ax < _PIO4_BOUND:
        if ax < _TWO_M27:
            return (x, 1.0)
        c = _kcos(x, 0.0)
        if ax < _TWO_M26:
            return (x, c)
        return (_ksin(x, 0.0, 0), c)
    if not ax <= _MEDIUM:
        return (_NAN, _NAN)
    n, y0, y1 = _rem_pio2(ax)
    q = n & 3
    ks = _ksin(y0, y1, 1)
    kc = _kcos(y0, y1)
    if q == 0:
        s, c = ks, kc
    elif q == 1:
        s, c = kc, -ks
    elif q == 2:
        s, c = -ks, -kc
    else:
        s, c = -kc, ks
    return (s if x > 0.0 else -s, c)


# --- exp and log: e_exp.c, e_log.c --------------------------------------------------------------
_O_THRESHOLD = _f(0x40862E42FEFA39EF)
_U_THRESHOLD = _f(0xC0874910D52D3051)
_LN2_HI = _f(0x3FE62E42FEE00000)
_LN2_LO = _f(0x3DEA39EF35793C76)
_INVLN2 = _f(0x3FF71547652B82FE)
_P1 = _f(0x3FC555555555553E)
_P2 = _f(0xBF66C16C16BEBD93)
_P3 = _f(0x3F11566AAF25DE2C)
_P4 = _f(0xBEBBBD41C5D26BF1)
_P5 = _f(0x3E66376972BEA4D0)
_HALF_LN2 = _f(0x3FD62E4300000000)    # fdlibm: high word > 0x3fd62e42
_THREE_HALF_LN2 = _f(0x3FF0A2B200000000)
_TWO_M28 = 2.0 ** -28
_LG1 = _f(0x3FE5555555555593)
_LG2 = _f(0x3FD999999997FA04)
_LG3 = _f(0x3FD2492494229359)
_LG4 = _f(0x3FCC71C51D8E78AF)
_LG5 = _f(0x3FC7466496CB03DE)
_LG6 = _f(0x3FC39A09D078C69F)
_LG7 = _f(0x3FC2F112DF3E5244)
_SQRT2_HALF = _f(0x3FE6A09E667F3BCD)
#: 2^k for k = -1021 ... 1023 (exp's k = 1024, near the overflow threshold, scales by 2 2^1023 as fdlibm does).
_POW2 = np.array([math.ldexp(1.0, k) for k in range(-1021, 1024)])


@jit(plain_from_python=True)
def exp(x: float) -> float:
    """e^x (e_exp.c; the scaling by 2^k by ldexp)."""
    if x != x:
        return x
    if x > _O_THRESHOLD:
        return _INF
    if x < _U_THRESHOLD:
        return 0.0
    ax = abs(x)
    k = 0
    hi = 0.0
    lo = 0.0
    if ax >= _HALF_LN2:
        if ax < _THREE_HALF_LN2:
            if x > 0.0:
                hi, lo, k = x - _LN2_HI, _LN2_LO, 1
            else:
                hi, lo, k = x + _LN2_HI, -_LN2_LO, -1
        else:
            k = int(_INVLN2 * x + (0.5 if x > 0.0 else -0.5))
            t = float(k)
            hi = x - t * _LN2_HI
            lo = t * _LN2_LO
        x = hi - lo
    elif ax < _TWO_M28:
        return 1.0 + x
    t = x * x
    c = x - t * (_P1 + t * (_P2 + t * (_P3 + t * (_P4 + t * _P5))))
    if k == 0:
        return 1.0 - ((x * c) / (c - 2.0) - x)
    y = 1.0 - ((lo - (x * c) / (2.0 - c)) - hi)
    if k == 1024:
        return float(y * 2.0 * _POW2[1023 + 1021])
    if k >= -1021:
        return float(y * _POW2[k + 1021])   # exact: 2^k from a table, not ldexp (a libm call)
    return math.ldexp(y, k)


@jit(plain_from_python=True)
def log(x: float) -> float:
    """Natural logarithm of x (e_log.c's kernel; x = (1 + f) 2^k, 1 + f in [sqrt(2)/2, sqrt(2)))."""
    if not x > 0.0:
        return _NAN if x != 0.0 else -_INF
    if x == _INF:
        return x
    m, k = math.frexp(x)
    if m < _SQRT2_HALF:
        m *= 2.0
        k -= 1
    f = m - 1.0
    s = f / (2.0 + f)
    dk = float(k)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    r = t2 + t1
    hfsq = 0.5 * f * f
    return dk * _LN2_HI - ((hfsq - (s * (hfsq + r) + dk * _LN2_LO)) - f)


@jit(plain_from_python=True)
def pow_positive(x: float, y: float) -> float:
    """x^y for x > 0 as e^(y ln x): a few ulp, for a step-size controller's factor, not for physics."""
    return float(exp(y * log(x)))


# --- atan and atan2: s_atan.c, e_atan2.c --------------------------------------------------------
_ATANHI0 = _f(0x3FDDAC670561BB4F)
_ATANHI1 = _f(0x3FE921FB54442D18)
_ATANHI2 = _f(0x3FEF730BD281F69B)
_ATANHI3 = _f(0x3FF921FB54442D18)
_ATANLO0 = _f(0x3C7A2B7F222F65E2)
_ATANLO1 = _f(0x3C81A62633145C07)
_ATANLO2 = _f(0x3C7007887AF0CBBD)
_ATANLO3 = _f(0x3C91A62633145C07)
_AT0 = _f(0x3FD555555555550D)
_AT1 = _f(0xBFC999999998EBC4)
_AT2 = _f(0x3FC24924920083FF)
_AT3 = _f(0xBFBC71C6FE231671)
_AT4 = _f(0x3FB745CDC54C206E)
_AT5 = _f(0xBFB3B0F2AF749A6D)
_AT6 = _f(0x3FB10D66A0D03D51)
_AT7 = _f(0xBFADDE2D52DEFD9A)
_AT8 = _f(0x3FA97B4B24760DEB)
_AT9 = _f(0xBFA2B4442C6A6C2F)
_AT10 = _f(0x3F90AD3AE322DA11)
_PI = _f(0x400921FB54442D18)
_PI_LO = _f(0x3CA1A62633145C07)
_PIO2_HI = _f(0x3FF921FB54442D18)
_PIO2_LO = _f(0x3C91A62633145C07)
_PIO4_HI = _f(0x3FE921FB54442D18)


@jit(plain_from_python=True)
def atan(x: float) -> float:
    """The arc tangent of x in [-pi/2, pi/2] (s_atan.c)."""
    if x != x:
        return x
    ax = abs(x)
    if ax >= 2.0 ** 66:
        return _ATANHI3 + _ATANLO3 if x > 0.0 else -_ATANHI3 - _ATANLO3
    ident = -1
    if ax < 0.4375:
        if ax < _TWO_M27:
            return x
        t = x
    elif ax < 1.1875:
        if ax < 0.6875:
            ident, t = 0, (2.0 * ax - 1.0) / (2.0 + ax)
        else:
            ident, t = 1, (ax - 1.0) / (ax + 1.0)
    elif ax < 2.4375:
        ident, t = 2, (ax - 1.5) / (1.0 + 1.5 * ax)
    else:
        ident, t = 3, -1.0 / ax
    z = t * t
    w = z * z
    s1 = z * (_AT0 + w * (_AT2 + w * (_AT4 + w * (_AT6 + w * (_AT8 + w * _AT10)))))
    s2 = w * (_AT1 + w * (_AT3 + w * (_AT5 + w * (_AT7 + w * _AT9))))
    if ident < 0:
        return t - t * (s1 + s2)
    if ident == 0:
        hi, lo = _ATANHI0, _ATANLO0
    elif ident == 1:
        hi, lo = _ATANHI1, _ATANLO1
    elif ident == 2:
        hi, lo = _ATANHI2, _ATANLO2
    else:
        hi, lo = _ATANHI3, _ATANLO3
    z = hi - ((t * (s1 + s2) - lo) - t)
    return z if x > 0.0 else -z


@jit(plain_from_python=True)
def atan2(y: float, x: float) -> float:
    """The angle of (x, y) in [-pi, pi] (e_atan2.c), signed zeros and infinities as C's atan2."""
    if x != x or y != y:
        return x + y
    if x == 1.0:
        return float(atan(y))
    m = (1 if math.copysign(1.0, y) < 0.0 else 0) + (2 if math.copysign(1.0, x) < 0.0 else 0)
    if y == 0.0:
        if m <= 1:
            return y
        return _PI if m == 2 else -_PI
    if x == 0.0:
        return -_PIO2_HI if y < 0.0 else _PIO2_HI
    if abs(x) == _INF:
        if abs(y) == _INF:
            quarter = _PIO4_HI if m < 2 else 3.0 * _PIO4_HI
            return quarter if m % 2 == 0 else -quarter
        if m == 0:
            return 0.0
        if m == 1:
            return -0.0
        return _PI if m == 2 else -_PI
    if abs(y) == _INF:
        return -_PIO2_HI if y < 0.0 else _PIO2_HI
    if abs(y) > abs(x) * 2.0 ** 60:   # fdlibm: exponents more than 60 apart
        z = _PIO2_HI + 0.5 * _PI_LO
        m &= 1
    elif x < 0.0 and abs(y) * 2.0 ** 60 < abs(x):
        z = 0.0
    else:
        z = atan(abs(y / x))
    if m == 0:
        return z
    if m == 1:
        return -z
    if m == 2:
        return _PI - (z - _PI_LO)
    return (z - _PI_LO) - _PI


# --- asin and acos: e_asin.c, e_acos.c ----------------------------------------------------------
_PS0 = _f(0x3FC5555555555555)
_PS1 = _f(0xBFD4D61203EB6F7D)
_PS2 = _f(0x3FC9C1550E884455)
_PS3 = _f(0xBFA48228B5688F3B)
_PS4 = _f(0x3F49EFE07501B288)
_PS5 = _f(0x3F023DE10DFDF709)
_QS1 = _f(0xC0033A271C8A2D4B)
_QS2 = _f(0x40002AE59C598AC8)
_QS3 = _f(0xBFE6066C1B8D0159)
_QS4 = _f(0x3FB3B8C5B12E9282)
_NEAR_ONE = _f(0x3FEF333300000000)   # fdlibm: high word >= 0x3fef3333 (|x| > 0.975)
_TWO_M57 = _f(0x3C60000100000000)    # fdlibm: high word <= 0x3c600000


@jit(plain_from_python=True)
def _r(t: float) -> float:
    """asin's rational approximation R(t) = p(t)/q(t) (e_asin.c)."""
    p = t * (_PS0 + t * (_PS1 + t * (_PS2 + t * (_PS3 + t * (_PS4 + t * _PS5)))))
    q = 1.0 + t * (_QS1 + t * (_QS2 + t * (_QS3 + t * _QS4)))
    return p / q


@jit(plain_from_python=True)
def _high(s: float) -> float:
    """s rounded to its leading 21 bits (Veltkamp's split by 2^32 + 1), so that its square is exact:
    fdlibm clears the low 32 bits of s (SET_LOW_WORD(s, 0)) for the same purpose."""
    c = s * 4294967297.0
    return c - (c - s)


@jit(plain_from_python=True)
def asin(x: float) -> float:
    """The arc sine of x in [-pi/2, pi/2] (e_asin.c)."""
    ax = abs(x)
    if ax >= 1.0:
        if ax == 1.0:
            return x * _PIO2_HI + x * _PIO2_LO
        return _NAN
    if ax < 0.5:
        if ax < _TWO_M26:
            return x
        return float(x + x * _r(x * x))
    t = (1.0 - ax) * 0.5
    s = math.sqrt(t)
    if ax >= _NEAR_ONE:
        t = _PIO2_HI - (2.0 * (s + s * _r(t)) - _PIO2_LO)
    else:
        w = _high(s)
        c = (t - w * w) / (s + w)
        p = 2.0 * s * _r(t) - (_PIO2_LO - 2.0 * c)
        q = _PIO4_HI - 2.0 * w
        t = _PIO4_HI - (p - q)
    return float(t if x > 0.0 else -t)


@jit(plain_from_python=True)
def acos(x: float) -> float:
    """The arc cosine of x in [0, pi] (e_acos.c)."""
    ax = abs(x)
    if ax >= 1.0:
        if ax == 1.0:
            return 0.0 if x > 0.0 else _PI + 2.0 * _PIO2_LO
        return _NAN
    if ax < 0.5:
        if ax < _TWO_M57:
            return _PIO2_HI + _PIO2_LO
        return float(_PIO2_HI - (x - (_PIO2_LO - x * _r(x * x))))
    if x < 0.0:
        z = (1.0 + x) * 0.5
        s = math.sqrt(z)
        w = _r(z) * s - _PIO2_LO
        return float(_PI - 2.0 * (s + w))
    z = (1.0 - x) * 0.5
    s = math.sqrt(z)
    df = _high(s)
    c = (z - df * df) / (s + df)
    return float(2.0 * (df + (_r(z) * s + c)))


@jit(plain_from_python=True)
def hypot(x: float, y: float) -> float:
    """sqrt(x^2 + y^2) (a correctly rounded square root: the same bits everywhere)."""
    return math.sqrt(x * x + y * y)


__all__ = ["acos", "asin", "atan", "atan2", "cos", "exp", "hypot", "log", "pow_positive", "sin", "sincos"]
