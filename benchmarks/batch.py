"""Collections: `scatter batch` against its peers on 300+ small real meshes.

    NUMPY_MADVISE_HUGEPAGE=0 PYTHONPATH=$PWD python benchmarks/batch.py [--meshes 304] [--repeats 3]
        [--no-dask] [--settle 60] [--folder DIR] [--out FILE]

The collection: --meshes copies of the small untextured meshes of samples/ (not the large
skull and koala, whose sampling time would hide the fixed costs) in OBJ, OFF, PLY, STL and GLB,
each copy scaled and moved so that no two files are alike, in a temporary folder, listed
in an interleaved order (copy 0 of every mesh, then copy 1, ...) so that every fifth of
the run holds the same mix of meshes. Every command runs once before the timed rounds
(a warm-up), then the rounds run back to back; the commands run with Python's bytecode
cache on (PYTHONDONTWRITEBYTECODE unset), as an installed package runs. Each mesh: 2,048 points with normals, written as
binary PLY. Timed as whole commands, start-up included, medians of back-to-back runs:

- `scatter batch --from-list LIST -o OUT/{stem}.ply -n 2048 -a normal -j 2`: the time
  includes Python's start-up, the imports, starting the two worker processes (forked
  from the command after its imports) and stopping them;
- a trimesh script: multiprocessing.Pool(2) mapping load, sample_surface, write PLY
  (trimesh imports SciPy when it is installed: the report says whether it was);
- each of the two again, over the outputs of a run before (scatter replaces each file
  through a new temporary file, the script rewrites it in place), after all the fresh rounds.

Every fresh run writes into a new, empty folder, and nothing is deleted before the end:
on ext4 without a journal (this machine's root file system), for 60 s after files were
deleted (360 s while their inode table is not yet written back), creating a file skips
the recently freed inodes, at a cost that grows with their number: several times the
usual cost per file after a few thousand deletions. That adds the same time per file to
both peers and hides their difference. For the same reason the timing starts --settle
seconds after the collection is written (a run of this benchmark just before deletes its
files at its end; so does a test run). --folder puts the work on another file system:
a tmpfs (/dev/shm) has no such history.
- a shell loop of `scatter sample` (over the first --loop meshes, scaled to the whole);
- `scatter batch --engine dask` on a local cluster of two one-thread workers started
  before the timing (`dask scheduler`, `dask worker --nthreads 1`): the time includes the
  command's start-up, importing dask.distributed, connecting, the tasks and closing the
  client. Twice per fresh cluster: the first batch also starts each Dask worker's sampling
  process (as -j 2 starts its workers); a later batch finds them running (a long-lived
  cluster's usual case). Starting the cluster itself is timed on its own.

Also: the fixed cost of a run (a batch of one mesh, each engine) against one `scatter
sample` of that mesh (the goal: a batch's within 0.1 s of it), the CPU seconds each
run costs by process (the command with the workers it waits for; the Dask scheduler,
workers and their sampling processes), the peak resident memory of each batch worker
over each fifth of the collection (VmHWM, reset at each fifth through
/proc/PID/clear_refs: exact, no polling gaps) and, in one process, where a mesh's time
goes (load, sample, write).
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
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
# not the textured boxtextured.glb and cesiummilktruck.glb either: trimesh decodes their
# textures on load (2.5 s for the truck), which scatter does not need: the peer would lose
# on work it need not do
SMALL = ["icosahedron_binary.stl", "moebius-160-10.ply", "hemisphere.off", "narrow_triangles.obj",
         "pediment_join_plate_12.stl", "spot_triangulated.obj", "boxvertexcolors.glb"]
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
    out = sys.argv[2]
    sources = [l for l in open(sys.argv[1]).read().split("\n") if l]
    jobs = [(src, "%%s/%%s.ply" %% (out, src.rsplit("/", 1)[-1].rsplit(".", 1)[0])) for src in sources]
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
            # an OBJ as the sample is, with no material library (trimesh would add one for
            # the UVs, and a material's OBJ takes the slow way through trimesh)
            m.export(path, **({"include_texture": False} if suffix == "obj" else {}))
            paths.append(path)
    return [paths[i * copies + c] for c in range(copies) for i in range(len(SMALL))]  # interleaved


def run(cmd, **kw):
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, **kw)
    return time.perf_counter() - t


def scatter(*args):
    return [sys.executable, "-m", "scatter_cli", *map(str, args)]


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


def peak_mb(pid, reset=False):
    """The process's peak resident memory (VmHWM) in MB, then (``reset``) start it again."""
    try:
        with open(f"/proc/{pid}/status") as f:
            hwm = next(int(line.split()[1]) / 1024 for line in f if line.startswith("VmHWM:"))
        if reset:
            with open(f"/proc/{pid}/clear_refs", "w") as f:
                f.write("5")
        return hwm
    except (OSError, StopIteration):
        return None


