"""The edge-link kernel under AddressSanitizer and UndefinedBehaviorSanitizer.

Builds scatter_cli/sampling/_cedges.c with -fsanitize=address,undefined into a copy of the
package (and of the tests and benchmarks) in a temporary directory, then, with the
sanitizer runtimes preloaded, runs tests/test_edges.py (boxes, creases, boundary,
non-manifold and degenerate faces, fuzzed triangle lists with repeated positions, -0.0 and
invalid faces against the NumPy twin, an index out of range refused), then the kernel on
the CAD part split in four six times (516,096 faces, corners repeated per face) and on the
skull sample, compared with the NumPy twin's arrays. Any report aborts.

    python benchmarks/edges_sanitizers.py      (gcc with libasan/libubsan; Linux)

Results are in benchmarks/results/2026-12-04-edges.md.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sanitized import run_sanitized  # noqa: E402

BIG = r'''
import numpy as np, sys, trimesh
from scatter_cli.sampling import sharp
from scatter_cli.sampling.normals import face_normals
assert sharp._kernel is not None and sys.argv[1] in sharp._kernel.__file__
part = trimesh.load("samples/pediment_join_plate_12.stl")
for _ in range(6):
    part = part.subdivide()
skull = trimesh.load("samples/skull.ply", process=False)
for name, v, f in (("part, corners repeated", part.vertices[part.faces].reshape(-1, 3),
                    np.arange(3 * len(part.faces)).reshape(-1, 3)),
                   ("skull", np.asarray(skull.vertices, float), np.asarray(skull.faces, np.int64))):
    v = np.ascontiguousarray(v, dtype=np.float64)
    normals = face_normals(v, f)
    valid = np.any(normals != 0, axis=1)
    for limit in (np.inf, 0.96):
        kernel, twin = sharp.edge_slots(v, f, valid, normals, limit), sharp._numpy_edge_slots(v, f, valid, normals, limit)
        assert all(np.array_equal(getattr(kernel, k), getattr(twin, k)) for k in ("head", "second", "count", "rest")), name
    print(f"edges: {name}, {len(f):,} faces under the sanitizers, the NumPy twin's arrays (all edges, and those that can be sharp)")
'''


def main():
    run_sanitized("_cedges", "sampling.sharp", "tests/test_edges.py", BIG)


if __name__ == "__main__":
    main()
