"""The edge kernel (`_cedges.edges`) of two checkouts on one mesh, call after call.

    python benchmarks/edge_kernels.py BEFORE AFTER [--mesh FILE] [--rounds 9]

BEFORE and AFTER are folders holding a built `scatter_cli` (their kernels built in
place). Both kernels are loaded into this process and called in turn on the same
arrays, at 15 degrees, on 1 and 2 threads; each call's wall and CPU time, medians
printed. The arrays both give are compared: they must be equal. The mesh (default: the
sample CAD part split in four six times, 516,096 faces, corners repeated per face) is
loaded with this checkout's `load_surface`.
"""

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from builds import kernel_of  # noqa: E402
from scatter_cli.loading.load import load_surface  # noqa: E402
from scatter_cli.sampling.normals import face_normals  # noqa: E402

FIELDS = ("head", "second", "count", "rest")


def part_mesh():
    """The sample CAD part split in four six times: (vertices, faces), corners repeated."""
    import trimesh

    part = trimesh.load(ROOT / "samples" / "pediment_join_plate_12.stl")
    for _ in range(6):
        part = part.subdivide()
    v = np.ascontiguousarray(part.vertices[part.faces].reshape(-1, 3), dtype=np.float64)
    return v, np.arange(len(v), dtype=np.int64).reshape(-1, 3)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before")
    parser.add_argument("after")
    parser.add_argument("--mesh", help="a mesh file (default: the CAD part split to 516,096 faces)")
    parser.add_argument("--rounds", type=int, default=9)
    args = parser.parse_args()
    if args.mesh:
        g = load_surface(args.mesh).geometries[0]
        v, f = np.ascontiguousarray(g.vertices, dtype=np.float64), np.ascontiguousarray(g.faces, dtype=np.int64)
    else:
        v, f = part_mesh()
    normals = face_normals(v, f)
    valid = (normals != 0).any(axis=1)
    limit = math.cos(math.radians(15.0)) + 1e-6
    kernels = {tag: kernel_of(folder, "_cedges", tag) for tag, folder in (("before", args.before), ("after", args.after))}
    print(f"{len(f):,} faces, {args.rounds} rounds")
    for threads in (1, 2):
        wall, cpu, got = {k: [] for k in kernels}, {k: [] for k in kernels}, {}
        for _ in range(args.rounds + 1):  # the first a warm-up
            for name, kernel in kernels.items():
                out = [np.empty(3 * len(f), np.int64) for _ in FIELDS]
                t, c = time.perf_counter(), time.process_time()
                edges, rests = kernel.edges(v, f, valid, normals, limit, threads, *out)
                wall[name].append(time.perf_counter() - t)
                cpu[name].append(time.process_time() - c)
                got[name] = [out[0][:edges], out[1][:edges], out[2][:edges], out[3][:rests]]
        same = all(np.array_equal(a, b) for a, b in zip(got["before"], got["after"]))
        print(f"threads {threads}: " + ", ".join(
            f"{k} wall {statistics.median(wall[k][1:]) * 1e3:.1f} ms CPU {statistics.median(cpu[k][1:]) * 1e3:.1f} ms"
            for k in kernels) + f"; same arrays: {same}")
        if not same:
            sys.exit("the two kernels disagree")


if __name__ == "__main__":
    main()