def outputs_done(folder):
    try:
        return sum(1 for e in os.scandir(folder) if not e.name.startswith("."))
    except OSError:
        return 0


def batch_memory(listing, out, total):
    """Peak resident MB of each batch worker over each fifth of the collection:
    {pid: [MB per fifth]} (a worker's peak is read every 10 ms and reset at each fifth)."""
    shutil.rmtree(out, ignore_errors=True)
    proc = subprocess.Popen(scatter("batch", "--from-list", listing, "-o", f"{out}/{{stem}}.ply", "-n", COUNT, "-a",
                                    "normal", "-j", 2, "-q"), stdin=subprocess.DEVNULL)
    peaks, workers, fifth, scanned = {}, [], 0, 0.0
    while proc.poll() is None:
        if time.monotonic() - scanned > 0.2:
            workers, scanned = children(proc.pid), time.monotonic()
        done = outputs_done(out)
        boundary = done >= (fifth + 1) * total / 5 and fifth < 4
        for pid in workers:
            mb = peak_mb(pid, reset=boundary)
            if mb is not None:
                peaks.setdefault(pid, [float("nan")] * 5)[fifth] = mb
        fifth += boundary
        time.sleep(0.01)
    assert proc.returncode == 0
    return peaks


def cpu_seconds(pids):
    """CPU seconds used so far by each of ``pids`` and by their children, by role:
    {"scheduler", "workers", "sampling"} (the first pid is the scheduler)."""
    used = {"scheduler": 0.0, "workers": 0.0, "sampling": 0.0}
    tick = os.sysconf("SC_CLK_TCK")
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        seconds = (int(fields[11]) + int(fields[12])) / tick
        if int(name) == pids[0]:
            used["scheduler"] += seconds
        elif int(name) in pids:
            used["workers"] += seconds
        elif int(fields[1]) in pids[1:]:
            used["sampling"] += seconds
    return used


