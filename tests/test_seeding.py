"""scatter_cli.core.seeding: NumPy's PCG64DXSM seeding and advance in plain integers, checked
against NumPy itself, with broken variants that must differ."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scatter_cli.sampling import plan as sampling
from scatter_cli.core import seeding

SEEDS = st.integers(min_value=0, max_value=2**200)
STEPS = st.integers(min_value=0, max_value=2**130)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(SEEDS)
def test_seed_sequence_is_numpys(seed):
    sequence = np.random.SeedSequence(seed)
    assert seeding.seed_pool(seed) == [int(w) for w in sequence.pool]
    assert seeding.generate_state(seed, 4) == [int(w) for w in sequence.generate_state(4, np.uint64)]


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(SEEDS, STEPS)
def test_seeded_and_advanced_state_is_numpys(seed, steps):
    bits = np.random.PCG64DXSM(seed)
    state, inc = seeding.pcg64_state(seed)
    assert (state, inc) == (bits.state["state"]["state"], bits.state["state"]["inc"])
    bits.advance(steps)
    assert seeding.advance(state, inc, steps) == bits.state["state"]["state"]


@pytest.mark.parametrize("seed, start", [(0, 0), (0, 2048), (7, 1), (2**40 + 3, 10**9)])
def test_the_kernel_state_is_the_numpy_streams(seed, start):
    state = sampling._stream(seed, start).state["state"]
    mask = (1 << 64) - 1
    assert sampling.generator_state(seed, start) == (state["state"] >> 64, state["state"] & mask,
                                                     state["inc"] >> 64, state["inc"] & mask)


def test_broken_variants_differ():
    """The test above can fail: seeding with the cheap multiplier, advancing with the
    default one, or dropping the pool's cross-mixing each give another state."""
    seed, steps = 12345, 3 * 2048
    bits = np.random.PCG64DXSM(seed)
    bits.advance(steps)
    want = bits.state["state"]["state"]
    state, inc = seeding.pcg64_state(seed)
    assert seeding.advance(state, inc, steps) == want
    saved = seeding.DEFAULT_MULTIPLIER, seeding.CHEAP_MULTIPLIER, seeding.POOL_SIZE
    try:
        seeding.DEFAULT_MULTIPLIER = saved[1]
        assert seeding.advance(*seeding.pcg64_state(seed), steps) != want
        seeding.DEFAULT_MULTIPLIER, seeding.CHEAP_MULTIPLIER = saved[0], saved[0]
        assert seeding.advance(*seeding.pcg64_state(seed), steps) != want
        seeding.CHEAP_MULTIPLIER, seeding.POOL_SIZE = saved[1], 2
        assert seeding.advance(*seeding.pcg64_state(seed), steps) != want
    finally:
        seeding.DEFAULT_MULTIPLIER, seeding.CHEAP_MULTIPLIER, seeding.POOL_SIZE = saved
