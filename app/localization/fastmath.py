"""Small compiled (numba) building blocks shared by the per-particle kernels.

Without Intel's SVML, numba calls the C library for every ``sin``, ``cos`` and for
numpy's Gaussian sampler, one particle at a time; at 10,000 particles those calls
cost more than the whole sensor model. The two helpers here are branch-free
polynomial and table forms that the compiler vectorizes:

* :func:`sincos`: sine and cosine of any angle within ``SINCOS_MAX_ERROR`` (Cody-Waite
  reduction to [-pi/4, pi/4], Taylor polynomials of degree 9 and 10 there).
* :func:`fill_normal`: standard-normal noise from raw 32-bit random words through a
  tabulated inverse CDF (``NORMAL_KNOTS`` intervals, linear interpolation). The tails
  are cut at ``NORMAL_TAIL_SIGMA`` standard deviations and the table is rescaled so
  the variance is exactly one; for motion noise nothing beyond that matters.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np
from numba import njit
from numpy.typing import NDArray

from app.maps.geometry import grid_cell as _grid_cell_arithmetic

#: Compiler liberties every kernel takes: no signed zeros, reciprocals, fused
#: multiply-add, fast approximate functions and reassociation (which vectorizes
#: reductions). Never ``nnan``/``ninf``: -inf marks an impossible particle.
FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}

_HALF_PI_HI = 1.5707963267341256  # pi/2 split in two for an exact reduction
_HALF_PI_LO = 6.077100506506192e-11
_TWO_OVER_PI = 0.6366197723675814

#: Absolute error bound of :func:`sincos` for |t| < 1e6: the first term the sine's
#: polynomial leaves out, (pi/4)^11 / 11! = 1.76e-9 (the cosine's, (pi/4)^12 / 12!, is
#: smaller), plus float64 rounding of the polynomial and the reduction (< 1e-13).
SINCOS_MAX_ERROR = (math.pi / 4) ** 11 / math.factorial(11) + 1e-13


@njit(cache=True, inline="always", fastmath=FAST)
def sincos(t: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """(sin t, cos t), absolute error below ``SINCOS_MAX_ERROR`` for |t| < 1e6, branch-free."""
    k = np.floor(t * _TWO_OVER_PI + 0.5)
    r = (t - k * _HALF_PI_HI) - k * _HALF_PI_LO
    r2 = r * r
    s = r * (1.0 + r2 * (-1 / 6 + r2 * (1 / 120 + r2 * (-1 / 5040 + r2 * (1 / 362880)))))
    c = 1.0 + r2 * (-0.5 + r2 * (1 / 24 + r2 * (-1 / 720 + r2 * (1 / 40320 + r2 * (-1 / 3628800)))))
    q = k - 4.0 * np.floor(k * 0.25)  # quadrant 0..3
    odd = q == 1.0 or q == 3.0
    sin_t = c if odd else s
    cos_t = s if odd else c
    sin_t = -sin_t if q >= 2.0 else sin_t
    cos_t = -cos_t if (q == 1.0 or q == 2.0) else cos_t
    return sin_t, cos_t


#: The compiled form of :func:`app.maps.geometry.grid_cell` (the same function, so
#: kernels and numpy callers agree on every cell). Branch-free: loops calling it vectorize.
grid_cell = njit(cache=True, inline="always", error_model="numpy")(_grid_cell_arithmetic)


#: Intervals of the tabulated inverse normal CDF (a power of two).
NORMAL_KNOTS = 4096
#: Where the tabulated normal ends, in standard deviations.
NORMAL_TAIL_SIGMA = 4.0


def _normal_table() -> NDArray[np.float32]:
    """Inverse-CDF knots at u = i / NORMAL_KNOTS, ends clipped, unit variance."""
    u = np.arange(NORMAL_KNOTS + 1) / NORMAL_KNOTS
    inner = NormalDist()
    table = np.empty(NORMAL_KNOTS + 1)
    table[1:-1] = [inner.inv_cdf(float(p)) for p in u[1:-1]]
    table[0], table[-1] = -NORMAL_TAIL_SIGMA, NORMAL_TAIL_SIGMA
    # Variance of the piecewise-linear variable: exact per interval for X = a + (b-a)U.
    a, b = table[:-1], table[1:]
    variance = np.mean((a * a + a * b + b * b) / 3.0)
    return (table / np.sqrt(variance)).astype(np.float32)


NORMAL_TABLE = _normal_table()
_FRACTION_BITS = 32 - int(np.log2(NORMAL_KNOTS))


@njit(cache=True, nogil=True, fastmath=FAST)
def _fill_normal(words, table, shift, out):  # fmt: skip  # pragma: no cover - compiled
    inv = np.float32(1.0 / (1 << shift))
    mask = np.uint32((1 << shift) - 1)
    sh = np.uint32(shift)
    for i in range(out.shape[0]):
        w = words[i]
        j = np.int64(w >> sh)
        f = np.float32(w & mask) * inv
        out[i] = table[j] + f * (table[j + 1] - table[j])


def fill_normal(rng: np.random.Generator, n: int) -> NDArray[np.float32]:
    """``n`` standard-normal draws (float32) from ``rng``'s bit stream."""
    words = rng.bit_generator.random_raw((n + 1) // 2).view(np.uint32)[:n]
    out = np.empty(n, dtype=np.float32)
    _fill_normal(words, NORMAL_TABLE, _FRACTION_BITS, out)
    return out


#: Beyond this |z| the softplus correction log(1 + e^-|z|) is below 2.1e-9: dropped.
SOFTPLUS_SPAN = 20.0
#: Absolute error bound of :func:`softplus`: the dropped correction log1p(e^-SPAN)
#: (2.06e-9), plus the atanh series cut after s^14 with s <= 1/3 (the rest is below
#: 2 s^17 / 17 / (1 - s^2) = 1.03e-9), plus float64 rounding (< 1e-12). The e^x polynomial's cut,
#: x^11 / 11! relative with |x| <= SPAN / 32 (32 times that after five squarings), is
#: below 1e-15 absolute once multiplied by e^-t itself.
SOFTPLUS_MAX_ERROR = (
    math.log1p(math.exp(-SOFTPLUS_SPAN)) + 2 * (1 / 3) ** 17 / 17 / (1 - 1 / 9) + 1e-12
)
#: Taylor coefficients of e^x, highest degree first (Horner): 1/10!, ..., 1/1!, 1.
_EXP_TAYLOR = tuple(1.0 / math.factorial(k) for k in range(10, -1, -1))
#: atanh series: log1p(u) = 2 s (1 + s^2/3 + ... + s^14/15), s = u / (2 + u).
_ATANH_SERIES = tuple(1.0 / k for k in range(15, 0, -2))


@njit(cache=True, inline="always", fastmath=FAST, error_model="numpy")
def softplus(z: float) -> float:  # pragma: no cover - compiled
    """log(1 + e^z), absolute error below ``SOFTPLUS_MAX_ERROR`` (3.1e-9), branch-free.

    softplus(z) = max(z, 0) + log1p(e^-|z|). e^-t for t <= SOFTPLUS_SPAN is the Taylor
    polynomial of e^(-t/32) squared five times; log1p(u) = 2 atanh(u / (2 + u)), an
    odd series in s = u / (2 + u) <= 1/3.
    """
    x = -min(abs(z), SOFTPLUS_SPAN) * (1.0 / 32.0)
    e = 0.0
    for c in _EXP_TAYLOR:
        e = e * x + c
    for _ in range(5):
        e = e * e
    s = e / (2.0 + e)
    s2 = s * s
    series = 0.0
    for c in _ATANH_SERIES:
        series = series * s2 + c
    return max(z, 0.0) + 2.0 * s * series


@njit("float64(float64, float64)", cache=True, nogil=True, error_model="numpy")
def hypot(x: float, y: float) -> float:  # pragma: no cover - compiled
    """``np.hypot`` of two numbers, the same bits (both call the C library's ``hypot``;
    ``math.hypot`` is Python's own and differs in the last bit now and then), at a third
    of numpy's cost on a scalar pair (0.2 against 0.65 us): the filter takes the length
    of a move or a step several times a frame. Compiled for float64 only (an integer
    argument is converted), so no call waits for a compiler."""
    return np.hypot(x, y)


#: Up to this many values numpy's ``add.reduce`` sums in one block (its pairwise
#: summation's ``PW_BLOCKSIZE``): :func:`pairwise_sum` follows it that far.
PAIRWISE_BLOCK = 128


@njit(cache=True, nogil=True, inline="always")
def pairwise_sum(v, n):  # fmt: skip  # pragma: no cover - compiled
    """``np.add.reduce(v[:n])`` to the last bit for ``n <= PAIRWISE_BLOCK`` (no fastmath:
    numpy's order of additions): numpy's pairwise summation, which adds fewer than 8
    values in turn from 0.0, and more in eight running sums (a stride of 8) joined
    pairwise, then the rest in turn. Callers with more values use numpy."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += v[i]
        return res
    r0, r1, r2, r3 = v[0], v[1], v[2], v[3]
    r4, r5, r6, r7 = v[4], v[5], v[6], v[7]
    i = 8
    end = n - n % 8
    while i < end:
        r0 += v[i]
        r1 += v[i + 1]
        r2 += v[i + 2]
        r3 += v[i + 3]
        r4 += v[i + 4]
        r5 += v[i + 5]
        r6 += v[i + 6]
        r7 += v[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += v[i]
        i += 1
    return res
