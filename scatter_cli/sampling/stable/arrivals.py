"""The arrival-time streams of ``--stable``: each used face is a Poisson process in time
with its rate, drawn from its own counter-based stream.

A face's time axis is cut into blocks of length ``BLOCK_MEAN / rate`` (the face's own
scale, so a block holds BLOCK_MEAN arrivals on average whatever the mesh's units). Block
``b`` of the face with key ``k`` has state ``s = mix(k + (b + 1) G)``; lane ``l`` of
the block is ``mix(s + l G)``: lane 0 gives the block's Poisson count ``c``, arrival
``j < c`` uses lanes ``1 + 4 j .. 4 + 4 j`` (its time within the block, then the in-face
warp's inputs). ``mix`` is SplitMix64's finaliser and ``G`` its golden-ratio increment
(:mod:`scatter_cli.core.hashing`). An arrival is held as one word, ``id = used face << bits |
counter`` with ``counter = block << COUNT_BITS | j``.
"""

from __future__ import annotations


import numpy as np

from ...core import native
from ...errors import ScatterError
from ...core.hashing import lane, to_unit

# Expected arrivals per block. The work is about F + N / m block counts plus N + F m / 2
# arrival times: 2 balances the 1.31M-face icosphere at 10^6 points against the skull
# (0.1M faces) at 10^7.
BLOCK_MEAN = 2.0
COUNT_BITS = 5  # a block's arrival number j fits in 5 bits: counts are capped at 31
LANES = 4  # per arrival: time, then up to three warp inputs
ARRIVAL_BLOCK = 1 << 20  # time blocks expanded at a time
THREAD_FACES = 1 << 17  # fewer used faces: the NumPy path's arrivals on one thread
RAY_LANE = 1 << 32  # lanes RAY_LANE + 4 j + k of a block: arrival j's ray rotation (--exterior)


def _poisson_cdf():
    """(31,) float64 P(count <= k) for a Poisson(BLOCK_MEAN) count, k = 0 .. 30.

    Built from a literal e^-2 by plain multiplications and additions, so the table is
    the same on every machine.
    """
    p = 0.1353352832366127  # exp(-2.0)
    cdf = []
    total = 0.0
    for k in range((1 << COUNT_BITS) - 1):
        if k:
            p = p * BLOCK_MEAN / k
        total += p
        cdf.append(total)
    return np.array(cdf)


POISSON_CDF = _poisson_cdf()


def _blocks_before(tau, length):
    """(n,) int64 blocks of lengths ``length`` (n,) that cover time [0, tau): every
    arrival of a later block has time >= tau, in floating point too."""
    with np.errstate(over="ignore", invalid="ignore"):
        nb = np.floor(tau / length) + 1
    nb = nb.astype(np.int64)
    nb += nb * length < tau
    return nb


def _expand(counts):
    """(owner (total,), rank (total,)) int64: entry ``t`` of run ``owner`` counts 0.."""
    owner = np.repeat(np.arange(len(counts)), counts)
    starts = np.cumsum(counts) - counts
    return owner, np.arange(len(owner)) - starts[owner]


def arrivals(table, tau, first=0, last=None):
    """Arrivals before ``tau`` of used faces ``first .. last - 1``.

    Returns (time (m,) float64, used face (m,) int64, counter (m,) uint64 = block << 5 | j).
    """
    last = len(table) if last is None else last
    rate = table.rate[first:last]
    length = BLOCK_MEAN / rate
    nb = _blocks_before(tau, length)
    cum = np.cumsum(nb)
    out = []
    total = int(cum[-1]) if len(cum) else 0
    for lo in range(0, total, ARRIVAL_BLOCK):
        hi = min(lo + ARRIVAL_BLOCK, total)
        f0 = int(np.searchsorted(cum, lo, side="right"))
        f1 = int(np.searchsorted(cum, hi - 1, side="right")) + 1
        counts = nb[f0:f1].copy()
        skip = lo - (int(cum[f0]) - int(nb[f0]))
        counts[0] -= skip
        counts[-1] -= int(cum[f1 - 1]) - hi
        owner, b = _expand(counts)
        b[: counts[0]] += skip
        face = owner + f0
        state = lane(table.key[first + face], (b + 1).astype(np.uint64))
        c = np.searchsorted(POISSON_CDF, to_unit(lane(state, 0)), side="right")
        blk, j = _expand(c)
        u = to_unit(lane(state[blk], (1 + LANES * j).astype(np.uint64)))
        t = (b[blk] + u) * length[face[blk]]
        keep = np.flatnonzero(t < tau)
        ctr = (b[blk[keep]].astype(np.uint64) << np.uint64(COUNT_BITS)) | j[keep].astype(np.uint64)
        out.append((t[keep], face[blk[keep]] + first, ctr))
    if not out:
        return np.empty(0), np.empty(0, np.int64), np.empty(0, np.uint64)
    return tuple(np.concatenate(x) for x in zip(*out))


def all_arrivals(table, tau):
    """:func:`arrivals` of every used face, in face ranges on the worker threads (the
    NumPy path)."""
    n = len(table)
    threads = native.worker_count()
    pieces = 1 if threads == 1 or n < THREAD_FACES else native.PIECES_PER_THREAD * threads
    cuts = np.linspace(0, n, pieces + 1).astype(np.int64).tolist()
    with native.thread_pool(threads) as pool:
        parts = list(pool.map(lambda a, b: arrivals(table, tau, a, b), cuts[:-1], cuts[1:]))
    return tuple(np.concatenate(x) for x in zip(*parts)) if len(parts) > 1 else parts[0]


def counter_bits(table, tau):
    """Bits of the counter (block << COUNT_BITS | j) in an arrival id ``used face << bits |
    counter``, for the arrivals before ``tau``: room for the most blocks any face has."""
    expected = tau * table.total
    if not expected < 2.0**40:  # about 2^40 arrivals: past any memory
        raise ScatterError(f"{table.surface.source}: --stable would keep {expected:.3g} arrivals: too many")
    most = int(_blocks_before(tau, BLOCK_MEAN / np.max(table.rate)))
    bits = COUNT_BITS + (2 * most + 1).bit_length()
    if bits + max(1, (len(table) - 1).bit_length()) > 63:
        raise ScatterError(f"{table.surface.source}: too many points for --stable on {len(table):,} faces")
    return bits


def pack(used, ctr, bits):
    """(n,) uint64 arrival ids ``used << bits | ctr``."""
    return (used.astype(np.uint64) << np.uint64(bits)) | ctr


def unpack(ids, bits):
    """(used face (n,) int64, counter (n,) uint64) of arrival ids."""
    return (ids >> np.uint64(bits)).astype(np.int64), ids & np.uint64((1 << bits) - 1)
