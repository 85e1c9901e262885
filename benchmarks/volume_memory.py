"""Peak memory of volume runs against their count: flat memory means chunks, not the count.

    PYTHONPATH=. python benchmarks/volume_memory.py [--mesh samples/skull.ply] [--counts 2e6,2e7]

Runs `scatter sample MESH --volume -n N -a sdf,inside -o OUT.ply` (and a near-surface run)
once per count in a child process of its own, and prints each child's peak resident
memory (ru_maxrss) and time, and the ratio of the peaks. Target: the peak at 2*10^7 within
1.5x of the peak at 2*10^6.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def peak_of(args):
    """(peak RSS in MB, seconds) of one child running ``args``."""
    code = ("import resource, subprocess, sys, time; t = time.perf_counter(); "
            "r = subprocess.run(sys.argv[1:]); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, time.perf_counter() - t); "
            "sys.exit(r.returncode)")
    env = dict(os.environ, PYTHONPATH=ROOT)
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, check=True)
    mb, seconds = out.stdout.split()
    return float(mb), float(seconds)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default=os.path.join(ROOT, "samples", "skull.ply"))
    ap.add_argument("--counts", default="2e6,2e7")
    args = ap.parse_args()
    counts = [int(float(c)) for c in args.counts.split(",")]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "out.ply")
        for label, extra in (("box", ["--volume"]), ("near", ["--near", "0.01", "--box-share", "0.1"])):
            peaks = []
            for n in counts:
                cmd = [sys.executable, "-m", "scatter_cli", "sample", args.mesh, *extra, "-n", str(n),
                       "-a", "sdf,inside", "-o", out, "-q"]
                mb, seconds = peak_of(cmd)
                peaks.append(mb)
                rows.append(f"| {label} | {n:,} | {mb:.0f} MB | {seconds:.1f} s |")
                os.unlink(out)
            rows.append(f"| {label} | peak ratio | {peaks[-1] / peaks[0]:.2f}x | |")
    print(f"mesh: {args.mesh}; load {open('/proc/loadavg').read().split()[:3]}; {time.strftime('%Y-%m-%d')}")
    print("| points | count | peak RSS | time |\n|---|---:|---:|---:|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
