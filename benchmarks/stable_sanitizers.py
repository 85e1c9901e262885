"""The stable kernel under AddressSanitizer and UndefinedBehaviorSanitizer.

Builds scatter_cli/sampling/stable/_cstable.c with -fsanitize=address,undefined into a copy of the package
in a temporary directory, then runs, with the sanitizer runtimes preloaded, --stable on
the sample meshes and on random meshes with degenerate, duplicated and non-finite faces,
and calls the kernel with out-of-range indices (it must refuse them). Any report aborts.

    python benchmarks/stable_sanitizers.py      (gcc with libasan/libubsan; Linux)

Run at c71580a, again with the arrival sort and id placement of 2026-12-02, and again
with arrivals written straight into time buckets and the corner rows (2026-12-02, later):
no report; the bad calls refused.
"""

import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sanitized import ROOT, sanitized_copy  # noqa: E402

CHECK = r'''
import numpy as np, os, sys, trimesh
import scatter_cli
from scatter_cli.sampling.stable import source as stable, arrivals as stable_arrivals, order as stable_order
assert stable._kernel is not None and sys.argv[1] in stable._kernel.__file__
rng = np.random.default_rng(0)
for name in ("skull.ply", "cesiummilktruck.glb", "narrow_triangles.obj", "moebius-160-10.ply"):
    for kw in (dict(count=20000), dict(count=None, density=5.0), dict(count=0), dict(count=None, radius=2.0)):
        scatter_cli.sample(sys.argv[2] + "/" + name, stable=True, attributes=("face", "bary"), **kw)
# over 2^16 arrivals: face ranges share the time buckets, three threads sort in place
# (side arrays); then every bucket overflows and the pass reruns with exact room
os.environ["SCATTER_THREADS"] = "3"
for sds in (stable_order.ROOM_SDS, -50.0):
    stable_order.ROOM_SDS = sds
    scatter_cli.sample(sys.argv[2] + "/skull.ply", 200000, stable=True, attributes=("face", "bary"))
scatter_cli.sample(sys.argv[2] + "/boxtextured.glb", 20000, stable=True, weight="texture:g")
for k in range(30):
    v = rng.normal(size=(50, 3))
    v[rng.integers(0, 50, 3)] = np.nan if k % 3 == 0 else 0.0
    f = rng.integers(0, 50, size=(200, 3))
    f[:20] = f[20:40]
    try:
        scatter_cli.sample(trimesh.Trimesh(v, f, process=False), 500, stable=True, attributes=("bary",))
    except scatter_cli.ScatterError:
        pass
key, rate = np.zeros(3, np.uint64), np.ones(3)
t, ids, none = np.zeros(4), np.zeros(4, np.uint64), (np.empty(0), np.empty(0, np.uint64))
bad = [lambda: stable._kernel.arrivals(key, rate, 1.0, 2.0, stable_arrivals.POISSON_CDF, 0, 5, 8, 4.0, 2, 4,
                                       np.zeros(1, np.int64), np.full(1, 4), t, ids),
       lambda: stable._kernel.arrivals(key, rate, 1.0, 2.0, stable_arrivals.POISSON_CDF, 0, 3, 8, 4.0, 2, 4,
                                       np.zeros(1, np.int64), np.full(1, 9), t, ids),
       lambda: stable._kernel.faces(np.zeros((3, 3)), np.array([[0, 1, 7]]), 0, 1, 0, np.empty(1, np.uint8),
                                    np.empty(1, np.uint64), np.empty(1), np.empty((1, 9))),
       lambda: stable._kernel.place(np.array([9 << 8], np.uint64), 8, key, None, np.zeros((3, 3), np.int64),
                                    np.zeros((3, 3)), None, np.empty((1, 3)), None, None, False),
       lambda: stable._kernel.place(np.array([9 << 8], np.uint64), 8, key, None, np.zeros((3, 3), np.int64),
                                    np.zeros((3, 3)), np.zeros((3, 9)), np.empty((1, 3)), None, None, False),
       lambda: stable._kernel.order(t, ids, np.array([0, 2]), np.array([3, 1]), 1, 0, 2, 2.0, 1, 4, key, 8, *none),
       lambda: stable._kernel.order(t, ids, np.array([0, 2]), np.array([0, 2]), 1, 1, 2, 2.0, 1, 4, key, 8, *none)]
for call in bad:
    try:
        call()
        raise SystemExit("a bad call was not refused")
    except (ValueError, TypeError):
        pass
print("stable kernel: no sanitizer report, bad calls refused")
'''


def main():
    with tempfile.TemporaryDirectory() as tmp:
        env = sanitized_copy(tmp, "_cstable")
        # run from tmp: python -c puts the working directory first on the path
        subprocess.run([sys.executable, "-c", CHECK, tmp, str(ROOT / "samples")], env=env, check=True, cwd=tmp)


if __name__ == "__main__":
    main()
