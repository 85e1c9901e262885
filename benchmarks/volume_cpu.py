"""CPU and wall seconds of scatter's volume labels on a shared machine.

On the points of benchmarks/volume.py (10^6 uniform in the padded box of the skull, or
of ``--mesh``): the distance (distance.TriangleTree and closest_points) and the winding
numbers (winding.WindingTree and winding_numbers), each with its tree built, after a
warm-up on 10^4 points; with ``--open3d``, Open3D's compute_signed_distance too. CPU seconds (all
threads) move less than wall seconds when other work shares the cores, so runs of two
builds alternated on a busy machine compare them better than wall time does.

    PYTHONPATH=. python benchmarks/volume_cpu.py [--open3d] [--points N] [--parts] [--mesh NAME]
    python benchmarks/volume_cpu.py --checkouts BEFORE AFTER [--rounds R] [--points N] [--mesh NAME]

``--parts``: instead, the steps of a distance + winding run (``sdf,inside``) apart: each
tree's build, both built as a run builds them (``source.label_trees``), and each kind of
query over all the points, median CPU and wall seconds of 5.

``--checkouts``: instead, the whole distance + winding run of benchmarks/volume.py (both
trees built as a run builds them, then the queries), median wall and CPU seconds of 5 runs
in a fresh process of each checkout (its kernels built in place), the checkouts taking
turns for R rounds, then each one's medians over the rounds: a before-and-after on a
shared machine, where the load moves between rounds.

Figures: benchmarks/results/2026-12-03-volume-speed.md, 2026-12-05-volume-builds.md,
2026-12-05-volume-bounds.md.
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


ONE_CHECKOUT = r"""
import sys, time
import numpy as np
sys.path.insert(0, "benchmarks")
import volume as bench
v, f = bench.load(sys.argv[2])
p = bench.box_points(v, int(sys.argv[1]))
bench.ours_distance_winding(v, f, p[:10000])
runs = []
for _ in range(5):
    c, t = time.process_time(), time.perf_counter()
    bench.ours_distance_winding(v, f, p)
    runs.append((time.perf_counter() - t, time.process_time() - c))
print(*np.median(runs, axis=0))
"""


def checkouts(folders, points, rounds, mesh="skull"):
    """{checkout: [(wall s, CPU s) per round]}: the checkouts' runs, taking turns."""
    import os
    import subprocess

    out = {d: [] for d in folders}
    for r in range(rounds):
        for d in folders:
            env = dict(os.environ, PYTHONPATH=str(Path(d).resolve()))
            done = subprocess.run([sys.executable, "-c", ONE_CHECKOUT, str(points), mesh], cwd=d, env=env,
                                  capture_output=True, text=True, check=True)
            out[d].append(tuple(map(float, done.stdout.split())))
            print(f"round {r}: {d}: wall {out[d][-1][0]:.3f} cpu {out[d][-1][1]:.3f}", flush=True)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--open3d", action="store_true")
    ap.add_argument("--points", type=int, default=10**6)
    ap.add_argument("--parts", action="store_true")
    ap.add_argument("--checkouts", nargs=2, metavar=("BEFORE", "AFTER"))
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--mesh", default="skull", help="a mesh of benchmarks/volume.py (skull, sphere7, hemisphere)")
    args = ap.parse_args()
    if args.checkouts:
        for d, runs in checkouts(args.checkouts, args.points, args.rounds, args.mesh).items():
            wall, cpu = np.median(runs, axis=0)
            print(f"{d}: median over {args.rounds} rounds: wall {wall:.3f} s, cpu {cpu:.3f} s")
        print("load", open("/proc/loadavg").read().split()[0])
        return
    v, f = bench.load(args.mesh)
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
