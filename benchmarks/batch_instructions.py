"""Instructions a batch worker spends per small mesh, counted by callgrind (not seconds:
the same count for the same code whatever else the machine is doing).

    python benchmarks/batch_instructions.py TREE [TREE...] [--meshes 70]

For each TREE (a checkout with its kernels built in place): batch.py's collection (its
first --meshes meshes) sampled as a batch worker samples them (``worker.sample_file``,
2,048 points with normals, binary PLY, outputs on /dev/shm), once and three times, each
under ``valgrind --tool=callgrind``; the difference over twice the meshes is the count
per mesh, start-up excluded. Only user-space instructions count: system calls (creating
files) are not in it.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import batch as bench  # noqa: E402

PASSES = r'''
import os, sys
from scatter_cli.engines import worker
from scatter_cli.run.options import SampleOptions
from scatter_cli.core.process import lean_trimesh, single_threaded_blas
single_threaded_blas()
worker.preload()
lean_trimesh()
paths, out, passes = sys.argv[1].split("\n"), sys.argv[2], int(sys.argv[3])
options = SampleOptions(count=%d, attributes=("normal",)).check()
if "_checked" not in options.__dict__:  # a tree from before the worker kept its options built
    options = options.as_dict()
setup = {"options": options, "ascii": False, "crs": None, "quiet": True}
for k in range(passes):
    for i, p in enumerate(paths):
        assert worker.sample_file(p, f"{out}/{k}/{i}.ply", "ply", setup)["error"] is None
''' % bench.COUNT


def instructions(tree, paths, out, passes):
    env = dict(os.environ, PYTHONPATH=str(tree), SCATTER_THREADS="1")
    done = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", sys.executable, "-c",
                           PASSES, "\n".join(map(str, paths)), str(out / str(passes)), str(passes)],
                          env=env, capture_output=True, text=True, check=True)
    return int(re.search(r"Collected : (\d+)", done.stderr).group(1))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trees", nargs="+")
    ap.add_argument("--meshes", type=int, default=70)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="scatter-instructions-"))
    out = Path(tempfile.mkdtemp(prefix="scatter-instructions-", dir="/dev/shm" if os.path.isdir("/dev/shm") else None))
    try:
        paths = bench.make_collection(work, -(-args.meshes // len(bench.SMALL)))[: args.meshes]
        for tree in args.trees:
            one, three = (instructions(Path(tree).resolve(), paths, out, k) for k in (1, 3))
            print(f"{tree}: {(three - one) / (2 * len(paths)):,.0f} instructions per mesh")
    finally:
        subprocess.run(["rm", "-rf", str(work), str(out)], check=False)


if __name__ == "__main__":
    main()
