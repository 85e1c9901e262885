"""The volume kernel (closest points, ray parity, tree order) under AddressSanitizer and
UndefinedBehaviorSanitizer.

Builds scatter_cli/volume/_cvolume.c with -fsanitize=address,undefined into a copy of the
package (and of tests, testkit and benchmarks) in a temporary directory, then, with the
sanitizer runtimes preloaded, runs tests/test_distance.py (brute-force comparisons on
closed, open, self-intersecting and instanced meshes, grazing rays, the kernel against
the NumPy path, 60 hypothesis soups with degenerate triangles and coordinates from 1e-100
to 1e100, and the bad calls the kernel must refuse), then 10^5 points on the skull sample
on 2 threads. Any report aborts.

    python benchmarks/volume_sanitizers.py      (gcc with libasan/libubsan; Linux)

Results are in benchmarks/results/2026-12-03-volume-distance.md.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sanitized import run_sanitized  # noqa: E402

BIG = r'''
import numpy as np, sys, trimesh
from scatter_cli.volume import distance, parity
assert distance._kernel is not None and sys.argv[1] in distance._kernel.__file__
m = trimesh.load("samples/skull.ply", process=False)
tree = distance.TriangleTree(np.asarray(m.vertices, float), np.asarray(m.faces, np.int64))
lo, hi = m.bounds
pad = 0.1 * (hi - lo).max()
p = np.random.default_rng(1).uniform(lo - pad, hi + pad, (100000, 3))
d, q, f = distance.closest_points(tree, p)
inside = parity.parity_inside(tree, p)
assert np.isfinite(d).all() and (f >= 0).all() and (f < len(m.faces)).all()
print("volume kernel: skull, 10^5 points under the sanitizers:", round(float(d.mean()), 6), int(inside.sum()), "inside")
'''


def main():
    run_sanitized("_cvolume", "volume.distance", "tests/test_distance.py", BIG)


if __name__ == "__main__":
    main()
