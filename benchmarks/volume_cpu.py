"""CPU and wall seconds of scatter's volume labels on a shared machine.

On the points of benchmarks/volume.py (10^6 uniform in the skull's padded box): the
distance (distance.TriangleTree and closest_points) and the winding numbers
(winding.WindingTree and winding_numbers), each with its tree built, after a warm-up on
10^4 points; with ``--open3d``, Open3D's compute_signed_distance too. CPU seconds (all
threads) move less than wall seconds when other work shares the cores, so runs of two
builds alternated on a busy machine compare them better than wall time does.

    PYTHONPATH=. python benchmarks/volume_cpu.py [--open3d] [--points N] [--parts]

``--parts``: instead, the steps of a distance + winding run (``sdf,inside``) apart: each
tree's build, both built as a run builds them (``source.label_trees``), and each kind of
query over all the points, median CPU and wall seconds of 5.

Figures: benchmarks/results/2026-12-03-volume-speed.md.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import volume as bench  # noqa: E402

from scatter_cli.volume import distance, winding  # noqa: E402
from scatter_cli.volume.source import label_trees  # noqa: E402


def winding_labels(v, f, p):
    tree = winding.WindingTree(v, f)
    return np.concatenate([winding.winding_numbers(tree, p[i:i + bench.CHUNK]) >= 0.5
                           for i in range(0, len(p), bench.CHUNK)])


def measured(fn, v, f, p):
    """(CPU s, wall s) of fn on all points after a warm-up"""
    fn(v, f, p[:10000])
    c, t = time.process_time(), time.perf_counter()
    fn(v, f, p)
    return time.process_time() - c, time.perf_counter() - t


def parts(v, f, p, repeats=5):
    """The steps of a distance + winding run: {step: (median CPU s, median wall s)}."""
    tri = v[f]
    trees = label_trees(tri, True, True)
    chunks = range(0, len(p), bench.CHUNK)
    steps = {
        "distance tree (and its kernel form)": lambda: distance.TriangleTree.from_triangles(tri).wide(),
        "winding tree": lambda: winding.WindingTree(tri),
        "both trees, as a run builds them": lambda: label_trees(tri, True, True),
        "distance queries": lambda: [distance.closest_points(trees[0], p[i:i + bench.CHUNK]) for i in chunks],
        "winding queries": lambda: [winding.winding_numbers(trees[1], p[i:i + bench.CHUNK]) for i in chunks],
    }
    out = {}
    for name, step in steps.items():
        step()
        times = []
        for _ in range(repeats):
            c, t = time.process_time(), time.perf_counter()
            step()
            times.append((time.process_time() - c, time.perf_counter() - t))
        out[name] = tuple(np.median(times, axis=0))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--open3d", action="store_true")
    ap.add_argument("--points", type=int, default=10**6)
    ap.add_argument("--parts", action="store_true")
    args = ap.parse_args()
    v, f = bench.load("skull")
    p = bench.box_points(v, args.points)
    if args.parts:
        for name, (c, w) in parts(v, f, p).items():
            print(f"{name}: cpu {c:.3f} wall {w:.3f}")
        print("load", open("/proc/loadavg").read().split()[0])
        return
    runs = {"distance": bench.ours_distance, "winding": winding_labels}
    if args.open3d:
        runs["open3d"] = bench.open3d_sdf
    out = [f"{name}: cpu {c:.2f} wall {w:.2f}" for name, (c, w) in ((k, measured(fn, v, f, p)) for k, fn in runs.items())]
    print(" | ".join(out), "| load", open("/proc/loadavg").read().split()[0])


if __name__ == "__main__":
    main()
