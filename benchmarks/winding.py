"""Winding numbers: scatter's tree (scatter_cli/volume/winding.py) against libigl and Open3D.

On the skull sample (100,002 faces, closed) and a closed 327,680-face icosphere, N points
(default 10^6) uniform in the box grown by 0.1 of its largest side: the time of

- scatter: WindingTree (the tree) + winding_numbers, on native.worker_count() threads;
- libigl: igl.fast_winding_number(V, F, Q) (its own tree and order-2 expansion, beta 2);
- Open3D: RaycastingScene (add_triangles) + compute_occupancy (labels only, by rays);

a warm-up, then the median of back-to-back runs, each tool in turn, with the ratios to
scatter in the same run. Then each one's label disagreement with the exact winding number
(brute force, w >= 0.5) on open meshes (hemisphere.off and an icosphere with a cap cut
off) at fewer points, and scatter's peak of traced memory (tracemalloc) at two point
counts, for a flat-memory check.

    python benchmarks/winding.py [--points N] [--repeats R] [--open-points M]
    (pip install libigl open3d)
"""

import argparse
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from scatter_cli.core import native
from scatter_cli.volume import winding  # noqa: E402


def meshes():
    skull = trimesh.load(ROOT / "samples" / "skull.ply", force="mesh")
    sphere = trimesh.creation.icosphere(subdivisions=7)
    return {"skull (100,002 faces)": skull, "icosphere-7 (327,680 faces)": sphere}


def box_points(vertices, n, seed=0):
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    pad = 0.1 * (hi - lo).max()
    return np.random.default_rng(seed).uniform(lo - pad, hi + pad, size=(n, 3))


def ours(v, f, q):
    return winding.winding_numbers(winding.WindingTree(v, f), q) >= 0.5


def libigl(v, f, q):
    import igl

    return igl.fast_winding_number(v, f, q) >= 0.5


def open3d(v, f, q):
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
    return scene.compute_occupancy(o3d.core.Tensor(q.astype(np.float32))).numpy() > 0.5


TOOLS = {"scatter": ours, "libigl fast_winding_number": libigl, "Open3D compute_occupancy": open3d}


def timed(fn, *args):
    t = time.perf_counter()
    out = fn(*args)
    return time.perf_counter() - t, out


def speed(points, repeats):
    print(f"## Time, {points:,} points in the padded box (median of {repeats} after a warm-up)\n")
    print("| mesh | tool | seconds | ratio to scatter | inside share |")
    print("|---|---|---|---|---|")
    for name, m in meshes().items():
        v, f = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
        q = box_points(v, points)
        times = {tool: [] for tool in TOOLS}
        inside = {}
        for tool, fn in TOOLS.items():
            fn(v, f, q[:10000])  # warm-up (imports, first-touch)
        for _ in range(repeats):
            for tool, fn in TOOLS.items():
                t, labels = timed(fn, v, f, q)
                times[tool].append(t)
                inside[tool] = labels.mean()
        base = statistics.median(times["scatter"])
        for tool in TOOLS:
            med = statistics.median(times[tool])
            print(f"| {name} | {tool} | {med:.2f} | {med / base:.2f} | {inside[tool]:.4f} |")
        t_build, tree = timed(winding.WindingTree, v, f)
        t_eval, _ = timed(winding.winding_numbers, tree, q)
        print(f"| {name} | scatter: tree alone / evaluation alone | {t_build:.2f} / {t_eval:.2f} | | |")
    print()


def exact_winding(tri, points, chunk=32):
    out = np.empty(len(points))
    for at in range(0, len(points), chunk):
        q = points[at:at + chunk, None, :]
        a, b, c = (tri[None, :, k, :] - q for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", b, c) * la
               + np.einsum("pfi,pfi->pf", c, a) * lb)
        out[at:at + chunk] = np.arctan2(det, den).sum(axis=1) / (2 * np.pi)
    return out


def open_meshes():
    hemi = trimesh.load(ROOT / "samples" / "hemisphere.off", force="mesh")
    sphere = trimesh.creation.icosphere(4)
    keep = sphere.vertices[sphere.faces][:, :, 2].max(axis=1) <= 0.6
    capped = trimesh.Trimesh(sphere.vertices, sphere.faces[keep], process=False)
    return {"hemisphere.off (3,600 faces, open)": hemi, "icosphere-4, cap z > 0.6 cut (open)": capped}


def disagreement(points):
    print(f"## Labels on open meshes against the exact winding number ({points:,} points in the padded box)\n")
    print("| mesh | tool | labels differing from exact w >= 0.5 | of which off the margin |exact w - 0.5| >= 0.05 |")
    print("|---|---|---|---|")
    for name, m in open_meshes().items():
        v, f = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
        q = box_points(v, points, seed=1)
        exact = exact_winding(v[f], q)
        truth, clear = exact >= 0.5, np.abs(exact - 0.5) >= 0.05
        for tool, fn in TOOLS.items():
            wrong = fn(v, f, q) != truth
            print(f"| {name} | {tool} | {wrong.mean():.2%} ({wrong.sum()}) | {wrong[clear].mean():.2%} ({wrong[clear].sum()}) |")
    print()


def memory():
    print("## scatter's peak traced memory beyond the points and the result (tracemalloc)\n")
    m = trimesh.load(ROOT / "samples" / "skull.ply", force="mesh")
    tree = winding.WindingTree(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64))
    print("| points | peak MB |")
    print("|---|---|")
    for n in (200_000, 2_000_000):
        q = box_points(tree.triangles.reshape(-1, 3), n)
        tracemalloc.start()
        w = winding.winding_numbers(tree, q)
        peak = tracemalloc.get_traced_memory()[1] - w.nbytes
        tracemalloc.stop()
        print(f"| {n:,} | {peak / 1e6:.1f} |")
    print()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--open-points", type=int, default=20_000)
    args = ap.parse_args()
    with open("/proc/loadavg") as f:
        load = f.read().split()[:3]
    print(f"threads: scatter {native.worker_count()} (SCATTER_THREADS), kernel {'on' if winding._kernel else 'OFF'}; "
          f"load average at start {' '.join(load)}\n")
    speed(args.points, args.repeats)
    disagreement(args.open_points)
    memory()
    with open("/proc/loadavg") as f:
        print("load average at the end", " ".join(f.read().split()[:3]))


if __name__ == "__main__":
    main()
