"""Time of SamplePlan.draw per 10^7 points on one thread (median of 40 chunks of 131,072).

    NUMPY_MADVISE_HUGEPAGE=0 python benchmarks/draw_time.py [--numpy]

On the 1.31M-face icosphere and the skull; ``--numpy`` times the NumPy path
(SCATTER_NUMPY=1) instead of the compiled kernel.
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
from scatter_cli import sampling  # noqa: E402
from scatter_cli.surface import load_surface  # noqa: E402

CHUNK = 1 << 17
meshes = {"icosphere (1.31M faces)": trimesh.creation.icosphere(subdivisions=8),
          "skull (100k faces)": Path(__file__).resolve().parent.parent / "samples" / "skull.ply"}
for name, mesh in meshes.items():
    plan = sampling.SamplePlan(load_surface(mesh))
    times = []
    for k in range(40):
        t = time.perf_counter()
        plan.draw(k * CHUNK, (k + 1) * CHUNK, 0)
        times.append(time.perf_counter() - t)
    kernel = "NumPy path" if sampling._kernel is None else "kernel"
    print(f"{name}, {kernel}: {np.median(times) * 1e7 / CHUNK:.3f} s per 10^7 points, one thread")
