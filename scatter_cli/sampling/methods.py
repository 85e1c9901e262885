"""The stratified and Sobol methods: draws (face, barycentrics) for a run of points.

Each method maps point indices ``start .. stop - 1`` of a run of ``count`` points to
``(used, b)``: ``used`` (n,) int64 indices into the plan's used faces and ``b`` (n, 2)
float64 barycentric weights (b1, b2), which :meth:`SamplePlan.place` turns into points.
Every quantity is a pure function of the seed, the count and the point index, so any
chunking or thread count gives the same bytes.

- ``stratified``: systematic sampling over the area CDF: point j falls in the face
  holding (j + offset) / count of the total area, for one uniform offset per run, so a
  face receives floor or ceil of its expected count and the faces are visited in
  order. The m points of a face are spread by a jittered golden-ratio lattice in the
  unit square (u1 = (r + jitter) / m, u2 = frac(r g + shift) for the point's rank r
  in its face, a per-face uniform shift and g the golden ratio), then warped.
  Each point is uniform on its stratum x [0, 1), so the face's points are uniform
  on the triangle in expectation, and with the uniform offset every face gets
  exactly its expected share of points in expectation: the method is unbiased.
- ``sobol``: point j is the j-th point (in Gray-code order) of the 3-dimensional
  Sobol sequence, Owen-scrambled per dimension with a seeded hash (Burley 2020,
  "Practical Hash-based Owen Scrambling"); dimension 0 chooses the face through the
  area CDF, dimensions 1 and 2 go through the warp. At most 2^32 points per run.
"""

from __future__ import annotations

import numpy as np

from ..core.hashing import lane
from .warps import square_to_triangle

SOBOL_BITS = 32
SOBOL_MAX_COUNT = 1 << SOBOL_BITS
GOLDEN = 0.6180339887498949  # frac of the golden ratio
_ONE_BELOW = float(np.nextafter(1.0, 0.0))
_STRATIFIED_TAG = 0x5354_5241  # stream keys: independent of the random method's stream
_SOBOL_TAG = 0x534F_424C


def _stream(seed: int, tag: int, position: int, n: int):
    """Uniforms ``position .. position + n - 1`` (n,) of the (seed, tag) stream."""
    bits = np.random.PCG64DXSM(np.random.SeedSequence([tag, seed]))
    bits.advance(position)
    return np.random.Generator(bits).random(n)


# ---------------------------------------------------------------------------
# Stratified


def _stratified_offset(seed: int) -> float:
    return float(_stream(seed, _STRATIFIED_TAG, 0, 1)[0])


def _strata(plan, count: int, offset: float, j):
    """Face of each systematic point j (n,) int64: select((j + offset) / count)."""
    u = (j.astype(np.float64) + offset) / count
    return plan.select(np.minimum(u, _ONE_BELOW))


def _first_index(plan, count, offset, face, lo, hi):
    """Smallest j in [lo, hi] whose face is >= ``face`` (hi when none before it)."""
    while lo < hi:
        mid = (lo + hi) // 2
        if _strata(plan, count, offset, np.array([mid]))[0] >= face:
            hi = mid
        else:
            lo = mid + 1
    return lo


def stratified_draws(plan, count: int, start: int, stop: int, seed: int, warp=square_to_triangle):
    """Points ``start .. stop - 1`` of a stratified run of ``count``: (used (n,), b (n, 2))."""
    offset = _stratified_offset(seed)
    j = np.arange(start, stop, dtype=np.int64)
    used = _strata(plan, count, offset, j)
    if not len(j):
        return used, np.empty((0, 2))
    # Runs of equal faces; the first and last may extend beyond this chunk.
    new = np.empty(len(j), dtype=bool)
    new[0] = True
    np.not_equal(used[1:], used[:-1], out=new[1:])
    run_start = j[new]
    run_start[0] = _first_index(plan, count, offset, used[0], 0, start)
    run_end = np.empty_like(run_start)
    run_end[:-1] = run_start[1:]
    run_end[-1] = _first_index(plan, count, offset, used[-1] + 1, stop, count)
    run = np.cumsum(new) - 1
    rank = j - run_start[run]
    m = (run_end - run_start)[run]
    jitter = _stream(seed, _STRATIFIED_TAG + 1, start, len(j))
    lo = int(used[0])
    shift = _stream(seed, _STRATIFIED_TAG + 2, lo, int(used[-1]) - lo + 1)[used - lo]
    u = np.empty((len(j), 2))
    np.add(rank, jitter, out=u[:, 0])
    u[:, 0] /= m
    np.minimum(u[:, 0], _ONE_BELOW, out=u[:, 0])
    r = rank.astype(np.float64)
    r *= GOLDEN
    r += shift
    np.subtract(r, np.floor(r), out=u[:, 1])
    return used, warp(u)


# ---------------------------------------------------------------------------
# Sobol


def _direction_numbers(s: int, a: int, m_init, bits=SOBOL_BITS):
    """Direction numbers (bits,) uint32 v_k = m_k 2^(bits - k) of one Sobol dimension.

    s: degree of the primitive polynomial, a: its inner coefficients a_1 .. a_{s-1}
    as a binary number (a_1 the highest bit), m_init: the s initial odd m_k.
    m_k = 2 a_1 m_{k-1} ^ 4 a_2 m_{k-2} ^ ... ^ 2^s m_{k-s} ^ m_{k-s}.
    """
    m = list(m_init)
    for k in range(s, bits):
        new = m[k - s] ^ (m[k - s] << s)
        for i in range(1, s):
            if (a >> (s - 1 - i)) & 1:
                new ^= m[k - i] << i
        m.append(new)
    return np.array([m[k] << (bits - 1 - k) for k in range(bits)], dtype=np.uint32)


