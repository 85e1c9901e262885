"""Every core: how each kind of work scales with the threads, and batch with its workers.

    NUMPY_MADVISE_HUGEPAGE=0 PYTHONPATH=$PWD python benchmarks/cores.py [--quick] [--repeats 3]
        [--only surface,volume,off,...] [--meshes 10000] [--out FILE]

For 1, 2, 4, ... threads up to the CPUs this process may use (``native.available_cpus()``:
its affinity mask, at most its cgroup's CPU quota), then that count itself when it is not
a power of two, and the default (SCATTER_THREADS unset), each kind of work in-process on
the skull sample, best of --repeats wall times:

- surface: 10^8 points (--quick 10^7): the whole run (loaded, prepared, every chunk
  made and dropped, as ``-o /dev/null``), as for stable, exterior and volume;
- poisson: 10^6 candidates thinned to an exact count of 10^5 (the candidates drawn once);
- stable: ``--stable``, 10^7 points (--quick 10^6);
- exterior: ``--exterior``, 10^6 points (--quick 2x10^5);
- volume: ``--volume -a sdf,inside``, 10^7 points (--quick 10^6);
- loaders: an ASCII STL of the skull's faces ten times over, 180 MB (--quick once, 18 MB),
  parsed from memory; off, ascii-ply and obj: the skull ten times over (its vertices and
  faces repeated, the indices moved on) as an OFF, an ASCII PLY and an OBJ, about 60 MB
  each (--quick once);
- batch: ``scatter batch`` over --meshes small meshes (copies of a 20-face mesh, 256
  points each, binary PLY) on a tmpfs, the whole command's wall time, ``-j`` 1, 2, 4, ...
  and the default (-j: the CPUs; threads per worker: the CPUs over -j).

Each row gives seconds and the parallel efficiency t(1) / (T t(T)) (1.0: every thread
fully used; batch: per worker). Results go to stdout as a Markdown table and, with --out,
to a file (benchmarks/results/).
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import scatter_cli  # noqa: E402
from scatter_cli.core import native  # noqa: E402

SKULL = str(REPO / "samples" / "skull.ply")
SMALL = REPO / "samples" / "icosahedron_binary.stl"


def thread_counts():
    cpus = native.available_cpus()
    counts = [1 << k for k in range(cpus.bit_length()) if 1 << k <= cpus]
    return counts + ([cpus] if cpus not in counts else []) + [None]  # None: the default


def with_threads(threads):
    if threads is None:
        os.environ.pop("SCATTER_THREADS", None)
    else:
        os.environ["SCATTER_THREADS"] = str(threads)


def drain(run):
    for _ in run.chunks():
        pass


def prepared(count, **options):
    """(what, the work) of a whole run of the skull with ``options``, in-process: loaded,
    prepared (the exterior pass, the trees), every chunk made and dropped."""
    return " ".join([f"{count:.0e} points"] + [f"{k}={v}" for k, v in options.items()]), \
        lambda: drain(scatter_cli.prepare(SKULL, count, **options))


def poisson(quick):
    import trimesh

    from scatter_cli.sampling.poisson import thinning

    candidates = scatter_cli.sample(SKULL, 10**6, seed=1).points.astype(np.float64)
    area = float(trimesh.load(SKULL, process=False).area)
    return "10^6 candidates thinned to 10^5", lambda: thinning.thin_to_count(candidates, 10**5, area)


def loaders(quick):
    from scatter_cli.loading import fast

    text = ascii_stl(1 if quick else 10)
    return f"ASCII STL, {len(text) / 1e6:.0f} MB", lambda: fast.read_stl(text, "skull.stl", False, False, False)


def text_mesh(kind, quick):
    from scatter_cli.loading import fast

    data = skull_text(kind, 1 if quick else 10)
    name = {"off": "OFF", "ply": "ASCII PLY", "obj": "OBJ"}[kind]
    read = {"off": fast.read_off, "ply": fast.read_ply, "obj": fast.read_obj}[kind]
    return f"{name}, {len(data) / 1e6:.0f} MB", lambda: read(data, "skull." + kind, False, False, False)


def skull_text(kind, copies):
    """The skull ``copies`` times over as an OFF, ASCII PLY or OBJ (bytes)."""
    import trimesh

    mesh = trimesh.load(SKULL, process=False)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    vertices = "".join("%.9g %.9g %.9g\n" % tuple(r) for r in v.tolist()) * copies
    faces = "".join("".join("3 %d %d %d\n" % tuple(r) for r in (f + k * len(v)).tolist()) for k in range(copies))
    nv, nf = copies * len(v), copies * len(f)
    if kind == "off":
        return f"OFF\n{nv} {nf} 0\n{vertices}{faces}".encode()
    if kind == "obj":
        return ("".join("v " + line for line in vertices.splitlines(True)) + "".join(
            "f %d %d %d\n" % tuple(int(x) + 1 for x in line.split()[1:]) for line in faces.splitlines())).encode()
    return (f"ply\nformat ascii 1.0\nelement vertex {nv}\nproperty double x\nproperty double y\nproperty double z\n"
            f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n{vertices}{faces}").encode()


# name -> a maker, given --quick, of (what, the work done once)
WORKS = {
    "surface": lambda quick: prepared(count=10**7 if quick else 10**8),
    "poisson": poisson,
    "stable": lambda quick: prepared(count=10**6 if quick else 10**7, stable=True),
    "exterior": lambda quick: prepared(count=2 * 10**5 if quick else 10**6, exterior=True),
    "volume": lambda quick: prepared(count=10**6 if quick else 10**7, volume=True, attributes="sdf,inside"),
    "loaders": loaders,
    "off": lambda quick: text_mesh("off", quick),
    "ascii-ply": lambda quick: text_mesh("ply", quick),
    "obj": lambda quick: text_mesh("obj", quick),
}


def ascii_stl(copies):
    """The skull's faces ``copies`` times over as ASCII STL text (bytes)."""
    import trimesh

    mesh = trimesh.load(SKULL, process=False)
    corners = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]
    facet = "facet normal 0 0 1\n outer loop\n" + "  vertex %.9g %.9g %.9g\n" * 3 + " endloop\nendfacet\n"
    body = (facet * len(corners) % tuple(corners.ravel())).encode()
    return b"solid skull\n" + body * copies + b"endsolid skull\n"


