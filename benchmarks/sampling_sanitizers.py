"""The sampling kernel under AddressSanitizer and UndefinedBehaviorSanitizer.

Builds scatter_cli/sampling/_csampling.c with -fsanitize=address,undefined into a copy of
the package (and of the tests and benchmarks) in a temporary directory, then, with the
sanitizer runtimes preloaded, runs the kernel-against-NumPy cases of
tests/test_kernel_parity.py (areas, guide table, selection, placement, the stream, face
normals, bounds) and the bounds tests of tests/test_hard_numeric.py (signed zeros,
infinities, NaN, every row count up to 1000 and property-based arrays), then a binary STL
of 200,003 random faces sampled whole and the bounds of its 600,009 vertices against the
NumPy twin. Any report aborts.

    python benchmarks/sampling_sanitizers.py      (gcc with libasan/libubsan; Linux)
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sanitized import run_sanitized  # noqa: E402

BIG = r'''
import numpy as np, sys
from scatter_cli.api import sample
from scatter_cli.sampling import plan
from scatter_cli.surface.model import column_bounds
assert plan._kernel is not None and sys.argv[1] in plan._kernel.__file__
corners = np.random.default_rng(4).standard_normal((200003, 3, 3)).astype(np.float32)
records = np.zeros(len(corners), dtype=[("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
records["corners"] = corners
with open("soup.stl", "wb") as f:
    f.write(b"\0" * 80 + np.uint32(len(corners)).tobytes() + records.tobytes())
s = sample("soup.stl", count=100000, seed=1, attributes="face,normal")
v = corners.reshape(-1, 3).astype(np.float64)
assert all(a.tobytes() == b.tobytes() for a, b in zip(plan.column_bounds(v), column_bounds(v)))
print(f"sampling kernel: {len(s.points):,} points on a 200,003-face STL and its bounds under the sanitizers")
'''


def main():
    run_sanitized("_csampling", "sampling.plan",
                  ["tests/test_kernel_parity.py", "tests/test_hard_numeric.py", "-k", "csampling or bounds or runs"], BIG)


if __name__ == "__main__":
    main()
