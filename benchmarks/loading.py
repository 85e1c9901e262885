"""Loading benchmark: whole commands on the 1.31M-face icosphere in every format, the
memory a load takes, and load time per mesh on a collection of small files, fast readers
against trimesh.

    PYTHONPATH=. python benchmarks/loading.py [--runs 5] [--small 300] [--dir DIR] [--no-cloudcompare]
        [--formats "ASCII STL,binary STL"]

Part 1 runs `scatter sample FILE -n 1000000 -o out.ply -q` for each format, the formats
taken in turn round after round (so a change in the machine's load hits them alike), and
CloudCompare on the OBJ; it prints medians of wall time and peak memory, and each
format's ratio to binary PLY from the same rounds. Part 2 loads each icosphere file in a
fresh process and prints its peak memory beyond the arrays it returns (testkit/loadmemory.py).
Part 3 loads small meshes in one process, each with the fast readers
(load_surface(plain=True)) and with trimesh.load (process=False), and prints the median
time per mesh of each. ``--formats``: parts 1 and 2 for those formats only (and binary PLY,
the baseline), CloudCompare and part 3 left out.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from testkit.benchargs import options, work_folder  # noqa: E402

FORMATS = [  # (label, suffix, trimesh export options)
    ("binary PLY", "ply", {}),
    ("OBJ", "obj", {}),
    ("OFF", "off", {}),
    ("ASCII PLY", "ply", {"encoding": "ascii"}),
    ("ASCII STL", "stl", {"file_type": "stl_ascii"}),
    ("binary STL", "stl", {}),
    ("GLB", "glb", {}),
]
TARGETS = {"OBJ": 2.0, "OFF": 2.0, "ASCII PLY": 2.0, "ASCII STL": 2.0, "binary STL": 1.2, "GLB": 1.2}


def big_files(folder):
    """The icosphere in every format, written by a child process (a child forked from a
    large parent would report the parent's memory as its own peak)."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = {label: folder / f"ico8-{label.replace(' ', '-').lower()}.{suffix}" for label, suffix, _ in FORMATS}
    todo = [(str(paths[label]), options) for label, _, options in FORMATS if not paths[label].exists()]
    if todo:
        code = ("import sys, trimesh\nm = trimesh.creation.icosphere(subdivisions=8)\n"
                f"for path, options in {todo!r}:\n    m.export(path, **options)\n")
        subprocess.run([sys.executable, "-c", code], check=True)
    return paths


def child_env():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    env["QT_QPA_PLATFORM"] = "offscreen"
    return env


def timed(cmd, env, cwd):
    """(wall seconds, peak resident MB) of one command."""
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    err = proc.stderr.read().decode()
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed: {err.strip()[:300]}")
    return wall, usage.ru_maxrss / 1024


def part_whole_commands(paths, runs, cloudcompare, work):
    env = child_env()
    out = Path(work) / "out.ply"
    jobs = {label: [sys.executable, "-m", "scatter_cli", "sample", str(p), "-n", "1000000", "-o", str(out), "-q"]
            for label, p in paths.items()}
    if cloudcompare:
        runtime = Path(work) / "xdg"
        runtime.mkdir(mode=0o700, exist_ok=True)
        jobs["CloudCompare OBJ"] = ["CloudCompare", "-SILENT", "-NO_TIMESTAMP", "-AUTO_SAVE", "OFF", "-O",
                                    str(paths["OBJ"]), "-SAMPLE_MESH", "POINTS", "1000000", "-C_EXPORT_FMT", "PLY",
                                    "-SAVE_CLOUDS", "FILE", str(Path(work) / "cc.ply")]
        env_cc = dict(env, XDG_RUNTIME_DIR=str(runtime))
    times = {k: [] for k in jobs}
    peaks = {k: [] for k in jobs}
    for label, cmd in jobs.items():  # one warm-up each: page cache, .pyc files
        timed(cmd, env_cc if label.startswith("CloudCompare") else env, work)
    for _ in range(runs):
        for label, cmd in jobs.items():
            wall, peak = timed(cmd, env_cc if label.startswith("CloudCompare") else env, work)
            times[label].append(wall)
            peaks[label].append(peak)
    base = statistics.median(times["binary PLY"])
    print(f"\nWhole command, icosphere(8) (1,310,720 faces), -n 1000000, median of {runs} rounds")
    print("| input | file MB | time s | peak MB | / binary PLY | target |")
    print("|---|---:|---:|---:|---:|---|")
    for label in jobs:
        t = statistics.median(times[label])
        path = paths.get(label) or paths["OBJ"]
        target = TARGETS.get(label)
        verdict = "" if target is None else f"<= {target}x: {'met' if t / base <= target else 'NOT met'}"
        print(f"| {label} | {path.stat().st_size / 1e6:.0f} | {t:.2f} | {statistics.median(peaks[label]):.0f} | "
              f"{t / base:.2f} | {verdict} |")
    if cloudcompare:
        ratio = statistics.median(times["CloudCompare OBJ"]) / statistics.median(times["OBJ"])
        print(f"OBJ: CloudCompare / scatter = {ratio:.2f} (target >= 4: {'met' if ratio >= 4 else 'NOT met'})")


def part_memory(paths):
    from testkit.loadmemory import load_memory

    def run(cmd, env=None):
        return subprocess.run(cmd, env=child_env(), capture_output=True, text=True)

    print("\nMemory of a load (load_surface(plain=True) in a fresh process): peak resident size beyond the")
    print("size before and the returned arrays; the readers map the file and touch all of it")
    print("| input | file MB | arrays MB | beyond arrays MB | less the file MB | / file size |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, path in paths.items():
        m = load_memory(path, run)
        beyond = m["peak"] - m["before"] - m["arrays"]
        print(f"| {label} | {m['file'] / 1e6:.0f} | {m['arrays'] / 1e6:.0f} | {beyond / 1e6:.0f} | "
              f"{m['extra'] / 1e6:.0f} | {m['extra'] / m['file']:.2f} |")


def small_files(folder, count):
    """``count`` small meshes (40 to 1,280 faces), formats in turn, some with quads."""
    import numpy as np
    import trimesh

    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    kinds = [("obj", {}), ("off", {}), ("ply", {"encoding": "ascii"}), ("ply", {}), ("stl", {}),
             ("stl", {"file_type": "stl_ascii"}), ("glb", {})]
    paths = []
    for k in range(count):
        suffix, options = kinds[k % len(kinds)]
        path = folder / f"m{k:03d}.{suffix}"
        if not path.exists():
            if k % 3 == 0:
                mesh = trimesh.creation.box(extents=rng.uniform(0.5, 2, 3))
            else:
                mesh = trimesh.creation.icosphere(subdivisions=int(rng.integers(1, 4)))
            mesh.vertices = mesh.vertices * rng.uniform(0.5, 2, 3)
            mesh.export(path, **options)
        paths.append(path)
    return paths


def part_small_files(paths, runs):
    import trimesh

    from scatter_cli.loading.load import load_surface

    fast, slow = [], []
    for _ in range(runs):
        for p in paths:
            t = time.perf_counter()
            load_surface(p, plain=True)
            fast.append(time.perf_counter() - t)
            t = time.perf_counter()
            trimesh.load(p, process=False)
            slow.append(time.perf_counter() - t)
    f, s = statistics.median(fast), statistics.median(slow)
    print(f"\nSmall files: {len(paths)} meshes (OBJ, OFF, ASCII/binary PLY, ASCII/binary STL, GLB in turn), "
          f"{runs} passes, median load time per mesh")
    print(f"| reader | ms per mesh |\n|---|---:|\n| fast readers | {f * 1e3:.3f} |\n| trimesh.load | {s * 1e3:.3f} |")
    print(f"trimesh / fast = {s / f:.1f}")


def main():
    args = options(runs=5, small=300, dir=None, no_cloudcompare=False,
                   formats=(None, "comma-separated labels, e.g. 'ASCII STL,binary STL'"))
    chosen = None if args.formats is None else {"binary PLY", *(f.strip() for f in args.formats.split(","))}
    if chosen and chosen - {label for label, _, _ in FORMATS}:
        sys.exit(f"unknown formats: {', '.join(sorted(chosen - {label for label, _, _ in FORMATS}))}")
    with work_folder(args.dir) as (folder, work):
        cc = not args.no_cloudcompare and not chosen and shutil.which("CloudCompare") is not None
        paths = {k: p for k, p in big_files(folder / "big").items() if not chosen or k in chosen}
        part_whole_commands(paths, args.runs, cc, work)
        part_memory(paths)
        if not chosen:
            part_small_files(small_files(folder / "small", args.small), max(1, args.runs // 2))


if __name__ == "__main__":
    main()
