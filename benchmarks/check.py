"""``scatter check`` on a large terrain: the time of each of its stages against pymeshlab's
own load and sampling, measured in the same run, and the peak memory of the command.

    PYTHONPATH=$PWD python benchmarks/check.py [--grid 290] [--count 50000] [--repeats 3] [--out FILE]

The mesh: a height field of 2 (grid - 1)^2 faces (168k at grid 290), smooth hills plus
noise, so that many faces cross every level along z (the worst case for the exact
slabs), written to a binary PLY. Stage times are medians over ``--repeats`` in-process
runs of ``run_check`` after a warm-up, taken from its progress callback. pymeshlab's
own work is ``MeshSet.load_new_mesh`` plus ``generate_sampling_montecarlo`` on the same
file, timed in the same process between the check runs. Peak memory: the maximum
resident set (wait4) of ``python -m scatter_cli check MESH -n COUNT`` and, for scale,
of ``python -m scatter_cli info MESH`` (imports and the loaded mesh).
"""

from __future__ import annotations

import argparse
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


def terrain(path, grid):
    import trimesh

    x, y = np.meshgrid(np.linspace(0, 100, grid), np.linspace(0, 100, grid))
    z = 5 * np.sin(x / 7) * np.cos(y / 11) + np.random.default_rng(0).normal(0, 0.3, x.shape)
    i = (np.arange(grid - 1)[:, None] * grid + np.arange(grid - 1)[None, :]).ravel()
    faces = np.r_[np.c_[i, i + 1, i + grid], np.c_[i + 1, i + grid + 1, i + grid]]
    trimesh.Trimesh(np.c_[x.ravel(), y.ravel(), z.ravel()], faces, process=False).export(path)
    return len(faces)


def check_stages(mesh, count):
    """{stage: seconds} of one run_check, from its progress callback."""
    from scatter_cli.commands.check import run_check

    marks = []
    run_check(mesh, count=count, seed=1, out=lambda line: None, progress=lambda s: marks.append((s, time.perf_counter())))
    out = {}
    for (name, t0), (_, t1) in zip(marks[:-1], marks[1:]):
        key = "exact regions" if name.startswith("exact regions") else name
        out[key] = out.get(key, 0.0) + t1 - t0
    out["total"] = marks[-1][1] - marks[0][1]
    return out


def pymeshlab_own(mesh, count):
    import pymeshlab

    t = time.perf_counter()
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(mesh))
    ms.generate_sampling_montecarlo(samplenum=count)
    return time.perf_counter() - t


def peak_mb(args):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-m", "scatter_cli", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    assert os.waitstatus_to_exitcode(status) in (0, 1), args
    return usage.ru_maxrss / 1024


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--grid", type=int, default=290)
    ap.add_argument("--count", type=int, default=50_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        mesh = Path(tmp) / "terrain.ply"
        faces = terrain(mesh, args.grid)
        check_stages(mesh, args.count)  # warm-up
        pymeshlab_own(mesh, args.count)
        runs, own = [], []
        for _ in range(args.repeats):
            runs.append(check_stages(mesh, args.count))
            own.append(pymeshlab_own(mesh, args.count))
        mem_check = peak_mb(["check", str(mesh), "-n", str(args.count)])
        mem_info = peak_mb(["info", str(mesh)])
    with open("/proc/loadavg") as f:
        load = f.read().split()[:3]
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    own_med = statistics.median(own)
    lines = [f"terrain {faces:,} faces, -n {args.count:,}; medians of {args.repeats} runs after a warm-up; "
             f"load average {' '.join(load)}", "", "| stage | s | / pymeshlab's own |", "|---|---:|---:|"]
    for k, v in med.items():
        lines.append(f"| {k} | {v:.3f} | {v / own_med:.1f}x |")
    lines += [f"| pymeshlab's own load + sampling | {own_med:.3f} | 1.0x |", "",
              f"peak resident memory: check {mem_check:.0f} MB, info {mem_info:.0f} MB "
              f"(check beyond info: {mem_check - mem_info:.0f} MB)"]
    text = "\n".join(lines)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")


if __name__ == "__main__":
    main()
