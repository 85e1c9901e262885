"""The winding-number kernel under AddressSanitizer and UndefinedBehaviorSanitizer.

Builds scatter_cli/volume/_cwinding.c with -fsanitize=address,undefined into a copy of the
package (and of tests, testkit and benchmarks) in a temporary directory,
then, with the sanitizer runtimes preloaded, runs tests/test_winding.py (brute-force
cases, kernel/NumPy parity, bad arrays the kernel must refuse, fuzzed soups with NaN,
inf, huge and tiny coordinates and zero-area faces, fuzzed links), then the kernel on the
skull sample (100k faces) at 20,000 points in its padded box, on two threads, compared
with the NumPy path's bytes. Any report aborts.

    python benchmarks/winding_sanitizers.py      (gcc with libasan/libubsan; Linux)

Results are in benchmarks/results/2026-12-03-winding.md.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sanitized import run_sanitized  # noqa: E402

BIG = r'''
import numpy as np, sys, trimesh
from scatter_cli.volume import winding
assert winding._kernel is not None and sys.argv[1] in winding._kernel.__file__
m = trimesh.load("samples/skull.ply", force="mesh")
tree = winding.WindingTree(np.asarray(m.vertices, float), np.asarray(m.faces, np.int64))
lo, hi = m.bounds
pad = 0.1 * (hi - lo).max()
points = np.random.default_rng(0).uniform(lo - pad, hi + pad, size=(20000, 3))
w = winding.winding_numbers(tree, points)
kernel, winding._kernel = winding._kernel, None
assert w.tobytes() == winding.winding_numbers(tree, points).tobytes()
print("winding kernel: skull, 20,000 points under the sanitizers, same bytes as NumPy; inside:", int((w >= 0.5).sum()))
'''


def main():
    run_sanitized("_cwinding", "volume.winding", "tests/test_winding.py", BIG)


if __name__ == "__main__":
    main()
