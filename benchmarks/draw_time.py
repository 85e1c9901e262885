"""Time of SamplePlan.draw per 10^7 points on one thread (median over chunks).

    NUMPY_MADVISE_HUGEPAGE=0 python benchmarks/draw_time.py [--numpy]

On the 1.31M-face icosphere and the skull; ``--numpy`` times the NumPy path
(SCATTER_NUMPY=1) instead of the compiled kernel. The kernel is timed in draw order at
2^17 points a chunk, and in face order at 2^17 and at the plan's default chunk (2^19 on
meshes of 2^18 faces or more); the output is the same bytes every way.
"""

import os
import sys
import time
from pathlib import Path

if "--numpy" in sys.argv:
    os.environ["SCATTER_NUMPY"] = "1"

import numpy as np  # noqa: E402
import trimesh  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from scatter_cli.sampling import plan as sampling  # noqa: E402
from scatter_cli.loading.load import load_surface  # noqa: E402

POINTS = 6 << 20  # per timing, whatever the chunk


def per_ten_million(plan, chunk):
    times = []
    for k in range(POINTS // chunk):
        t = time.perf_counter()
        plan.draw(k * chunk, (k + 1) * chunk, 0)
        times.append(time.perf_counter() - t)
    return np.median(times) * 1e7 / chunk


meshes = {"icosphere (1.31M faces)": trimesh.creation.icosphere(subdivisions=8),
          "skull (100k faces)": Path(__file__).resolve().parent.parent / "samples" / "skull.ply"}
for name, mesh in meshes.items():
    plan = sampling.SamplePlan(load_surface(mesh))
    if sampling._kernel is None:
        print(f"{name}, NumPy path: {per_ten_million(plan, 1 << 17):.3f} s per 10^7 points, one thread")
        continue
    for order, chunk in [(False, 1 << 17), (True, 1 << 17), (True, sampling.LARGE_MESH_CHUNK)]:
        plan.in_face_order = order
        what = "face order" if order else "draw order"
        print(f"{name}, kernel, {what}, {chunk:,} a chunk: "
              f"{per_ten_million(plan, chunk):.3f} s per 10^7 points, one thread")
