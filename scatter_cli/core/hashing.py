"""SplitMix64, the one hash of the Python code: counter-based streams and keys.

``mix`` is SplitMix64's finaliser and ``GOLDEN`` its golden-ratio increment; value ``i``
of the stream with key ``k`` is ``mix(k + i GOLDEN)`` (:func:`lane`). The compiled
kernels carry their own C copy, which gives the same bits.
"""

from __future__ import annotations

import numpy as np

MASK = (1 << 64) - 1
GOLDEN = 0x9E3779B97F4A7C15
M1, M2 = 0xBF58476D1CE4E5B9, 0x94D049BB133111EB
_G = np.uint64(GOLDEN)
_M1, _M2 = np.uint64(M1), np.uint64(M2)


def mix(z):
    """SplitMix64's finaliser on (n,) uint64 ``z``, in place; returns ``z``."""
    z ^= z >> np.uint64(30)
    z *= _M1
    z ^= z >> np.uint64(27)
    z *= _M2
    z ^= z >> np.uint64(31)
    return z


def mix_int(z: int) -> int:
    """SplitMix64's finaliser on one Python int (taken modulo 2^64)."""
    z &= MASK
    z = ((z ^ (z >> 30)) * M1) & MASK
    z = ((z ^ (z >> 27)) * M2) & MASK
    return z ^ (z >> 31)


def lane(state, offset):
    """(n,) uint64 ``mix(state + offset GOLDEN)``: value ``offset`` of the stream keyed
    ``state``; ``state`` and ``offset`` scalars or (n,) uint64."""
    z = np.asarray(offset, dtype=np.uint64) * _G
    z += state
    return mix(z)


def to_unit(z):
    """(n,) uint64 -> (n,) float64 in [0, 1): the top 53 bits."""
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


def seed_word(seed: int) -> int:
    """The seed (any non-negative int) folded into one 64-bit word."""
    h = 0
    seed = int(seed)
    while True:
        h = mix_int((h ^ (seed & MASK)) + GOLDEN)
        seed >>= 64
        if not seed:
            return h
