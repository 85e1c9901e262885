"""Write time per output format against binary PLY, and peak memory against the count.

    PYTHONPATH=. python benchmarks/write_formats.py [--count 10000000] [--runs 3] [--out benchmarks/write-formats-results.md]

1. Time (printed first): N points of samples/boxvertexcolors.glb are sampled once and held as chunks
   (2^17 points each); each format then writes the same chunks to a file in a temporary
   folder (on the same disk as the repo), alternating formats, --runs rounds; medians,
   and the ratio to binary PLY of the same round. Two layouts: xyz only, and xyz +
   normal + color. float32 coordinates for PLY/PCD/USD (what auto picks here); LAS/LAZ
   quantise float64 points (what the run gives them).
2. Memory (measured first): peak RSS (VmHWM) of a fresh process that samples and writes N/10 and N points
   (streamed, the whole pipeline): flat in the count means the same peak for both.
   USD holds every point by design (it cannot stream) and is measured for the record.
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

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

MESH = os.path.join(ROOT, "samples", "boxvertexcolors.glb")
FORMATS = [("ply", "ply"), ("pcd", "pcd"), ("las", "las"), ("laz", "laz"), ("usd", "usdc")]
LAYOUTS = {"xyz": "", "xyz+normal+color": "normal,color"}

CHILD = r"""
import sys, json
sys.path.insert(0, {root!r})
import scatter_cli.api as api
from scatter_cli.api import sampled_bounds
from scatter_cli.writers import run_precision, write_samples
fmt, suffix, count, attrs, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5]
run = api.prepare({mesh!r}, count, attributes=attrs, seed=1, precision=run_precision(fmt, "auto"))
write_samples(run.chunks(), out, fmt, run.layout, run.count, bounds=sampled_bounds(run.plan))
# VmHWM, not ru_maxrss: Linux keeps ru_maxrss across exec, so a child would report the
# peak of the (large) parent it was forked from
hwm = next(l for l in open("/proc/self/status") if l.startswith("VmHWM:"))
print(json.dumps(int(hwm.split()[1]) / 1024))
"""


def sampled_chunks(count, attrs, precision):
    import scatter_cli.api as api

    run = api.prepare(MESH, count, attributes=attrs, seed=1, precision=precision, chunk_size=1 << 17)
    from scatter_cli.api import sampled_bounds

    return list(run.chunks()), run.layout, sampled_bounds(run.plan)


def time_formats(count, runs, folder):
    from scatter_cli.writers import write_samples

    rows = []
    for name, attrs in LAYOUTS.items():
        data = {p: sampled_chunks(count, attrs, p) for p in ("float32", "float64")}
        times = {fmt: [] for fmt, _ in FORMATS}
        sizes = {}
        for _ in range(runs):
            for fmt, suffix in FORMATS:
                chunks, layout, bounds = data["float64" if fmt in ("las", "laz") else "float32"]
                out = os.path.join(folder, f"bench.{suffix}")
                t = time.perf_counter()
                write_samples(chunks, out, fmt, layout, count, bounds=bounds)
                times[fmt].append(time.perf_counter() - t)
                sizes[fmt] = os.path.getsize(out)
                os.unlink(out)
        ply = statistics.median(times["ply"])
        for fmt, _ in FORMATS:
            med = statistics.median(times[fmt])
            ratios = [t / p for t, p in zip(times[fmt], times["ply"])]
            rows.append({"layout": name, "format": fmt, "seconds": med, "ratio_to_ply": statistics.median(ratios),
                         "mb": sizes[fmt] / 1e6, "mpoints_per_s": count / med / 1e6, "all": times[fmt]})
        del data
        print(f"{name}: PLY {ply:.2f} s", file=sys.stderr)
    return rows


def peak_memory(count, folder):
    rows = []
    code = CHILD.format(root=ROOT, mesh=MESH)
    for name, attrs in LAYOUTS.items():
        for fmt, suffix in FORMATS:
            peaks = []
            for n in (count // 10, count):
                out = os.path.join(folder, f"mem.{suffix}")
                res = subprocess.run([sys.executable, "-c", code, fmt, suffix, str(n), attrs, out], check=True,
                                     capture_output=True, text=True)
                peaks.append(float(res.stdout.strip()))
                os.unlink(out)
            rows.append({"layout": name, "format": fmt, "peak_mb_small": peaks[0], "peak_mb_large": peaks[1]})
            print(f"{name} {fmt}: {peaks[0]:.0f} -> {peaks[1]:.0f} MB", file=sys.stderr)
    return rows


def markdown(count, runs, timing, memory):
    lines = [f"# Write time per format, {count:,} points (medians of {runs} alternating rounds)", "",
             "| layout | format | seconds | x binary PLY | Mpoints/s | file MB |", "|---|---|---|---|---|---|"]
    for r in timing:
        lines.append(f"| {r['layout']} | {r['format']} | {r['seconds']:.2f} | {r['ratio_to_ply']:.2f} | "
                     f"{r['mpoints_per_s']:.1f} | {r['mb']:.0f} |")
    lines += ["", f"# Peak RSS of sample + write, {count // 10:,} against {count:,} points", "",
              "| layout | format | peak MB (N/10) | peak MB (N) |", "|---|---|---|---|"]
    for r in memory:
        lines.append(f"| {r['layout']} | {r['format']} | {r['peak_mb_small']:.0f} | {r['peak_mb_large']:.0f} |")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=10_000_000)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "write-formats-results.md"))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(dir=ROOT) as folder:
        memory = peak_memory(args.count, folder)
        timing = time_formats(args.count, args.runs, folder)
    text = markdown(args.count, args.runs, timing, memory)
    with open(args.out, "w") as f:
        f.write(text)
    with open(os.path.splitext(args.out)[0] + ".json", "w") as f:
        json.dump({"count": args.count, "runs": args.runs, "timing": timing, "memory": memory}, f, indent=1)
    print(text)


if __name__ == "__main__":
    main()
