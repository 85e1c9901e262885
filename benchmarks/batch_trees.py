"""Two checkouts of scatter and the trimesh script, batch against batch, interleaved.

    NUMPY_MADVISE_HUGEPAGE=0 python benchmarks/batch_trees.py BEFORE AFTER [--rounds 7] [--meshes 304] [--settle 60] [--folder DIR]

BEFORE and AFTER are folders holding a built `scatter_cli` (their kernels built in
place). The collection is benchmarks/batch.py's (small meshes in five formats); each
round runs, one after the other: `scatter batch -j 2` of BEFORE, a batch of its first
mesh, `scatter sample` of that mesh, the same three of AFTER, then batch.py's trimesh
script; every command writes into a new, empty folder. A warm-up round comes first. Rounds interleave so that a change in
the machine's speed (a shared host's is large) moves all of them alike: the ratios of
each round's medians are what to compare, not the seconds of different runs.
"""

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import batch as bench  # noqa: E402

SAMPLE = ["-n", str(bench.COUNT), "-a", "normal", "-q"]
COMMON = [*SAMPLE, "-j", "2"]


def run(cmd, env, cwd):
    """(wall s, CPU s of the command and the children it waited for), run in ``cwd`` (not a
    checkout: `python -m` would import the scatter_cli of the current folder first)"""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.perf_counter() - t, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def fresh(folder):
    """A new empty folder (nothing is deleted before the end: see benchmarks/batch.py)."""
    folder.mkdir()
    return folder


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--meshes", type=int, default=304)
    ap.add_argument("--settle", type=float, default=60.0, help="seconds to wait before timing (benchmarks/batch.py)")
    ap.add_argument("--folder", default=None, help="where the work goes (benchmarks/batch.py)")
    args = ap.parse_args()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONUNBUFFERED", "PYTHONDONTWRITEBYTECODE", "CI")}
    trees = {"before": Path(args.before).resolve(), "after": Path(args.after).resolve()}
    for root in trees.values():
        subprocess.run([sys.executable, "-m", "compileall", "-q", str(root / "scatter_cli")], check=True)
    work = Path(tempfile.mkdtemp(prefix="scatter-batch-trees-", dir=args.folder))
    try:
        paths = bench.make_collection(fresh(work / "meshes"), -(-args.meshes // len(bench.SMALL)))[: args.meshes]
        listing, one = work / "meshes.txt", work / "one.txt"
        listing.write_text("".join(f"{p}\n" for p in paths))
        one.write_text(f"{paths[0]}\n")
        script = work / "tm_pool.py"
        script.write_text(bench.TRIMESH_SCRIPT)
        runs = {k: [] for k in ("before", "before_one", "before_sample", "after", "after_one", "after_sample",
                                "trimesh")}
        time.sleep(args.settle)
        print(f"load before: {os.getloadavg()[0]:.2f}; {len(paths)} meshes")
        folders = iter(range(1 << 30))
        for r in range(-1, args.rounds):
            got = {}
            for name, root in trees.items():
                tree_env = dict(env, PYTHONPATH=str(root))
                for kind, lst in ((name, listing), (name + "_one", one)):
                    out = fresh(work / f"out-{next(folders)}")
                    got[kind] = run([sys.executable, "-m", "scatter_cli", "batch", "--from-list", str(lst), "-o",
                                     f"{out}/{{stem}}.ply", *COMMON], tree_env, work)
                out = fresh(work / f"out-{next(folders)}")
                got[name + "_sample"] = run([sys.executable, "-m", "scatter_cli", "sample", str(paths[0]), "-o",
                                             f"{out}/one.ply", *SAMPLE], tree_env, work)
            out = fresh(work / f"out-{next(folders)}")
            got["trimesh"] = run([sys.executable, str(script), str(listing), str(out)], env, work)
            if r >= 0:
                for k, v in got.items():
                    runs[k].append(v)
                print(f"round {r}: " + ", ".join(f"{k} {w:.2f}/{c:.2f}" for k, (w, c) in got.items())
                      + f" (wall/CPU s; load {os.getloadavg()[0]:.2f})", flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v)) for k, v in runs.items()}
    print("\n| command | wall s (median) | CPU s (median) | trimesh script / this, wall | CPU |\n|---|---|---|---|---|")
    for k, (w, c) in med.items():
        print(f"| {k} | {w:.2f} | {c:.2f} | {med['trimesh'][0] / w:.2f}x | {med['trimesh'][1] / c:.2f}x |")
    ratios = [a / b for (a, _), (b, _) in zip(runs["after"], runs["before"])]
    print(f"\nEach round's after/before, the collection (wall): median {statistics.median(ratios):.3f}, "
          f"all {', '.join(f'{r:.2f}' for r in ratios)}")
    for name in trees:
        extra = [a - b for (a, _), (b, _) in zip(runs[name + "_one"], runs[name + "_sample"])]
        print(f"{name}: a batch of one mesh against one `scatter sample` of it, each round (wall): "
              f"median {statistics.median(extra):+.3f} s")


if __name__ == "__main__":
    main()
