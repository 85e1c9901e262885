"""The arrivals of ``--stable`` in arrival order: sorted by (time, face key, counter), a
total order that depends on no index, by the kernel's two-level counting sort on the
worker threads or by one NumPy value sort; a run keeps the N earliest, or every one
before a time.
"""

from __future__ import annotations

import numpy as np

from ...core import native
from .arrivals import BLOCK_MEAN, POISSON_CDF

_kernel = native.kernel("_cstable")
ROOM_SDS = 6.0  # a face range's share of a time bucket holds its mean count plus this many standard deviations
PIECES = 2  # face ranges a worker thread (more would cost room: each range has room of its own in every bucket)
FINE_BITS = 12  # a coarse bucket of the kernel's arrival sort holds 2^12 to 2^15 time keys


def kernel_arrivals(table, tau, bits):
    """The kernel's arrivals before ``tau`` of every used face, in arrival order: (time (m,)
    float64, id (m,) uint64, duplicates), sorted by (time, face key, counter) as
    :func:`arrival_order` sorts them; duplicates as :func:`has_duplicates`.

    A counting sort on the time key ``floor(t * K / tau)`` (K a power of two, about the
    expected count), in two levels on the worker threads. Face ranges write their arrivals
    straight into coarse buckets of the key, range by range within each bucket (each with
    room for its mean count plus ROOM_SDS standard deviations; in the rare case that one
    holds more, the pass runs again with room for the counts it returned). Then each
    coarse bucket, small enough for the cache, is sorted on the rest of its key and exactly
    within equal keys, and written back from the start of the same arrays.
    """
    n = len(table)
    threads = native.worker_count()
    expected = tau * table.total
    pieces = 1 if threads == 1 or n + expected < 1 << 16 or n < 4 * threads else PIECES * threads
    cuts = _balanced_cuts(table.rate, tau, pieces)
    key_bits = max(1, int(expected).bit_length())  # about 1 to 2 arrivals a key
    fine_bits = min(key_bits, max(FINE_BITS, key_bits - 8), FINE_BITS + 3)
    coarse = 1 << (key_bits - fine_bits)
    total = coarse << fine_bits
    scale = total / float(tau)
    mean = np.array([tau * float(np.sum(table.rate[a:b])) / coarse for a, b in zip(cuts[:-1], cuts[1:])])
    room = np.tile(np.maximum(0, mean + ROOM_SDS * np.sqrt(mean) + 16).astype(np.int64), (coarse, 1))
    args = (table.key, table.rate, float(tau), BLOCK_MEAN, POISSON_CDF)
    with native.thread_pool(threads) as pool:
        for _ in range(2):
            start = (np.cumsum(room) - room.ravel()).reshape(coarse, pieces)
            size = int(room.sum())
            t, ids = np.empty(size), np.empty(size, np.uint64)
            nexts = [start[:, k].copy() for k in range(pieces)]  # advanced by the kernel
            ends = [np.ascontiguousarray(start[:, k] + room[:, k]) for k in range(pieces)]
            list(pool.map(lambda k: _kernel.arrivals(*args, cuts[k], cuts[k + 1], bits, scale, fine_bits, total,
                                                     nexts[k], ends[k], t, ids), range(pieces)))
            counts = np.stack(nexts, axis=1) - start
            if (counts <= room).all():
                return _kernel_order(pool, t, ids, start.ravel(), counts.ravel(), (pieces, scale, fine_bits, total),
                                     table.key, bits)
            room = counts
    raise AssertionError("arrivals: the counts changed between two passes")


def _balanced_cuts(rate, tau, pieces):
    """[pieces + 1] face indices cutting ``rate`` (F,) into ranges of about equal work (a
    face plus its arrivals before ``tau``)."""
    if pieces == 1:
        return [0, len(rate)]
    work = np.cumsum(rate * tau + 1.0)
    return [0] + np.searchsorted(work, work[-1] * np.arange(1, pieces) / pieces).tolist() + [len(rate)]


def _kernel_order(pool, t, ids, start, counts, buckets, key, bits):
    """Sort the bucketed arrivals (segments ``start``, ``counts`` (C P,), see
    :func:`kernel_arrivals`) in place, in bucket ranges of about equal counts, many a
    thread: (time (m,), id (m,), duplicates). A range writes the positions below its first
    segment to side arrays (a range below may still read them), copied in afterwards."""
    parts, coarse = buckets[0], len(start) // buckets[0]
    bounds = np.zeros(coarse + 1, np.int64)
    np.cumsum(counts.reshape(coarse, parts).sum(axis=1), out=bounds[1:])
    m = int(bounds[-1])
    sorters = native.PIECES_PER_THREAD * native.worker_count() if m >= 1 << 16 else 1
    qcuts = np.searchsorted(bounds, np.linspace(0, m, sorters + 1)).tolist()
    qcuts[0], qcuts[-1] = 0, coarse
    sides = []
    for q0, q1 in zip(qcuts[:-1], qcuts[1:]):
        direct = int(start[q0 * parts]) if q0 < coarse else len(t)
        k = max(0, min(direct, int(bounds[q1])) - int(bounds[q0]))
        sides.append((int(bounds[q0]), np.empty(k), np.empty(k, np.uint64)))
    dups = pool.map(lambda k: _kernel.order(t, ids, start, counts, parts, qcuts[k], qcuts[k + 1], *buckets[1:], key,
                                            bits, *sides[k][1:]), range(sorters))
    dup = any(list(dups))
    for lo, t_side, id_side in sides:
        t[lo : lo + len(t_side)] = t_side
        ids[lo : lo + len(id_side)] = id_side
    return t[:m], ids[:m], dup


def arrival_order(t, face, ctr, key):
    """(m,) int64 permutation sorting arrivals by (time, face key, counter).

    t (m,) float64, face (m,) used-face index, ctr (m,) uint64, key (F,) uint64 face keys.
    One value sort of packed words (time quantised in the high bits, position in the low
    ones), then the rare runs of equal quantised time ordered exactly.
    """
    m = len(t)
    if m == 0:
        return np.empty(0, np.int64)
    bits = max(1, (m - 1).bit_length())
    qbits = min(52, 64 - bits)
    top = float(t.max())
    scale = 2.0 ** (qbits - 1) / top if top > 0 else 0.0  # q < 2^qbits even when rounded up
    packed = (t * scale).astype(np.uint64)
    packed <<= np.uint64(bits)
    packed |= np.arange(m, dtype=np.uint64)
    packed.sort()
    order = (packed & np.uint64((1 << bits) - 1)).astype(np.int64)
    packed >>= np.uint64(bits)
    tie = np.flatnonzero(packed[1:] == packed[:-1])
    if len(tie):
        member = np.zeros(m, dtype=bool)
        member[tie] = True
        member[tie + 1] = True
        pos = np.flatnonzero(member)
        run = np.cumsum(np.concatenate([[1], np.diff(pos) > 1]))
        idx = order[pos]
        order[pos] = idx[np.lexsort((ctr[idx], key[face[idx]], t[idx], run))]
    return order


def has_duplicates(t, face, ctr, key):
    """Whether two consecutive arrivals (sorted arrays) are the same arrival of two faces
    with one key."""
    same = np.flatnonzero(t[1:] == t[:-1])
    if not len(same):
        return False
    return bool(np.any((key[face[same]] == key[face[same + 1]]) & (ctr[same] == ctr[same + 1])))
