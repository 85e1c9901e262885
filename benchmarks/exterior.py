"""--exterior against the plain run, in one run of this script (ratios, not absolute times).

Scenes (written once to a temporary directory as binary PLY):
- ``icosphere``: trimesh.creation.icosphere(subdivisions=8), 1,310,720 faces, all exterior;
- ``hidden20``: the same sphere with a sphere of half its radius (subdivisions=7) inside:
  1,638,400 faces, 20 % of the area hidden.

For each scene and count, ``scatter sample MESH -n N -o out.ply`` with and without
``--exterior`` (``--stats`` gives the ray scene's construction (face normals, Embree's
geometry and its BVH build) and the BVH build alone, the exterior pass, the part of it
spent finding enclosed faces, and the rays). The target is
(ext - BVH build) / plain <= 3; (ext - ray scene) / plain, the ratio reported before
2026-12-02, also takes the face normals off. Prints the load average before and after,
and, for ``--repeats`` back-to-back warm runs each, the medians as a Markdown table.

    PYTHONPATH=. python benchmarks/exterior.py [--repeats 3] [--counts 100000,1000000] \
        [--mesh-to-sdf /path/to/python]

``--mesh-to-sdf PYTHON``: also, on the same two scenes at 5 subdivisions (its renders
cost about the same on small meshes), time mesh_to_sdf's scan sampler
(``get_surface_point_cloud``: 100 depth renders of 400 x 400, its defaults) with that
interpreter (an environment with ``pip install mesh-to-sdf``; headless:
PYOPENGL_PLATFORM=egl), and measure how uneven its points are: the coefficient of
variation of the counts over 100 equal-area cells of the outer sphere (about
sqrt(100 / n) for n uniform points).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def scenes(folder: Path, subdivisions=8, tag=""):
    import numpy as np
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=subdivisions)
    paths = {"icosphere" + tag: folder / f"icosphere{tag}.ply", "hidden20" + tag: folder / f"hidden20{tag}.ply"}
    ball.export(paths["icosphere" + tag])
    inner = trimesh.creation.icosphere(subdivisions=subdivisions - 1, radius=0.5)
    both = trimesh.Trimesh(np.vstack([ball.vertices, inner.vertices]),
                           np.vstack([ball.faces, inner.faces + len(ball.vertices)]), process=False)
    both.export(paths["hidden20" + tag])
    return paths


def run(mesh, n, out, exterior, stats_path):
    args = [sys.executable, "-m", "scatter_cli", "sample", str(mesh), "-n", str(n), "-o", str(out), "-q",
            "--stats", str(stats_path)]
    if exterior:
        args.append("--exterior")
    t = time.perf_counter()
    subprocess.run(args, check=True, stdin=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    return wall, json.loads(Path(stats_path).read_text())


M2S_SCRIPT = r"""
import os, sys, time, json
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
import numpy as np, trimesh
from mesh_to_sdf import get_surface_point_cloud
mesh = trimesh.load(sys.argv[1], process=False)
t = time.perf_counter()
cloud = get_surface_point_cloud(mesh, surface_point_method="scan", scan_count=100, scan_resolution=400)
seconds = time.perf_counter() - t
p = cloud.points
r = np.linalg.norm(p, axis=1)
outer = p[r > 0.75]
z = np.clip(outer[:, 2] / np.linalg.norm(outer, axis=1), -1, 1)
cell = np.minimum(((z + 1) / 2 * 10).astype(int), 9) * 10 + np.minimum(((np.arctan2(outer[:, 1], outer[:, 0]) + np.pi) / (2 * np.pi) * 10).astype(int), 9)
counts = np.bincount(cell, minlength=100)
print(json.dumps({"seconds": seconds, "points": len(p), "inner_points": int(np.sum(r < 0.75)),
                  "cv": float(counts.std() / counts.mean())}))
"""


def mesh_to_sdf(python, mesh):
    out = subprocess.run([python, "-c", M2S_SCRIPT, str(mesh)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--counts", default="100000,1000000")
    ap.add_argument("--mesh-to-sdf", default=None, metavar="PYTHON")
    opts = ap.parse_args()
    counts = [int(c) for c in opts.counts.split(",")]
    print(f"load average before: {open('/proc/loadavg').read().split()[:3]}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        m2s = []
        if opts.mesh_to_sdf:  # its renders cost the same on small meshes: 5 subdivisions (10,240 faces)
            for name, mesh in scenes(tmp, 5, "5").items():
                wall, st = run(mesh, 100000, tmp / "o.ply", True, tmp / "s.json")
                m2s.append((name, mesh_to_sdf(opts.mesh_to_sdf, mesh), wall))
        for name, mesh in scenes(tmp).items():
            for n in counts:
                plain, ext, build, bvh, passes, encl, rays, frac = [], [], [], [], [], [], [], []
                for exterior in (False, True):  # a warm-up of each, not counted
                    run(mesh, n, tmp / "o.ply", exterior, tmp / "s.json")
                for _ in range(opts.repeats):  # alternate, so that load drifts hit both alike
                    wall, _ = run(mesh, n, tmp / "o.ply", False, tmp / "s.json")
                    plain.append(wall)
                    wall, st = run(mesh, n, tmp / "o.ply", True, tmp / "s.json")
                    ext.append(wall)
                    build.append(st["timings"]["ray_scene"])
                    bvh.append(st["timings"]["bvh_build"])
                    passes.append(st["timings"]["exterior"])
                    encl.append(st["timings"].get("enclosure", 0.0))
                    rays.append(st["exterior"]["rays"])
                    frac.append(st["exterior"]["exterior_fraction"])
                p, e, b, t, x, c = (statistics.median(v) for v in (plain, ext, build, bvh, passes, encl))
                rows.append((name, n, p, e, b, t, x, c, (e - b) / p, (e - t) / p, rays[0], rays[0] / max(x - c, 1e-9),
                             statistics.median(frac), st["exterior"].get("faces_enclosed", 0)))
    print(f"CPUs: {os.cpu_count()}, threads: {os.environ.get('SCATTER_THREADS', 'default')}, "
          f"repeats: {opts.repeats} (medians)\n")
    print("| mesh | N | plain s | --exterior s | ray scene s | of which BVH build s | exterior pass s "
          "| of which enclosure s | (ext - ray scene) / plain | (ext - BVH build) / plain | rays "
          "| rays/s (pass less enclosure) | exterior fraction | faces enclosed |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, n, p, e, b, t, x, c, ratio, strict, r, rate, f, enclosed in rows:
        print(f"| {name} | {n:,} | {p:.2f} | {e:.2f} | {b:.2f} | {t:.2f} | {x:.2f} | {c:.2f} | {ratio:.2f} | {strict:.2f} "
              f"| {r:,} | {rate / 1e6:.2f} M | {f:.4f} | {enclosed:,} |")
    print(f"\nload average after: {open('/proc/loadavg').read().split()[:3]}")
    if m2s:
        print("\nmesh_to_sdf scan (100 renders of 400 x 400):\n")
        print("| mesh | mesh_to_sdf s | points | points on the hidden sphere | CV of outer cell counts "
              "| CV if uniform | scatter --exterior -n 100000 s |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        for name, r, wall in m2s:
            print(f"| {name} | {r['seconds']:.1f} | {r['points']:,} | {r['inner_points']:,} | {r['cv']:.3f} "
                  f"| {(100 / r['points']) ** 0.5:.3f} | {wall:.2f} |")


if __name__ == "__main__":
    main()
