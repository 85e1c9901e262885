"""Write time per output format against binary PLY and against the LAZ compressor alone,
and peak memory against the count: every figure of issue 16's benchmark in one run.

    PYTHONPATH=. python benchmarks/write_formats.py [--count 10000000] [--runs 5] [--out benchmarks/write-formats-results.md]

1. Memory (measured first): peak RSS (VmHWM) of a fresh process that samples and writes
   N/10, N and 3N points (streamed, the whole pipeline): flat in the count means the same
   peak for all. USD holds every point by design (it cannot stream) and is measured for the
   record, at N/10 and N only.
2. Time: N points of samples/boxvertexcolors.glb are sampled once and held as chunks
   (2^17 points each); each format then writes the same chunks to a file in a temporary
   folder (on the same disk as the repo), alternating formats, --runs rounds; medians of
   wall and CPU seconds (the process's user + system time, all threads: less sensitive to
   other jobs on the machine), and the ratio to binary PLY of the same round. Two layouts:
   xyz only, and xyz + normal + color. float32 coordinates for PLY/PCD/USD (what auto
   picks here); LAS/LAZ quantise float64 points (what the run gives them). Three
   references, in the same rounds:
   - ``lazrs alone``: the very point records our LAZ writer makes, built beforehand and
     held in memory, compressed through laspy's writer (LazBackend.LazrsParallel, the
     backend ours uses) in the same chunks: the compressor's own speed. ``laz`` rows give
     their ratio to it;
   - ``lazrs alone, 1 thread``: the same with LazBackend.Lazrs;
   - ``ply bytes`` and ``las bytes``: as many bytes as the PLY (LAS) file has, written with
     os.write in 1 MiB blocks from one buffer that stays in the cache, the same way for
     both: the part of a write that is the file system's, whatever the format code does.
     Their ratio is the floor of LAS's ratio to PLY for a writer on one core;
   - ``las, 1 thread``: our LAS writer with its blocks written in turn on the main thread
     instead of on its writer thread (what the writer costs without the second core).
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

import numpy as np

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


def held_records(chunks, layout, count, bounds):
    """The LAS point records of ``chunks``, as our writer makes them (one array per chunk)."""
    from scatter_cli.writers.las import LasWriter

    writer = LasWriter(None, layout, count, bounds)
    return [writer.records(c).copy() for c in chunks], writer.header_


def lazrs_alone(records, header, out, backend_name):
    import laspy

    backend = getattr(laspy.LazBackend, backend_name)
    with laspy.open(out, mode="w", header=header, do_compress=True, laz_backend=backend) as f:
        for r in records:
            f.point_writer.write_points(laspy.PackedPointRecord(r, header.point_format))


def raw_bytes(size, out, block=1 << 20):
    from scatter_cli.writers.las import file_descriptor, write_all
    from scatter_cli.writers import open_output

    data = np.ones(block, np.uint8)  # written pages: a bytes(block) of zeros wrote 4-6x slower here
    with open_output(out) as f:
        fd = file_descriptor(f)
        for start in range(0, size, block):
            write_all(f, fd, data[: min(block, size - start)])


def settle(size, folder):
    """Write and delete ``size`` bytes, untimed, just before each timed write, so that every
    format finds the same state: memory the page cache has just given back. This machine
    is a VM whose idle memory goes back to the host (DAMON pageout of pages unused for a
    minute, virtio-balloon free page reporting): a write whose page-cache pages come from
    that memory pays a host fault per page, and which writes do depended on what ran
    before them (300 MB: 0.06 s of CPU just after a settle, 0.6 to 1.1 s after a pause of
    10 to 30 s; docs/outputs.md)."""
    path = os.path.join(folder, "settle.bin")
    raw_bytes(size, path)
    os.unlink(path)


class _InTurn:
    """An executor that runs what it is given at once, on the calling thread."""

    def submit(self, fn, *args):
        from concurrent.futures import Future

        fn(*args)
        done = Future()
        done.set_result(None)
        return done

    def shutdown(self, wait=True):
        pass


def las_in_turn(chunks, out, layout, count, bounds):
    """Our LAS writer with each block written on the main thread, in turn."""
    from scatter_cli.writers.las import LasWriter
    from scatter_cli.writers import open_output

    with open_output(out) as stream:
        writer = LasWriter(stream, layout, count, bounds)
        writer.header()
        writer._thread.shutdown()
        writer._thread = _InTurn()
        for chunk in chunks:
            writer.write(chunk)
        writer.finish()
        writer.close()


def timed(fn):
    wall, cpu = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - wall, time.process_time() - cpu


def entries(count, data, records, header, sizes):
    """[(name, write(out))] in the order of a round: each reference next to the format it
    is compared with, so that both meet the same state of the machine."""
    from scatter_cli.writers import write_samples

    def fmt_writer(fmt):
        chunks, layout, bounds = data["float64" if fmt in ("las", "laz") else "float32"]
        return lambda out: write_samples(chunks, out, fmt, layout, count, bounds=bounds)

    chunks, layout, bounds = data["float64"]
    out = [(fmt, fmt_writer(fmt)) for fmt, _ in FORMATS]
    out.insert(0, ("ply bytes", lambda path: raw_bytes(sizes["ply"], path)))
    out.insert(3, ("las bytes", lambda path: raw_bytes(sizes["las"], path)))
    out.insert(5, ("las, 1 thread", lambda path: las_in_turn(chunks, path, layout, count, bounds)))
    out[7:7] = [("lazrs alone", lambda path: lazrs_alone(records, header, path, "LazrsParallel")),
                ("lazrs alone, 1 thread", lambda path: lazrs_alone(records, header, path, "Lazrs"))]
    return out


def time_formats(count, runs, folder):
    rows = []
    suffix = dict(FORMATS)
    for name, attrs in LAYOUTS.items():
        data = {p: sampled_chunks(count, attrs, p) for p in ("float32", "float64")}
        records, header = held_records(*data["float64"][:2], count, data["float64"][2])
        sizes = {}
        order = entries(count, data, records, header, sizes)
        for fmt in ("ply", "las"):  # untimed: the sizes the raw references write
            out = os.path.join(folder, f"bench.{fmt}")
            dict(order)[fmt](out)
            sizes[fmt] = os.path.getsize(out)
            os.unlink(out)
        wall, cpu = ({k: [] for k, _ in order} for _ in range(2))
        for _ in range(runs):
            for key, write in order:
                settle(sizes["las"], folder)
                out = os.path.join(folder, f"bench.{suffix.get(key, 'laz')}")
                w, c = timed(lambda: write(out))
                wall[key].append(w), cpu[key].append(c)
                sizes[key] = os.path.getsize(out)
                os.unlink(out)
        for key, _ in order:
            rows.append({"layout": name, "format": key, "seconds": statistics.median(wall[key]),
                         "cpu_seconds": statistics.median(cpu[key]),
                         "ratio_to_ply": median_ratio(wall[key], wall["ply"]),
                         "cpu_ratio_to_ply": median_ratio(cpu[key], cpu["ply"]),
                         "ratio_to_lazrs": median_ratio(wall[key], wall["lazrs alone"]) if key == "laz" else None,
                         "cpu_ratio_to_lazrs": median_ratio(cpu[key], cpu["lazrs alone"]) if key == "laz" else None,
                         "mb": sizes[key] / 1e6, "mpoints_per_s": count / statistics.median(wall[key]) / 1e6,
                         "all": wall[key], "all_cpu": cpu[key]})
        del data, records
        print(f"{name}: PLY {statistics.median(wall['ply']):.2f} s", file=sys.stderr)
    return rows


def median_ratio(times, base):
    return statistics.median(t / b for t, b in zip(times, base))


def peak_memory(count, folder):
    """Peak RSS (MB) of sampling and writing N/10, N and 3N points (USD: N/10 and N only)."""
    rows = []
    code = CHILD.format(root=ROOT, mesh=MESH)
    for name, attrs in LAYOUTS.items():
        for fmt, suffix in FORMATS:
            peaks = []
            for n in memory_counts(count, fmt):
                out = os.path.join(folder, f"mem.{suffix}")
                res = subprocess.run([sys.executable, "-c", code, fmt, suffix, str(n), attrs, out], check=True,
                                     capture_output=True, text=True)
                peaks.append(float(res.stdout.strip()))
                os.unlink(out)
            rows.append({"layout": name, "format": fmt, "counts": memory_counts(count, fmt), "peak_mb": peaks})
            print(f"{name} {fmt}: {' -> '.join(f'{p:.0f}' for p in peaks)} MB", file=sys.stderr)
    return rows


def memory_counts(count, fmt):
    return [count // 10, count] + ([] if fmt == "usd" else [3 * count])


def markdown(count, runs, timing, memory):
    lines = [f"# Write time per format, {count:,} points (medians of {runs} alternating rounds)", "",
             "| layout | format | seconds | x binary PLY | CPU seconds | CPU x PLY | x lazrs alone (wall / CPU) "
             "| Mpoints/s | file MB |", "|---|---|---|---|---|---|---|---|---|"]
    for r in timing:
        vs = f"{r['ratio_to_lazrs']:.2f} / {r['cpu_ratio_to_lazrs']:.2f}" if r["ratio_to_lazrs"] else ""
        lines.append(f"| {r['layout']} | {r['format']} | {r['seconds']:.2f} | {r['ratio_to_ply']:.2f} | "
                     f"{r['cpu_seconds']:.2f} | {r['cpu_ratio_to_ply']:.2f} | {vs} | {r['mpoints_per_s']:.1f} | "
                     f"{r['mb']:.0f} |")
    lines += ["", f"# Peak RSS of sample + write, {count // 10:,}, {count:,} and {3 * count:,} points", "",
              "| layout | format | peak MB (N/10) | peak MB (N) | peak MB (3N) |", "|---|---|---|---|---|"]
    for r in memory:
        peaks = [f"{p:.0f}" for p in r["peak_mb"]] + ["not measured"] * (3 - len(r["peak_mb"]))
        lines.append(f"| {r['layout']} | {r['format']} | {' | '.join(peaks)} |")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=10_000_000)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "write-formats-results.md"))
    args = ap.parse_args()
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(dir=ROOT) as folder:
        memory = peak_memory(args.count, folder)
        timing = time_formats(args.count, args.runs, folder)
    load = [round(x, 1) for x in load + os.getloadavg()]
    text = markdown(args.count, args.runs, timing, memory) + f"\nLoad average (1, 5, 15 min) at the start and the end: {load[:3]}, {load[3:]}\n"
    with open(args.out, "w") as f:
        f.write(text)
    with open(os.path.splitext(args.out)[0] + ".json", "w") as f:
        json.dump({"count": args.count, "runs": args.runs, "load": load, "timing": timing, "memory": memory}, f, indent=1)
    print(text)


if __name__ == "__main__":
    main()