def timed(cmd, cluster=None):
    """(seconds, CPU seconds by role) of one whole command."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    pids = [p.pid for p in cluster or ()]
    c0 = cpu_seconds(pids) if cluster else {}
    seconds = run(cmd)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = {"command": after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime}
    if cluster:
        cpu.update({k: v - c0[k] for k, v in cpu_seconds(pids).items()})
    return seconds, cpu


def start_cluster():
    """A scheduler and two one-thread workers on 127.0.0.1: (address, processes, seconds to start)."""
    import distributed

    t = time.perf_counter()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                               "--port", str(port), "--no-dashboard"], **quiet)]
    procs += [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                                "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"], **quiet) for _ in range(2)]
    with distributed.Client(address, timeout=60) as c:
        c.wait_for_workers(2, timeout=120)
    return address, procs, time.perf_counter() - t


def stop_cluster(procs):
    for p in reversed(procs):
        p.kill()
        p.wait()


def stage_times(paths):
    """Median seconds per mesh of load (+ plan), sample and write, in this process."""
    from scatter_cli import api
    from scatter_cli.writers import write_samples

    out = Path(tempfile.mkdtemp())
    load, samp, write = [], [], []
    for i, p in enumerate(paths):
        t0 = time.perf_counter()
        run = api.prepare(str(p), COUNT, attributes="normal")
        t1 = time.perf_counter()
        chunks = list(run.chunks())
        t2 = time.perf_counter()
        # a new file each time, as in a batch: renaming over an existing file makes ext4 flush it first
        write_samples(chunks, out / f"{i}.ply", "ply", run.layout, run.size)
        t3 = time.perf_counter()
        load.append(t1 - t0)
        samp.append(t2 - t1)
        write.append(t3 - t2)
    shutil.rmtree(out)
    return {k: (statistics.median(v), statistics.mean(v)) for k, v in
            (("load", load), ("sample", samp), ("write", write))}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", type=int, default=304, help="meshes in the collection")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--loop", type=int, default=20, help="meshes in the timed shell loop")
    ap.add_argument("--no-dask", action="store_true", help="leave the Dask engine out")
    ap.add_argument("--out", default=None)
    ap.add_argument("--settle", type=float, default=60.0,
                    help="seconds to wait before timing, for the file system (see the module's docstring)")
    ap.add_argument("--folder", default=None,
                    help="where the collection and the outputs go [default: the system's temporary folder]")
    args = ap.parse_args()
    os.environ.setdefault("PYTHONPATH", str(ROOT))
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)  # an installed package has its bytecode cached
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "scatter_cli")], check=True,
                   stdout=subprocess.DEVNULL)
    load_before = os.getloadavg()
    work = Path(tempfile.mkdtemp(prefix="scatter-batch-bench-", dir=args.folder))
    try:
        src = work / "meshes"
        src.mkdir()
        paths = make_collection(src, -(-args.meshes // len(SMALL)))[: args.meshes]
        n = len(paths)
        listing = work / "meshes.txt"
        listing.write_text("".join(f"{p}\n" for p in paths))
        one = work / "one.txt"
        one.write_text(f"{paths[0]}\n")
        script = work / "tm_pool.py"
        script.write_text(TRIMESH_SCRIPT)
        common = ["-n", COUNT, "-a", "normal", "-q"]
        kinds = ["batch", "trimesh", "batch_over", "trimesh_over", "batch_one", "sample_one"]
        if not args.no_dask:
            kinds += ["dask_first", "dask", "cluster", "dask_one"]
        times = {k: [] for k in kinds}
        cpus = {k: [] for k in kinds if k != "cluster"}  # CPU seconds of the command and the children it waited for
        cpu = {}

        folders = iter(range(1 << 30))

        def new_folder(kind):
            """A folder no run has written to (the next fresh run writes there; nothing is
            deleted before the end: see the module's docstring)."""
            folder = work / f"{kind}-{next(folders)}"
            folder.mkdir()
            return folder

        def batch_cmd(lst, out, *engine):
            return scatter("batch", "--from-list", lst, "-o", f"{out}/{{stem}}.ply", *common, *engine)

        def trimesh_cmd(out):
            return [sys.executable, str(script), str(listing), str(out)]

        time.sleep(args.settle)

        sample_one = scatter("sample", paths[0], *common, "-o", work / "one.ply")
        over = []  # each round's output folders, written over after all fresh rounds

        def keep(r, kind, t, c=None):
            if r >= 0:  # round -1: the warm-up, not kept
                times[kind].append(t)
                if c is not None:
                    cpus[kind].append(c["command"])

        for r in range(-1, args.repeats):
            batch_out, trimesh_out = new_folder("batch"), new_folder("trimesh")
            t, c = timed(batch_cmd(listing, batch_out, "-j", 2))
            keep(r, "batch", t, c)
            cpu["batch"] = c
            keep(r, "trimesh", *timed(trimesh_cmd(trimesh_out)))
            keep(r, "batch_one", *timed(batch_cmd(one, new_folder("one"), "-j", 2)))
            keep(r, "sample_one", *timed(sample_one))
            over.append((batch_out, trimesh_out))
            if args.no_dask:
                continue
            address, cluster, started = start_cluster()
            keep(r, "cluster", started)
            try:
                dask = ("--engine", "dask", "--scheduler", address)
                t, cpu["dask_first"] = timed(batch_cmd(listing, new_folder("dask"), *dask), cluster)
                keep(r, "dask_first", t)
                t, cpu["dask"] = timed(batch_cmd(listing, new_folder("dask"), *dask), cluster)
                keep(r, "dask", t)
                keep(r, "dask_one", timed(batch_cmd(one, new_folder("dask"), *dask), cluster)[0])
            finally:
                stop_cluster(cluster)
        for r, (batch_out, trimesh_out) in enumerate(over, -1):
            keep(r, "batch_over", *timed(batch_cmd(listing, batch_out, "-j", 2)))
            keep(r, "trimesh_over", *timed(trimesh_cmd(trimesh_out)))
        memory = batch_memory(listing, work / "mem", n)
        subset = paths[:: max(1, n // args.loop)][: args.loop]
        loop = " ; ".join(f"{sys.executable} -m scatter_cli sample {p} -n {COUNT} -a normal -o {work}/loop.ply"
                          for p in subset)
        t_loop = run(["sh", "-c", loop]) * n / len(subset)
        stages = stage_times(paths)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    text = report(args, n, times, cpu, memory, t_loop, len(subset), stages, load_before, cpus)
    print(text)
    if args.out:
        Path(args.out).write_text(text)


def report(args, n, times, cpu, memory, t_loop, looped, stages, load_before, cpus):
    med = {k: statistics.median(v) for k, v in times.items()}
    cmed = {k: statistics.median(v) for k, v in cpus.items() if v}
    engines = ("batch", "trimesh") + (() if args.no_dask else ("dask_first", "dask"))
    rate = {k: n / med[k] for k in engines}
    rate["loop"] = n / t_loop
    per_mesh = {k: (med[k] - med[k + "_one"]) / (n - 1) for k in ("batch",) + (() if args.no_dask else ("dask",))}
    load = os.getloadavg()
    ratios = [t / b for t, b in zip(times["trimesh"], times["batch"])]
    scipy_version = subprocess.run([sys.executable, "-c", "import scipy; print(scipy.__version__)"],
                                   capture_output=True, text=True).stdout.strip()
    lines = [
        f"# scatter batch: {n} small meshes, {COUNT} points with normals each (binary PLY)",
        "",
        f"Command: `NUMPY_MADVISE_HUGEPAGE=0 PYTHONPATH=$PWD python benchmarks/batch.py --meshes {args.meshes} "
        f"--repeats {args.repeats} --loop {args.loop}{' --no-dask' if args.no_dask else ''}"
        f"{f' --settle {args.settle:g}' if args.settle != 60 else ''}{f' --folder {args.folder}' if args.folder else ''}` "
        f"({time.strftime('%Y-%m-%d', time.gmtime())}; load average (1, 5, 15 min) before "
        f"{' '.join(f'{x:.1f}' for x in load_before)}, after {' '.join(f'{x:.1f}' for x in load)} "
        f"on {os.cpu_count()} CPUs)",
        "",
        "| run (whole command) | seconds (median) | meshes/s | scatter batch -j 2 is |",
        "|---|---|---|---|",
        f"| scatter batch -j 2 (starting its 2 workers included) | {med['batch']:.2f} | {rate['batch']:.1f} | 1 |",
        f"| trimesh + multiprocessing.Pool(2) | {med['trimesh']:.2f} | {rate['trimesh']:.1f} | "
        f"{rate['batch'] / rate['trimesh']:.2f}x faster |",
        f"| the same two, over the outputs of a fresh round: scatter batch -j 2 (files replaced atomically) | "
        f"{med['batch_over']:.2f} | {n / med['batch_over']:.1f} | 1 |",
        f"| trimesh + multiprocessing.Pool(2) (files rewritten in place) | {med['trimesh_over']:.2f} | "
        f"{n / med['trimesh_over']:.1f} | {med['trimesh_over'] / med['batch_over']:.2f}x faster |",
        f"| shell loop of scatter sample ({looped} timed, scaled) | {t_loop:.1f} | {rate['loop']:.2f} | "
        f"{rate['batch'] / rate['loop']:.1f}x faster |",
    ]
    if not args.no_dask:
        lines += [
            f"| Dask, 2 workers x 1 thread: first batch on the cluster (starting its sampling processes included) | "
            f"{med['dask_first']:.2f} | {rate['dask_first']:.1f} | {med['dask_first'] / med['batch']:.2f}x the time |",
            f"| Dask, 2 workers x 1 thread: a later batch (sampling processes running) | {med['dask']:.2f} | "
            f"{rate['dask']:.1f} | {med['dask'] / med['batch']:.2f}x the time |",
        ]
    lines += [
        "",
        f"Each round's trimesh time over its batch time (the two run back to back, so a change in the "
        f"machine's speed moves both): median {statistics.median(ratios):.2f}x, all "
        + ", ".join(f"{x:.2f}" for x in ratios) + ". "
        + (f"trimesh imported SciPy {scipy_version} (installed here), as it does wherever SciPy is installed."
           if scipy_version else "SciPy is not installed here: trimesh imported without it."),
        "",
        "All runs (s): " + "; ".join(f"{k} " + ", ".join(f"{t:.2f}" for t in v) for k, v in times.items()),
        "",
        "CPU seconds of the whole command (its own and its workers', median): "
        + ", ".join(f"{k} {v:.2f}" for k, v in cmed.items())
        + f". On a loaded machine the wall times above stretch; CPU seconds less so: -j 2 costs "
        f"{cmed['trimesh'] / cmed['batch']:.2f}x less CPU than the trimesh script, and its fixed cost is "
        f"{cmed['batch_one'] - cmed['sample_one']:+.2f} CPU s against one `scatter sample`.",
        "All runs (CPU s): " + "; ".join(f"{k} " + ", ".join(f"{t:.2f}" for t in v) for k, v in cpus.items() if v),
        "",
        f"Fixed cost: one `scatter sample` of the first mesh {med['sample_one']:.2f} s; a batch of that one mesh: "
        f"-j 2 {med['batch_one']:.2f} s ({med['batch_one'] - med['sample_one']:+.2f} s)"
        + ("" if args.no_dask else f", Dask {med['dask_one']:.2f} s (later batch)") + ". "
        f"Cost per further mesh ((all - one) / {n - 1}): "
        + ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in per_mesh.items()) + ".",
    ]
    if not args.no_dask:
        lines += ["", f"Starting the Dask cluster (scheduler and 2 workers, until connected; not in any time above): "
                      f"{med['cluster']:.2f} s."]
    lines += [
        "",
        "CPU seconds of one run (last repeat), by process: "
        + "; ".join(f"{k}: " + ", ".join(f"{role} {v:.2f}" for role, v in c.items()) + f" (total {sum(c.values()):.2f})"
                    for k, c in cpu.items()),
        "",
        "Peak resident memory of each batch worker (MB) over each fifth of the collection: "
        + "; ".join(f"worker {i + 1}: " + ", ".join(f"{m:.0f}" for m in fifths)
                    for i, fifths in enumerate(memory.values())),
        "",
        "Time per mesh in one process (median / mean, ms): "
        + ", ".join(f"{k} {a * 1e3:.1f} / {b * 1e3:.1f}" for k, (a, b) in stages.items()),
    ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
