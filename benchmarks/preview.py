"""How fast `scatter preview` draws contact sheets, and in how much memory.

    python benchmarks/preview.py [--repeats 3] [--json benchmarks/results/preview.json]

1. 300 binary PLY files of 2,048 points with normals (samples of the repo's meshes) to
   three sheets of 100 thumbnails at 256 px: thumbnails a second, start-up included
   (wall clock and CPU time of the whole command, medians of --repeats runs after a
   warm-up; on a shared machine the CPU time tells what free cores would give).
2. Peak resident memory of the command for 100, 200 and 300 such inputs (flat: pages
   are written as they fill, one drawn while the one before is encoded).
3. One file of 10^7 points (binary PLY with normals, and NPY): seconds to preview it.
4. The peer: matplotlib's 3-D scatter (the Agg backend, no display), drawing the same
   thumbnails one figure each, in this process (no start-up): thumbnails a second of
   wall clock and of CPU time, and scatter's ratio to it.

Figures are printed as Markdown and written as JSON (--json).
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

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

MESHES = ["spot_triangulated.obj", "koala.obj", "skull.ply", "hemisphere.off", "icosahedron_binary.stl",
          "moebius-160-10.ply", "pediment_join_plate_12.stl"]


def write_ply(path, points, normals):
    rows = np.empty(len(points), dtype=[(c, "<f4") for c in ("x", "y", "z", "nx", "ny", "nz")])
    for j, c in enumerate("xyz"):
        rows[c] = points[:, j]
        rows["n" + c] = normals[:, j]
    head = ["ply", "format binary_little_endian 1.0", "comment made by scatter", f"element vertex {len(points)}"]
    head += [f"property float {c}" for c in rows.dtype.names] + ["end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(head) + "\n").encode())
        f.write(rows.tobytes())


def make_collection(folder, count, points=2048):
    """``count`` PLY files: the repo's meshes sampled with seeds 0, 1, ..., in turn."""
    from scatter_cli import sample

    folder.mkdir(parents=True, exist_ok=True)
    for i in range(count):
        s = sample(ROOT / "samples" / MESHES[i % len(MESHES)], points, seed=i, attributes="normal")
        write_ply(folder / f"{i:04d}.ply", s.points, s.normal)


