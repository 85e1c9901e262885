"""Collections: `scatter batch` against its peers on 300+ small real meshes.

    PYTHONPATH=$PWD python benchmarks/batch.py [--copies 30] [--repeats 3] [--out benchmarks/batch-results.md]

The collection: copies of the small meshes of samples/ in OBJ, OFF, PLY, STL and GLB,
each copy scaled and moved so that no two files are alike, in a temporary folder. Each
mesh: 2,048 points with normals, written as binary PLY. Timed as whole commands,
start-up included, medians of back-to-back runs:

- `scatter batch DIR -o OUT/{rel}.ply -n 2048 -a normal -j 2`;
- a trimesh script: multiprocessing.Pool(2) mapping load, sample_surface, write PLY;
- a shell loop of `scatter sample` (over the first --loop meshes, scaled to the whole);
- `scatter batch --engine dask` on a local cluster of two one-thread workers (the cluster
  started once, before the runs, as a user's cluster would be).

Also: the resident memory of each batch worker against the meshes done (flat: no growth
with the collection) and, in one process, where a mesh's time goes (load, sample, write).
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SMALL = ["icosahedron_binary.stl", "moebius-160-10.ply", "hemisphere.off", "narrow_triangles.obj",
         "pediment_join_plate_12.stl", "spot_triangulated.obj", "boxtextured.glb", "boxvertexcolors.glb",
         "cesiummilktruck.glb", "skull.ply", "koala.obj"]
SUFFIXES = ["obj", "off", "ply", "stl", "glb"]
COUNT = 2048
TRIMESH_SCRIPT = r'''
import sys, multiprocessing, numpy as np, trimesh

def one(job):
    src, dst = job
    mesh = trimesh.load(src, force="mesh", process=False)
    points, face = trimesh.sample.sample_surface(mesh, %d)
    normals = mesh.face_normals[face]
    rows = np.empty(len(points), dtype=[(c, "<f4") for c in ("x", "y", "z", "nx", "ny", "nz")])
    for i, c in enumerate("xyz"):
        rows[c] = points[:, i]
        rows["n" + c] = normals[:, i]
    header = "ply\nformat binary_little_endian 1.0\nelement vertex %%d\n" %% len(rows)
    header += "".join("property float %%s\n" %% c for c in rows.dtype.names) + "end_header\n"
    with open(dst, "wb") as f:
        f.write(header.encode())
        f.write(rows.tobytes())

if __name__ == "__main__":
    lines = open(sys.argv[1]).read().split("\n")
    jobs = [tuple(l.split("\t")) for l in lines if l]
    with multiprocessing.Pool(2) as pool:
        pool.map(one, jobs, chunksize=1)
''' % COUNT


def make_collection(folder, copies):
    """len(SMALL) * copies meshes, each scaled and moved differently, suffixes in turn."""
    import trimesh

    rng = np.random.default_rng(0)
    paths = []
    for name in SMALL:
        mesh = trimesh.load(ROOT / "samples" / name, force="mesh", process=False)
        for c in range(copies):
            m = mesh.copy()
            m.apply_scale(float(rng.uniform(0.5, 2.0)))
            m.apply_translation(rng.uniform(-10, 10, 3))
            suffix = SUFFIXES[(c + len(paths)) % len(SUFFIXES)]
            path = folder / f"{Path(name).stem}-{c:03d}.{suffix}"
            m.export(path)
            paths.append(path)
    return paths


def run(cmd, **kw):
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, **kw)
    return time.perf_counter() - t


def scatter(*args):
    return [sys.executable, "-m", "scatter_cli", *map(str, args)]


def watch_workers(parent_pid, out_dir, samples):
    """Sample (meshes written, RSS MB of each worker process) until the parent exits."""
    from scatter_cli.worker import resident_bytes

    while os.path.exists(f"/proc/{parent_pid}"):
        kids = children(parent_pid)
        done = sum(1 for _ in os.scandir(out_dir)) if out_dir.exists() else 0
        samples.append((done, [resident_bytes(k) / 2**20 for k in kids]))
        time.sleep(0.05)


def children(pid):
    """Pids whose parent is ``pid`` (from /proc/*/stat: /proc/PID/task/PID/children needs
    a kernel option)."""
    found = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat") as f:
                    if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                        found.append(int(name))
            except (OSError, ValueError, IndexError):
                pass
    return found


def batch_with_memory(src, out):
    shutil.rmtree(out, ignore_errors=True)
    samples = []
    t = time.perf_counter()
    proc = subprocess.Popen(scatter("batch", src, "-o", f"{out}/{{rel}}.ply", "-n", COUNT, "-a", "normal", "-j", 2, "-q"),
                            stdin=subprocess.DEVNULL)
    watcher = threading.Thread(target=watch_workers, args=(proc.pid, out, samples))
    watcher.start()
    assert proc.wait() == 0
    elapsed = time.perf_counter() - t
    watcher.join()
    return elapsed, samples


def memory_profile(samples, total):
    """Peak worker RSS over each fifth of the collection."""
    fifths = []
    for q in range(5):
        lo, hi = q * total / 5, (q + 1) * total / 5
        rss = [max(r) for done, r in samples if lo <= done < hi and r]
        fifths.append(max(rss) if rss else float("nan"))
    return fifths


def start_cluster():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", str(port), "--no-dashboard"], **quiet)]
    procs += [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                                "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"], **quiet) for _ in range(2)]
    import distributed

    with distributed.Client(address, timeout=60) as c:
        c.wait_for_workers(2, timeout=120)
    return address, procs


def stage_times(paths):
    """Median seconds per mesh of load (+ plan), sample and write, in this process."""
    from scatter_cli import api
    from scatter_cli.writers import write_samples

    out = Path(tempfile.mkdtemp())
    load, samp, write = [], [], []
    for p in paths:
        t0 = time.perf_counter()
        run = api.prepare(str(p), COUNT, attributes="normal")
        t1 = time.perf_counter()
        chunks = list(run.chunks())
        t2 = time.perf_counter()
        write_samples(chunks, out / "x.ply", "ply", run.layout, run.size)
        t3 = time.perf_counter()
        load.append(t1 - t0)
        samp.append(t2 - t1)
        write.append(t3 - t2)
    shutil.rmtree(out)
    return {k: (statistics.median(v), statistics.mean(v)) for k, v in
            (("load", load), ("sample", samp), ("write", write))}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--copies", type=int, default=28, help="copies of each sample mesh")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--loop", type=int, default=20, help="meshes in the timed shell loop")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    os.environ.setdefault("PYTHONPATH", str(ROOT))
    work = Path(tempfile.mkdtemp(prefix="scatter-batch-bench-"))
    try:
        src = work / "meshes"
        src.mkdir()
        paths = make_collection(src, args.copies)
        n = len(paths)
        jobs_file = work / "jobs.tsv"
        jobs_file.write_text("".join(f"{p}\t{work / 'tm' / (p.stem + '.ply')}\n" for p in paths))
        (work / "tm").mkdir()
        script = work / "tm_pool.py"
        script.write_text(TRIMESH_SCRIPT)
        address, cluster = start_cluster()
        times = {"batch": [], "trimesh": [], "dask": []}
        memory = None
        try:
            for r in range(args.repeats):
                t, samples = batch_with_memory(src, work / "out")
                times["batch"].append(t)
                memory = memory or memory_profile(samples, n)
                times["trimesh"].append(run([sys.executable, str(script), str(jobs_file)]))
                shutil.rmtree(work / "dask", ignore_errors=True)
                times["dask"].append(run(scatter("batch", src, "-o", f"{work}/dask/{{rel}}.ply", "-n", COUNT, "-a",
                                                 "normal", "--engine", "dask", "--scheduler", address, "-q")))
        finally:
            for p in reversed(cluster):
                p.kill()
                p.wait()
        subset = paths[:: max(1, n // args.loop)][: args.loop]
        loop = " ; ".join(f"{sys.executable} -m scatter_cli sample {p} -n {COUNT} -a normal -o {work}/loop.ply"
                          for p in subset)
        t_loop = run(["sh", "-c", loop]) * n / len(subset)
        stages = stage_times(paths)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    med = {k: statistics.median(v) for k, v in times.items()}
    rate = {k: n / v for k, v in med.items()}
    rate["loop"] = n / t_loop
    lines = [
        f"# scatter batch: {n} meshes, {COUNT} points with normals each (binary PLY)",
        "",
        f"Command: `PYTHONPATH=$PWD python benchmarks/batch.py --copies {args.copies} --repeats {args.repeats}`"
        f" ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; load average {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} CPUs)",
        "",
        "| run | seconds (median) | meshes/s | scatter batch -j 2 is |",
        "|---|---|---|---|",
        f"| scatter batch -j 2 | {med['batch']:.2f} | {rate['batch']:.1f} | 1 |",
        f"| trimesh + multiprocessing.Pool(2) | {med['trimesh']:.2f} | {rate['trimesh']:.1f} | "
        f"{rate['batch'] / rate['trimesh']:.2f}x faster |",
        f"| shell loop of scatter sample ({len(subset)} timed, scaled) | {t_loop:.1f} | {rate['loop']:.2f} | "
        f"{rate['batch'] / rate['loop']:.1f}x faster |",
        f"| scatter batch --engine dask (2 workers, 1 thread each) | {med['dask']:.2f} | {rate['dask']:.1f} | "
        f"{med['dask'] / med['batch']:.2f}x the time |",
        "",
        "All runs: " + "; ".join(f"{k} " + ", ".join(f"{t:.2f}" for t in v) for k, v in times.items()),
        "",
        "Peak resident memory of a batch worker (MB) over each fifth of the collection: "
        + ", ".join(f"{m:.0f}" for m in memory),
        "",
        "Time per mesh in one process (median / mean, ms): "
        + ", ".join(f"{k} {a * 1e3:.1f} / {b * 1e3:.1f}" for k, (a, b) in stages.items()),
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
