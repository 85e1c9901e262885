"""The enclosure kernel under AddressSanitizer and UndefinedBehaviorSanitizer.

Builds scatter_cli/sampling/exterior/_cenclosure.c with -fsanitize=address,undefined into a copy of the
package (and of tests, testkit and benchmarks) in a temporary directory, then, with the sanitizer runtimes
preloaded, runs tests/test_enclosure_native.py (built scenes, 60 hypothesis scenes of
random shells, degenerate input: NaN/inf, huge and tiny coordinates, duplicate and
zero-area faces, and the bad calls the kernel must refuse) and tests/test_enclosure.py,
then the certificate on the benchmark's 1.64M-face hidden20 scene. Any report aborts.

    python benchmarks/enclosure_sanitizers.py      (gcc with libasan/libubsan; Linux)

Results are in docs/exterior.md ("Enclosed faces").
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
from scatter_cli.sampling.exterior import enclosure
assert enclosure._kernel is not None and sys.argv[1] in enclosure._kernel.__file__
outer, inner = trimesh.creation.icosphere(8), trimesh.creation.icosphere(7, radius=0.5)
v = np.vstack([outer.vertices, inner.vertices])
f = np.vstack([outer.faces, inner.faces + len(outer.vertices)]).astype(np.int64)
part, closed = enclosure.closed_parts(v, f)
out = enclosure.enclosed_faces(v, f, part, closed, 16 * float(np.spacing(np.float32(1.0))))
assert out.sum() == len(inner.faces), out.sum()
print("enclosure kernel: hidden20 certified under the sanitizers:", int(out.sum()), "faces")
'''


def main():
    with tempfile.TemporaryDirectory() as tmp:
        env = sanitized_copy(tmp, "_cenclosure", also=("tests", "testkit", "benchmarks"))
        env["SCATTER_REQUIRE_KERNELS"] = "1"
        os.symlink(ROOT / "samples", Path(tmp) / "samples")
        # run from tmp: the copied tests import the copied package, which holds the sanitized kernel
        tests = ["tests/test_enclosure_native.py", "tests/test_enclosure.py"]
        # the tests must see the sanitized kernel: a conftest appended to the copy checks it
        with open(Path(tmp) / "tests" / "conftest.py", "a") as conf:
            conf.write(f"\nfrom scatter_cli.sampling.exterior import enclosure as _e\nassert {tmp!r} in _e._kernel.__file__\n")
        subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests], env=env, check=True, cwd=tmp)
        subprocess.run([sys.executable, "-c", BIG, tmp], env=env, check=True, cwd=tmp)


if __name__ == "__main__":
    main()
