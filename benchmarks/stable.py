"""--stable against the default method: time in-process and end to end, peak memory, and
the fraction of points an edit moves against its expectation from the areas.

    PYTHONPATH=$PWD python benchmarks/stable.py [--counts 1e6,1e7] [--repeats 3] [--out FILE]

Meshes: the 1.31M-face icosphere (trimesh.creation.icosphere(subdivisions=8), written
to a binary PLY for the end-to-end runs) and samples/skull.ply. Times are medians of
back-to-back runs, default and --stable alternating after a warm run of each at the same
N, so their ratio is measured under the same load; both write xyz only, in the precision
--precision auto picks (the same for both: checked). End to end: ``python -m scatter_cli sample MESH -n N -o out.npy``;
peak memory is the child's maximum resident set (wait4), and "beyond the mesh" is that
minus the peak of the same command with ``-n 1``.
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scatter_cli import api  # noqa: E402
from scatter_cli.loading.load import load_surface  # noqa: E402


def icosphere_ply(directory):
    import trimesh

    path = Path(directory) / "icosphere8.ply"
    if not path.exists():
        trimesh.creation.icosphere(subdivisions=8).export(path)  # float32 vertices: what the file holds
    return path


def in_process(surface, n, repeats):
    """(default s, stable s): medians of runs of ``api.prepare(surface, n).collect()`` with
    and without --stable, alternating, after one warm run of each at the same N. Like with
    like: no attributes, the same precision (checked), the surface loaded once for both."""
    dtypes = {s: api.prepare(surface, n, stable=s).dtype for s in (False, True)}
    assert dtypes[False] == dtypes[True], dtypes
    times = {False: [], True: []}
    for k in range(repeats + 1):
        for s in (False, True):
            t = time.perf_counter()
            api.prepare(surface, n, stable=s).collect()
            if k:  # the first round warms both
                times[s].append(time.perf_counter() - t)
    return statistics.median(times[False]), statistics.median(times[True])


# Runs the command and prints its peak RSS: a small parent, so that the fork's copy of
# this benchmark's memory does not count in the child's maximum.
WRAPPER = ("import resource, subprocess, sys; rc = subprocess.run(sys.argv[1:], stdin=subprocess.DEVNULL).returncode; "
           "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(rc)")


def end_to_end(mesh, n, stable, out):
    """(seconds, peak RSS MB) of one run of the command."""
    cmd = [sys.executable, "-m", "scatter_cli", "sample", str(mesh), "-n", str(n), "-o", str(out), "-q"]
    if stable:
        cmd.append("--stable")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("PYTHONUNBUFFERED", None)
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", WRAPPER, *cmd], env=env, stdin=subprocess.DEVNULL,
                          capture_output=True, text=True)
    seconds = time.perf_counter() - t
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {proc.stderr}")
    return seconds, int(proc.stdout.split()[-1]) / 1024.0


def edit_fraction(path, share, n, seed=0):
    """(measured, expected) fraction of -n n --stable points that moving the vertices of a
    region of ``share`` of the area moves (outward, by 2 % of the bounding box)."""
    import trimesh

    mesh = trimesh.load(path, process=False, force="mesh")
    v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    d = np.linalg.norm(tri.mean(axis=1) - v[f[0, 0]], axis=1)
    order = np.argsort(d)
    region = order[: np.searchsorted(np.cumsum(area[order]), share * area.sum()) + 1]
    moved = np.unique(f[region])
    v2 = v.copy()
    v2[moved] *= 1.02
    tri2 = v2[f]
    area2 = 0.5 * np.linalg.norm(np.cross(tri2[:, 1] - tri2[:, 0], tri2[:, 2] - tri2[:, 0]), axis=1)
    changed = np.isin(f, moved).any(axis=1)
    before = api.sample(trimesh.Trimesh(v, f, process=False), n, stable=True, seed=seed, attributes=("face",))
    after = api.sample(trimesh.Trimesh(v2, f, process=False), n, stable=True, seed=seed, attributes=("face",))
    a = before.points[~changed[before.face]]
    b = after.points[~changed[after.face]]
    common = min(len(a), len(b))
    assert a[:common].tobytes() == b[:common].tobytes()
    total, total2, kept = area.sum(), area2.sum(), area[~changed].sum()
    expected = (total - kept) / total + kept / total * max(0.0, 1 - total / total2)
    return 1 - common / n, expected, float(area[changed].sum() / total)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--counts", default="1e6,1e7")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--edit-count", type=int, default=1_000_000)
    ap.add_argument("--out", default=None, help="write the results as JSON here")
    args = ap.parse_args()
    counts = [int(float(c)) for c in args.counts.split(",")]
    rows, edits = [], []
    with tempfile.TemporaryDirectory() as tmp:
        meshes = {"icosphere-8": icosphere_ply(tmp), "skull": ROOT / "samples" / "skull.ply"}
        for name, path in meshes.items():
            surface = load_surface(str(path))
            base = {s: end_to_end(path, 1, s, Path(tmp) / "o.npy")[1] for s in (False, True)}
            for n in counts:
                t_default, t_stable = in_process(surface, n, args.repeats)
                e2e = {False: [], True: []}
                for s in (False, True):  # warm the file cache and the interpreter's
                    end_to_end(path, n, s, Path(tmp) / "o.npy")
                for _ in range(args.repeats):
                    for s in (False, True):
                        e2e[s].append(end_to_end(path, n, s, Path(tmp) / "o.npy"))
                out_mb = os.path.getsize(Path(tmp) / "o.npy") / 2**20
                row = {
                    "mesh": name, "faces": surface.face_count, "count": n, "load_average": os.getloadavg()[0],
                    "in_process_default_s": t_default, "in_process_stable_s": t_stable,
                    "in_process_ratio": t_stable / t_default,
                    "end_to_end_default_s": statistics.median(x[0] for x in e2e[False]),
                    "end_to_end_stable_s": statistics.median(x[0] for x in e2e[True]),
                    "peak_default_mb": max(x[1] for x in e2e[False]),
                    "peak_stable_mb": max(x[1] for x in e2e[True]),
                    "output_mb": out_mb,
                }
                row["end_to_end_ratio"] = row["end_to_end_stable_s"] / row["end_to_end_default_s"]
                row["stable_beyond_mesh_mb"] = row["peak_stable_mb"] - base[True]
                row["memory_budget_mb"] = 3 * out_mb + 200
                rows.append(row)
                print(json.dumps(row), flush=True)
            for share in (0.01, 0.10):
                measured, expected, changed_area = edit_fraction(path, share, args.edit_count)
                edits.append({"mesh": name, "edited_area": changed_area, "moved": measured, "expected": expected})
                print(json.dumps(edits[-1]), flush=True)
    print_table(rows, edits)
    if args.out:
        Path(args.out).write_text(json.dumps({"timings": rows, "edits": edits}, indent=2) + "\n")


def print_table(rows, edits):
    print("\n| mesh | N | in-process default / stable (ratio) | end to end default / stable (ratio) | "
          "peak MB default / stable | stable beyond mesh MB (budget 3 x output + 200) | load |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['mesh']} | {r['count']:.0e} | {r['in_process_default_s']:.2f} / {r['in_process_stable_s']:.2f} s "
              f"({r['in_process_ratio']:.2f}x) | {r['end_to_end_default_s']:.2f} / {r['end_to_end_stable_s']:.2f} s "
              f"({r['end_to_end_ratio']:.2f}x) | {r['peak_default_mb']:.0f} / {r['peak_stable_mb']:.0f} | "
              f"{r['stable_beyond_mesh_mb']:.0f} ({r['memory_budget_mb']:.0f}) | {r['load_average']:.1f} |")
    print("\n| mesh | edited area | points moved | expected |")
    print("|---|---|---|---|")
    for e in edits:
        print(f"| {e['mesh']} | {e['edited_area']:.2%} | {e['moved']:.2%} | {e['expected']:.2%} |")


if __name__ == "__main__":
    main()
