"""The Embree scene kernel and the face-normal kernel under AddressSanitizer and
UndefinedBehaviorSanitizer.

Builds scatter_cli/sampling/exterior/_cembree.c and scatter_cli/sampling/_csampling.c with
-fsanitize=address,undefined into a copy of the package (and of tests, testkit and
benchmarks) in a temporary directory, then, with the sanitizer runtimes preloaded, runs
tests/test_rayscene.py (verdicts against embreex, awkward meshes with NaN, inf, huge and
tiny coordinates and repeated corners, the bad calls the kernels must refuse) and
tests/test_exterior.py, then builds the benchmark's 1.64M-face hidden20 ray scene and
casts its normal rays. Any report aborts.

    python benchmarks/rayscene_sanitizers.py      (gcc with libasan/libubsan; Linux)
"""

import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sanitized import ROOT, sanitized_copy  # noqa: E402

BIG = r'''
import numpy as np, sys, trimesh
from scatter_cli.sampling import normals
from scatter_cli.sampling.exterior import rayscene, rays as exterior_rays
from scatter_cli.surface.model import Geometry, Instance, Surface
assert sys.argv[1] in rayscene._compiled().__file__ and sys.argv[1] in normals._kernel.__file__
outer, inner = trimesh.creation.icosphere(8), trimesh.creation.icosphere(7, radius=0.5)
v = np.vstack([outer.vertices, inner.vertices])
f = np.vstack([outer.faces, inner.faces + len(outer.vertices)]).astype(np.int64)
occ = exterior_rays.Occluder(Surface([Geometry("hidden20", v, f)], [Instance("hidden20", 0)], "hidden20"))
rng = np.random.default_rng(0)
rows = rng.integers(0, len(f), 200000)
p = v[f[rows]].mean(axis=1)
free = occ.normal_escapes(p, occ.normals[rows])
assert abs(free.mean() - len(outer.faces) / len(f)) < 0.01, free.mean()
print("ray scene kernels: hidden20 under the sanitizers,", int(free.sum()), "of", len(rows), "normal rays out")
'''


def main():
    with tempfile.TemporaryDirectory() as tmp:
        env = sanitized_copy(tmp, ("_cembree", "_csampling"), also=("tests", "testkit", "benchmarks"))
        env["SCATTER_REQUIRE_KERNELS"] = "1"
        os.symlink(ROOT / "samples", Path(tmp) / "samples")
        with open(Path(tmp) / "tests" / "conftest.py", "a") as conf:  # the tests must see the sanitized kernels
            conf.write("\nfrom scatter_cli.sampling import normals as _v\n"
                       "from scatter_cli.sampling.exterior import rayscene as _r\n"
                       f"assert {tmp!r} in _r._compiled().__file__ and {tmp!r} in _v._kernel.__file__\n")
        tests = ["tests/test_rayscene.py", "tests/test_exterior.py"]
        subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests], env=env, check=True, cwd=tmp)
        subprocess.run([sys.executable, "-c", BIG, tmp], env=env, check=True, cwd=tmp)


if __name__ == "__main__":
    main()
