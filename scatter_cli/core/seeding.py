"""NumPy's ``PCG64DXSM(seed)`` state, advanced, in plain Python integers.

The sampling kernel draws from the 128-bit state that ``np.random.PCG64DXSM(seed)``
reaches after ``advance(n)``. Computing it here, bit for bit as NumPy does, spares a
batch worker importing ``numpy.random`` (13-17 ms, on the critical path of a batch's
start-up). Three steps, each NumPy's own:

- ``SeedSequence(seed).generate_state(4, uint64)``: the seed's 32-bit words mixed into a
  pool of four, then hashed out to eight 32-bit words (two per uint64, low word first);
- PCG64's seeding (``pcg_setseq_128_srandom_r``): ``inc = (seq << 1) | 1``, then a step,
  ``state += initstate``, a step, both with PCG's default 128-bit multiplier;
- ``advance(n)``: the LCG jumped ahead ``n`` steps with the DXSM generator's cheap 64-bit
  multiplier (Brown's algorithm).

tests/test_seeding.py checks every function against NumPy.
"""

from __future__ import annotations

MASK32 = (1 << 32) - 1
MASK128 = (1 << 128) - 1
POOL_SIZE = 4
INIT_A, MULT_A = 0x43B0D7E5, 0x931E8875
INIT_B, MULT_B = 0x8B51F9DD, 0x58F38DED
MIX_MULT_L, MIX_MULT_R = 0xCA01F9DD, 0x4973F715
XSHIFT = 16
DEFAULT_MULTIPLIER = 0x2360ED051FC65DA44385DF649FCCF645
CHEAP_MULTIPLIER = 0xDA942042E4DD58B5


def seed_words(seed: int) -> list:
    """A non-negative integer seed as NumPy's SeedSequence takes it: 32-bit words, low first."""
    if seed < 0:
        raise ValueError("the seed must be non-negative")
    words = []
    while True:
        words.append(seed & MASK32)
        seed >>= 32
        if not seed:
            return words


def seed_pool(seed: int) -> list:
    """The four 32-bit words of ``SeedSequence(seed).pool``."""
    entropy = seed_words(seed)
    const = INIT_A

    def hashmix(value):
        nonlocal const
        value ^= const
        const = (const * MULT_A) & MASK32
        value = (value * const) & MASK32
        return value ^ (value >> XSHIFT)

    def mix(x, y):
        result = (MIX_MULT_L * x - MIX_MULT_R * y) & MASK32
        return result ^ (result >> XSHIFT)

    pool = [hashmix(entropy[i] if i < len(entropy) else 0) for i in range(POOL_SIZE)]
    for src in range(POOL_SIZE):
        for dst in range(POOL_SIZE):
            if src != dst:
                pool[dst] = mix(pool[dst], hashmix(pool[src]))
    for src in range(POOL_SIZE, len(entropy)):
        for dst in range(POOL_SIZE):
            pool[dst] = mix(pool[dst], hashmix(entropy[src]))
    return pool


def generate_state(seed: int, words64: int) -> list:
    """``SeedSequence(seed).generate_state(words64, np.uint64)`` as Python integers."""
    pool = seed_pool(seed)
    const = INIT_B
    words = []
    for i in range(2 * words64):
        value = pool[i % POOL_SIZE] ^ const
        const = (const * MULT_B) & MASK32
        value = (value * const) & MASK32
        words.append(value ^ (value >> XSHIFT))
    return [words[2 * i] | words[2 * i + 1] << 32 for i in range(words64)]


def pcg64_state(seed: int) -> tuple:
    """(state, inc), 128-bit integers, of a freshly seeded ``PCG64DXSM(seed)``."""
    s0, s1, i0, i1 = generate_state(seed, 4)
    initstate, initseq = s0 << 64 | s1, i0 << 64 | i1
    inc = (initseq << 1 | 1) & MASK128
    state = inc  # one step from 0
    state = (state + initstate) & MASK128
    state = (state * DEFAULT_MULTIPLIER + inc) & MASK128
    return state, inc


def advance(state: int, inc: int, delta: int) -> int:
    """The state ``delta`` steps of the DXSM generator's LCG on from ``state``."""
    mult, plus = 1, 0
    cur_mult, cur_plus = CHEAP_MULTIPLIER, inc
    delta &= MASK128
    while delta:
        if delta & 1:
            mult = (mult * cur_mult) & MASK128
            plus = (plus * cur_mult + cur_plus) & MASK128
        cur_plus = ((cur_mult + 1) * cur_plus) & MASK128
        cur_mult = (cur_mult * cur_mult) & MASK128
        delta >>= 1
    return (mult * state + plus) & MASK128