def make_big(folder, n=10_000_000):
    """A sphere of ``n`` points with normals, as binary PLY and NPY (float32 columns)."""
    v = np.random.default_rng(0).standard_normal((n, 3)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    write_ply(folder / "big.ply", v, v)
    rows = np.empty(n, dtype=[(c, "<f4") for c in ("x", "y", "z", "nx", "ny", "nz")])
    for j, c in enumerate("xyz"):
        rows[c], rows["n" + c] = v[:, j], v[:, j]
    np.save(folder / "big.npy", rows)


def run(args):
    """(wall seconds, CPU seconds, peak RSS in MB) of one `scatter ARGS` process, from
    GNU time (a child forked from this process would count this process's memory too)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONUNBUFFERED", "CI")}
    env["PYTHONPATH"] = str(ROOT)
    with tempfile.NamedTemporaryFile("r", suffix=".rss") as rss:
        t = time.perf_counter()
        proc = subprocess.run(["/usr/bin/time", "-f", "%U %S %M", "-o", rss.name, sys.executable, "-m", "scatter_cli",
                               *map(str, args)], env=env, stdin=subprocess.DEVNULL, stderr=subprocess.PIPE)
        seconds = time.perf_counter() - t
        user, system, peak = rss.read().split()[-3:]
    if proc.returncode != 0:
        raise SystemExit(f"scatter {' '.join(map(str, args))} failed: {proc.stderr.decode()}")
    return seconds, float(user) + float(system), int(peak) / 1024


def median_run(args, repeats):
    """Medians of wall and CPU seconds, and the largest peak RSS, of ``repeats`` runs after
    a warm-up (the page cache, the imports)."""
    run(args)
    walls, cpus, peaks = zip(*(run(args) for _ in range(repeats)))
    return statistics.median(walls), statistics.median(cpus), max(peaks)


def matplotlib_rate(folder, k=20, size=256):
    """Thumbnails a second (wall clock, CPU time) of matplotlib's 3-D scatter on the first ``k`` files."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from scatter_cli.writers.pointfiles import read_points

    files = sorted(folder.iterdir())[:k]
    t, c = time.perf_counter(), time.process_time()
    for path in files:
        pts = read_points(path)
        fig = plt.figure(figsize=(size / 100, size / 100), dpi=100)
        ax = fig.add_subplot(projection="3d")
        ax.scatter(*pts.points.T, c=(pts.attributes["normal"] + 1) / 2, s=2, depthshade=True)
        ax.set_axis_off()
        fig.savefig(os.devnull, format="png")
        plt.close(fig)
    return k / (time.perf_counter() - t), k / (time.process_time() - c)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", default=None)
    opts = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        make_collection(tmp / "c300", 300)
        for k in (100, 200):
            (tmp / f"c{k}").mkdir()
            for p in sorted((tmp / "c300").iterdir())[:k]:
                os.link(p, tmp / f"c{k}" / p.name)
        make_big(tmp)
        sheets = ["--per-page", "100", "--size", "256", "-o"]
        runs = {k: median_run(["preview", tmp / f"c{k}", *sheets, tmp / f"s{k}-{{page}}.png"], opts.repeats)
                for k in (100, 200, 300)}
        big_ply = median_run(["preview", tmp / "big.ply", "-o", tmp / "big-ply.png"], opts.repeats)
        big_npy = median_run(["preview", tmp / "big.npy", "-o", tmp / "big-npy.png"], opts.repeats)
        one = median_run(["preview", tmp / "c300" / "0000.ply", "-o", tmp / "one.png"], opts.repeats)
        peer = matplotlib_rate(tmp / "c300")
    wall, cpu, _ = runs[300]
    figures = {
        "load": open("/proc/loadavg").read().split()[:3], "cpus": os.cpu_count(), "repeats": opts.repeats,
        "runs": {f"collection_{k}": dict(zip(("wall_s", "cpu_s", "peak_rss_mb"), v)) for k, v in runs.items()},
        "thumbnails_per_wall_second": 300 / wall, "thumbnails_per_cpu_second": 300 / cpu,
        "one_file": dict(zip(("wall_s", "cpu_s", "peak_rss_mb"), one)),
        "big_ply": dict(zip(("wall_s", "cpu_s", "peak_rss_mb"), big_ply)),
        "big_npy": dict(zip(("wall_s", "cpu_s", "peak_rss_mb"), big_npy)),
        "matplotlib_thumbnails_per_wall_second": peer[0], "matplotlib_thumbnails_per_cpu_second": peer[1],
    }
    rss = " / ".join(f"{runs[k][2]:.0f}" for k in (100, 200, 300))
    print(f"""| what | wall s | CPU s | figure |
|---|---|---|---|
| 300 files of 2,048 points, 3 sheets of 100 at 256 px | {wall:.2f} | {cpu:.2f} | {300 / wall:.0f} thumbnails/s of wall clock, {300 / cpu:.0f} per CPU second (goal >= 50) |
| 100 / 200 files | {runs[100][0]:.2f} / {runs[200][0]:.2f} | {runs[100][1]:.2f} / {runs[200][1]:.2f} | |
| peak RSS at 100 / 200 / 300 inputs | | | {rss} MB |
| one file, one thumbnail (start-up) | {one[0]:.2f} | {one[1]:.2f} | |
| 10^7-point binary PLY (240 MB) | {big_ply[0]:.2f} | {big_ply[1]:.2f} | peak RSS {big_ply[2]:.0f} MB (goal < 2 s) |
| 10^7-point NPY | {big_npy[0]:.2f} | {big_npy[1]:.2f} | peak RSS {big_npy[2]:.0f} MB |
| matplotlib 3-D scatter, same thumbnails, in-process | | | {peer[0]:.1f} thumbnails/s of wall clock, {peer[1]:.1f} per CPU second; scatter {300 / wall / peer[0]:.1f}x and {300 / cpu / peer[1]:.1f}x that |
| load (1, 5, 15 min) at the end | | | {' '.join(figures['load'])} on {os.cpu_count()} CPUs |""")
    if opts.json:
        Path(opts.json).write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
