"""Elementary functions that round the same on every machine: log, sin, cos, atan2, asin.

NumPy's own ``log1p``, ``arcsin``, ``arctan2`` (and ``log``, ``exp``, ``power``, ...) pick
their code by the CPU they run on: on a CPU with AVX-512, float64 results differ from
those of an AVX2 one in the last bits, and so would scatter's output bytes. These are
built from + - * /, ``sqrt`` and exact steps (``frexp``, ``rint``, comparisons) alone,
each rounded as IEEE 754 says on every CPU, so their results are the same bytes
everywhere (tests/test_elementary.py runs them under NumPy's baseline and its full
dispatch). Each is within 2 ulp of the true value. Arrays in, float64 arrays out, shapes
kept.
"""

from __future__ import annotations

import numpy as np

# The constants below are written out (tests/test_elementary.py derives each again from
# pi/2 and ln 2 to 60 digits, and from the series' exact terms), so that importing this
# module costs no arithmetic on fractions at start-up.
# pi / 2 as three parts, the first two of 33 significant bits: k * part is exact for |k| < 2**20
PIO2_1 = 1.5707963267341256
PIO2_2 = 6.077100506303966e-11
PIO2_3 = 2.0222662487959506e-21
TWO_OVER_PI = 0.6366197723675814
# ln 2 as two parts, the first of 40 significant bits: e * LN2_HI is exact for every exponent
LN2_HI = 0.6931471805601177
LN2_LO = -1.7239444525614835e-13
SQRT_HALF = 0.7071067811865476
# Taylor terms on [-pi/4, pi/4], highest first: sin r = r + r^3 S(r^2) with S's terms
# (-1)^k / (2k + 1)!, k = 8..1; cos r = 1 - r^2/2 + r^4 C(r^2) with C's (-1)^k / (2k)!, k = 9..2
SIN_TERMS = (2.8114572543455206e-15, -7.647163731819816e-13, 1.6059043836821613e-10, -2.505210838544172e-08,
             2.7557319223985893e-06, -0.0001984126984126984, 0.008333333333333333, -0.16666666666666666)
COS_TERMS = (-1.5619206968586225e-16, 4.779477332387385e-14, -1.1470745597729725e-11, 2.08767569878681e-09,
             -2.755731922398589e-07, 2.48015873015873e-05, -0.001388888888888889, 0.041666666666666664)
# log(1 + f) = 2 atanh(s), s = f / (2 + f): the terms 2 / (2k + 1) of z = s^2, k = 11..1
LOG_TERMS = (0.08695652173913043, 0.09523809523809523, 0.10526315789473684, 0.11764705882352941,
             0.13333333333333333, 0.15384615384615385, 0.18181818181818182, 0.2222222222222222,
             0.2857142857142857, 0.4, 0.6666666666666666)

# Cephes' rational approximation of atan on [0, 0.66]
PIO2 = 1.5707963267948966
PIO4 = 0.7853981633974483
PI = 3.141592653589793
MOREBITS = 6.123233995736765886130e-17  # pi/2 - PIO2
TAN3PIO8 = 2.41421356237309504880
P = (-8.750608600031904122785e-01, -1.615753718733365076637e+01, -7.500855792314704667340e+01,
     -1.228866684490136173410e+02, -6.485021904942025371773e+01)
Q = (2.485846490142306297962e+01, 1.650270098316988542046e+02, 4.328810604912902668951e+02,
     4.853903996359136964868e+02, 1.945506571482613964425e+02)


def _horner(terms, z):
    out = np.full_like(z, terms[0])
    for c in terms[1:]:
        out = out * z + c
    return out


def log(x):
    """Natural logarithm of ``x`` (float64 array; 0 gives -inf, inf inf, below 0 NaN)."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(x > 0, _log_positive(np.where(x > 0, x, 1.0)), np.where(x == 0, -np.inf, np.nan))


def _log_positive(x):
    """log of ``x`` (float64 array, 0 < x <= inf)."""
    m, e = np.frexp(x)  # x = m 2^e, m in [0.5, 1)
    low = m < SQRT_HALF
    m = np.where(low, 2.0 * m, m)  # now in [sqrt(1/2), sqrt(2))
    e = (e - low).astype(np.float64)
    f = m - 1.0  # exact
    s = f / (2.0 + f)
    z = s * s
    half = 0.5 * f * f
    log1 = f - (half - s * (half + z * _horner(LOG_TERMS, z)))
    return np.where(x == np.inf, np.inf, e * LN2_HI + (log1 + e * LN2_LO))


def _reduced(x):
    """(r, k): x = k pi/2 + r, |r| <= pi/4 (about), for |x| < 2**20 pi/2."""
    k = np.rint(x * TWO_OVER_PI)
    with np.errstate(invalid="ignore"):  # (NaN and inf: r is NaN, the quadrant any)
        return ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3, k.astype(np.int64) & 3


def sincos(x):
    """(sin x, cos x) of ``x`` (float64 array, |x| < 2**20 pi/2 = 1.6e6)."""
    r, k = _reduced(np.asarray(x, dtype=np.float64))
    z = r * r
    s = r + r * z * _horner(SIN_TERMS, z)
    c = 1.0 - (0.5 * z - z * z * _horner(COS_TERMS, z))
    sin = np.choose(k, [s, c, -s, -c])
    cos = np.choose(k, [c, -s, -c, s])
    return sin, cos


def sin(x):
    """Sine of ``x`` (float64 array, |x| < 1.6e6)."""
    return sincos(x)[0]


def cos(x):
    """Cosine of ``x`` (float64 array, |x| < 1.6e6)."""
    return sincos(x)[1]


def atan2(y, x):
    """Elementwise arctangent of y / x in [-pi, pi] (y, x float64 arrays), from + - * /
    only (Cephes' atan), as the winding kernel computes it: within 2 ulp of np.arctan2."""
    ay, ax = np.abs(y), np.abs(x)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(ax == 0, np.inf, ay / ax)  # (NaN stays NaN)
        small, large = t <= 0.66, t > TAN3PIO8
        arg = np.where(small, t, np.where(large, 1.0 / t, (t - 1.0) / (t + 1.0)))
        z = arg * arg
        z = z * ((((P[0] * z + P[1]) * z + P[2]) * z + P[3]) * z + P[4]) / (
            ((((z + Q[0]) * z + Q[1]) * z + Q[2]) * z + Q[3]) * z + Q[4])
        z = arg * z + arg
        a = np.where(small, z, np.where(large, PIO2 - z + MOREBITS, PIO4 + z + 0.5 * MOREBITS))
    a = np.where(ay == 0, 0.0, a)
    a = np.where(x < 0, PI - a, a)
    return np.where(y < 0, -a, a)


def asin(x):
    """Arcsine of ``x`` (float64 array in [-1, 1]), in [-pi/2, pi/2]."""
    x = np.asarray(x, dtype=np.float64)
    return atan2(x, np.sqrt((1.0 - x) * (1.0 + x)))
