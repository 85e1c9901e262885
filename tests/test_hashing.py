"""SplitMix64 is written once in Python (scatter_cli.core.hashing) and gives SplitMix64's bits."""

import re
from pathlib import Path

import numpy as np

from scatter_cli.core import hashing

PACKAGE = Path(__file__).resolve().parents[1] / "scatter_cli"


def test_mix_gives_splitmix64s_published_outputs():
    """SplitMix64 seeded with 0: its first outputs are mix(k GOLDEN), k = 1, 2, 3 (the
    values of the reference implementation); the int and array forms agree."""
    want = [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F]
    got = hashing.lane(np.uint64(0), np.arange(1, 4, dtype=np.uint64))
    assert got.tolist() == want
    assert [hashing.mix_int(k * hashing.GOLDEN) for k in (1, 2, 3)] == want
    assert hashing.to_unit(np.array([0, 1 << 63, (1 << 64) - 1], dtype=np.uint64)).tolist() == [0.0, 0.5, 1 - 2.0**-53]


def test_splitmix64_constants_appear_in_one_python_module():
    """The finaliser's multipliers are in hashing.py and in no other Python module (the C
    kernels keep their own copy)."""
    pattern = re.compile(r"0x(BF58476D1CE4E5B9|94D049BB133111EB)", re.IGNORECASE)
    holders = sorted(p.name for p in PACKAGE.rglob("*.py") if pattern.search(p.read_text()))
    assert holders == ["hashing.py"]