# Dimension 1 is van der Corput (all m_k = 1); dimensions 2 and 3 are those of Joe and
# Kuo's table (new-joe-kuo-6.21201): x + 1 with m = 1, and x^2 + x + 1 with m = 1, 3.
SOBOL_DIRECTIONS = np.stack([
    (np.ones(SOBOL_BITS, dtype=np.uint32) << np.arange(SOBOL_BITS - 1, -1, -1, dtype=np.uint32)),
    _direction_numbers(1, 0, [1]),
    _direction_numbers(2, 1, [1, 3]),
])
"""(3, 32) uint32: column k holds the direction numbers of bit k of the Gray code."""


def _trailing_zeros(i):
    """Index of the lowest set bit of each positive int64 in ``i`` (n,)."""
    low = (i & -i).astype(np.float64)  # a power of two: exact in float64
    return (np.frexp(low)[1] - 1).astype(np.intp)


def sobol_integers(start: int, stop: int):
    """Unscrambled Sobol points ``start .. stop - 1`` in Gray-code order: (n, 3) uint32.

    Point j is the XOR of the direction numbers of the set bits of gray(j) = j ^ (j >> 1);
    consecutive points differ by one direction number, so a run is one XOR scan.
    """
    if not 0 <= start <= stop <= SOBOL_MAX_COUNT:
        raise ValueError(f"Sobol points are indexed 0 .. 2^{SOBOL_BITS} - 1")
    n = stop - start
    out = np.empty((n, 3), dtype=np.uint32)
    if not n:
        return out
    gray = start ^ (start >> 1)
    first = np.zeros(3, dtype=np.uint32)
    for k in range(SOBOL_BITS):
        if (gray >> k) & 1:
            first ^= SOBOL_DIRECTIONS[:, k]
    idx = np.arange(start + 1, stop, dtype=np.int64)
    step = SOBOL_DIRECTIONS[:, _trailing_zeros(idx)]  # (3, n - 1)
    for d in range(3):
        col = np.empty(n, dtype=np.uint32)
        col[0] = first[d]
        col[1:] = step[d]
        np.bitwise_xor.accumulate(col, out=col)
        out[:, d] = col
    return out


def _reverse_bits(x):
    """Bit reversal of uint32 (n,)."""
    x = ((x >> 1) & 0x55555555) | ((x & 0x55555555) << 1)
    x = ((x >> 2) & 0x33333333) | ((x & 0x33333333) << 2)
    x = ((x >> 4) & 0x0F0F0F0F) | ((x & 0x0F0F0F0F) << 4)
    x = ((x >> 8) & 0x00FF00FF) | ((x & 0x00FF00FF) << 8)
    return (x >> 16) | (x << 16)


def owen_scramble(x, seed):
    """Nested uniform (Owen) scrambling of uint32 (n,) by a seeded hash.

    Reversed, each bit of x is flipped by a hash of the bits below it (the digits above
    it in x): adding the seed, then x ^= x * even constant, which only spreads bits
    upward. Reversed back, every digit's flip depends on the seed and the leading
    digits only: a nested permutation, so nets stay nets and each point is uniform.
    """
    x = _reverse_bits(x)
    x = x + np.uint32(seed)
    for c in (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6):
        x ^= x * np.uint32(c)
    return _reverse_bits(x)


def sobol_uniforms(start: int, stop: int, seed: int):
    """Scrambled Sobol points ``start .. stop - 1`` for ``seed``: (n, 3) float64 in [0, 1).

    The 32 scrambled bits of each coordinate are completed by 21 hashed bits of
    (seed, index, dimension), so no coordinate is confined to a 2^-32 grid.
    """
    keys = np.random.SeedSequence([_SOBOL_TAG, seed]).generate_state(4, dtype=np.uint64)
    x = sobol_integers(start, stop)
    low = lane(keys[3], np.arange(start, stop, dtype=np.uint64))
    u = np.empty(x.shape)
    for d in range(3):
        hi = owen_scramble(x[:, d], int(keys[d] & 0xFFFFFFFF)).astype(np.float64)
        lo = ((low >> np.uint64(21 * d)) & np.uint64((1 << 21) - 1)).astype(np.float64)
        u[:, d] = (hi * 2.0**21 + lo) * 2.0**-53
    return u


def sobol_draws(plan, count: int, start: int, stop: int, seed: int, warp=square_to_triangle):
    """Points ``start .. stop - 1`` of a Sobol run: (used (n,), b (n, 2))."""
    u = sobol_uniforms(start, stop, seed)
    return plan.select(u[:, 0]), warp(u[:, 1:3])


def random_draws(plan, count: int, start: int, stop: int, seed: int, warp=square_to_triangle):
    """Points ``start .. stop - 1`` of the random method: (used (n,), b (n, 2))."""
    from .plan import uniforms

    u = uniforms(seed, start, stop)
    return plan.select(u[:, 0]), warp(u[:, 1:3])


DRAWS = {"random": random_draws, "stratified": stratified_draws, "sobol": sobol_draws}
"""method name -> draws(plan, count, start, stop, seed, warp) -> (used, b)."""
