"""How fast `scatter preview` draws contact sheets, and in how much memory.

    python benchmarks/preview.py [--repeats 3] [--json benchmarks/results/preview.json]

1. 300 binary PLY files of 2,048 points with normals (samples of the repo's meshes) to
   three sheets of 100 thumbnails at 256 px: thumbnails a second, start-up included
   (wall clock of the whole command, median of --repeats runs after a warm-up).
2. Peak resident memory of the command for 100 and for 300 such inputs (flat: pages
   are written as they fill).
3. One file of 10^7 points (binary PLY with normals, and NPY): seconds to preview it.
4. The peer: matplotlib's 3-D scatter (the Agg backend, no display), drawing the same
   thumbnails one figure each, in this process: thumbnails a second, and the ratio.

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
    """(seconds, peak RSS in MB) of one `scatter ARGS` process. The memory is GNU time's
    (%M): a child forked from this process would count this process's memory too."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONUNBUFFERED", "CI")}
    env["PYTHONPATH"] = str(ROOT)
    with tempfile.NamedTemporaryFile("r", suffix=".rss") as rss:
        t = time.perf_counter()
        proc = subprocess.run(["/usr/bin/time", "-f", "%M", "-o", rss.name, sys.executable, "-m", "scatter_cli",
                               *map(str, args)], env=env, stdin=subprocess.DEVNULL, stderr=subprocess.PIPE)
        seconds = time.perf_counter() - t
        peak = int(rss.read().split()[-1]) / 1024
    if proc.returncode != 0:
        raise SystemExit(f"scatter {' '.join(map(str, args))} failed: {proc.stderr.decode()}")
    return seconds, peak


def median_run(args, repeats):
    run(args)  # warm-up: the page cache, the imports
    times, peaks = zip(*(run(args) for _ in range(repeats)))
    return statistics.median(times), max(peaks)


def matplotlib_rate(folder, k=20, size=256):
    """Thumbnails a second of matplotlib's 3-D scatter on the first ``k`` files."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from scatter_cli.pointfiles import read_points

    files = sorted(folder.iterdir())[:k]
    t = time.perf_counter()
    for path in files:
        pts = read_points(path)
        fig = plt.figure(figsize=(size / 100, size / 100), dpi=100)
        ax = fig.add_subplot(projection="3d")
        ax.scatter(*pts.points.T, c=(pts.attributes["normal"] + 1) / 2, s=2, depthshade=True)
        ax.set_axis_off()
        fig.savefig(os.devnull, format="png")
        plt.close(fig)
    return k / (time.perf_counter() - t)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", default=None)
    opts = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        make_collection(tmp / "c300", 300)
        (tmp / "c100").mkdir()
        for p in sorted((tmp / "c300").iterdir())[:100]:
            os.link(p, tmp / "c100" / p.name)
        make_big(tmp)
        sheets = ["--per-page", "100", "--size", "256", "-o"]
        t300, rss300 = median_run(["preview", tmp / "c300", *sheets, tmp / "s300-{page}.png"], opts.repeats)
        t100, rss100 = median_run(["preview", tmp / "c100", *sheets, tmp / "s100-{page}.png"], opts.repeats)
        t_ply, rss_ply = median_run(["preview", tmp / "big.ply", "-o", tmp / "big-ply.png"], opts.repeats)
        t_npy, _ = median_run(["preview", tmp / "big.npy", "-o", tmp / "big-npy.png"], opts.repeats)
        t_one, _ = median_run(["preview", tmp / "c300" / "0000.ply", "-o", tmp / "one.png"], opts.repeats)
        peer = matplotlib_rate(tmp / "c300")
    rate = 300 / t300
    figures = {
        "load": open("/proc/loadavg").read().split()[:3], "cpus": os.cpu_count(), "repeats": opts.repeats,
        "collection_300_seconds": t300, "thumbnails_per_second": rate, "peak_rss_mb_100": rss100,
        "peak_rss_mb_300": rss300, "collection_100_seconds": t100, "one_file_seconds": t_one,
        "big_ply_seconds": t_ply, "big_ply_peak_rss_mb": rss_ply, "big_npy_seconds": t_npy,
        "matplotlib_thumbnails_per_second": peer, "ratio_to_matplotlib": rate / peer,
    }
    print(f"""| what | figure |
|---|---|
| 300 files of 2,048 points, 3 sheets of 100 at 256 px | {t300:.2f} s: {rate:.0f} thumbnails/s (goal >= 50) |
| same, 100 files, 1 sheet | {t100:.2f} s |
| one file, one thumbnail (mostly start-up) | {t_one:.2f} s |
| peak RSS, 100 / 300 inputs | {rss100:.0f} / {rss300:.0f} MB |
| 10^7-point binary PLY (240 MB) | {t_ply:.2f} s, peak RSS {rss_ply:.0f} MB (goal < 2 s) |
| 10^7-point NPY | {t_npy:.2f} s |
| matplotlib 3-D scatter, same thumbnails | {peer:.1f} thumbnails/s: scatter is {rate / peer:.0f}x faster |
| load (1, 5, 15 min) | {' '.join(figures['load'])} on {os.cpu_count()} CPUs |""")
    if opts.json:
        Path(opts.json).write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