def best(fn, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def batch_times(meshes, repeats):
    """-j -> the whole command's best wall time over ``meshes`` copies of a small mesh."""
    root = Path(tempfile.mkdtemp(dir="/dev/shm" if os.path.isdir("/dev/shm") else None))
    try:
        (root / "in").mkdir()
        for i in range(meshes):
            shutil.copyfile(SMALL, root / "in" / f"m{i:06d}.stl")
        out = {}
        env = dict(os.environ, PYTHONPATH=str(REPO))
        env.pop("SCATTER_THREADS", None)
        for jobs in thread_counts():
            flags = [] if jobs is None else ["-j", str(jobs)]
            times = []
            for r in range(repeats):
                target = root / f"out-{jobs}-{r}"
                t = time.perf_counter()
                subprocess.run([sys.executable, "-m", "scatter_cli", "batch", str(root / "in"), "-o",
                                f"{target}/{{stem}}.ply", "-n", "256", *flags], env=env, check=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                times.append(time.perf_counter() - t)
                shutil.rmtree(target)
            out[jobs] = min(times)
        return out
    finally:
        shutil.rmtree(root, ignore_errors=True)


def row(name, what, times):
    one = times[1]
    cells = []
    for threads, t in times.items():
        used = native.available_cpus() if threads is None else threads
        cells.append(f"{t:.2f} s ({one / (used * t):.2f})")
    return f"| {name} | {what} | " + " | ".join(cells) + " |"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", default="surface,poisson,stable,exterior,volume,loaders,off,ascii-ply,obj,batch")
    parser.add_argument("--meshes", type=int, default=10_000)
    parser.add_argument("--out")
    args = parser.parse_args()
    only = args.only.split(",")
    counts = thread_counts()
    lines = [f"{native.available_cpus()} CPUs available to this process (os.cpu_count(): {os.cpu_count()}); "
             f"kernels: {'compiled' if all(native.kernel(k) for k in native.KERNELS) else 'NumPy path'}; "
             f"best of {args.repeats}; cells: seconds (parallel efficiency t1 / (T tT)).", "",
             "| work | size | " + " | ".join("default" if c is None else f"{c} thread{'s' * (c > 1)}" for c in counts)
             + " |", "|---|---|" + "---|" * len(counts)]
    print("\n".join(lines), flush=True)
    for name, make in WORKS.items():
        if name not in only:
            continue
        what, fn = make(args.quick)
        times = {}
        for threads in counts:
            with_threads(threads)
            fn()  # (warm: the kernels' trees, the caches)
            times[threads] = best(fn, args.repeats)
        lines.append(row(name, what, times))
        print(lines[-1], flush=True)
    if "batch" in only:
        meshes = args.meshes // (10 if args.quick else 1)
        lines.append(row("batch", f"{meshes:,} small meshes, -j as the column", batch_times(meshes, args.repeats)))
        print(lines[-1], flush=True)
    if args.out:
        Path(args.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
