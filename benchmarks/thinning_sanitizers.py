"""The thinning kernel (grid, pair search, greedy thinning) under AddressSanitizer and
UndefinedBehaviorSanitizer.

Builds scatter_cli/sampling/poisson/_cthinning.c with -fsanitize=address,undefined into a copy of the
package (and of tests, testkit and benchmarks) in a temporary directory, then, with the
sanitizer runtimes preloaded, runs tests/test_native.py (the thinning kernels against
their NumPy twins, the bad calls they must refuse), tests/test_thinning.py and the
thinning cases of tests/test_kernel_parity.py, with and without the AVX-512 loops where
the CPU has them. Any report aborts.

    python benchmarks/thinning_sanitizers.py      (gcc with libasan/libubsan; Linux)
"""

import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sanitized import ROOT, sanitized_copy  # noqa: E402


def main():
    with tempfile.TemporaryDirectory() as tmp:
        env = sanitized_copy(tmp, "_cthinning", also=("tests", "testkit", "benchmarks"))
        env["SCATTER_REQUIRE_KERNELS"] = "1"
        os.symlink(ROOT / "samples", Path(tmp) / "samples")
        with open(Path(tmp) / "tests" / "conftest.py", "a") as conf:  # the tests must see the sanitized kernel
            conf.write(f"\nfrom scatter_cli.sampling.poisson import pairs as _p\nassert {tmp!r} in _p._kernel.__file__\n")
        tests = [t for t in ("tests/test_native.py", "tests/test_thinning.py", "tests/test_kernel_parity.py")
                 if (Path(tmp) / t).exists()]
        for plain in ("", "1"):
            run_env = dict(env, SCATTER_NO_AVX512=plain)
            subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests, "-k",
                            "thin or pair or greedy or avx or refuse or grid"], env=run_env, check=True, cwd=tmp)
        print("thinning kernel: the tests ran under the sanitizers, with and without AVX-512 loops")


if __name__ == "__main__":
    main()
