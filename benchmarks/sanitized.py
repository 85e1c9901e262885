"""One compiled kernel built with AddressSanitizer and UndefinedBehaviorSanitizer into a
copy of the package, for the sanitizer scripts (stable_sanitizers.py, enclosure_sanitizers.py, ...)."""

import glob
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

import numpy

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scatter_cli.core.native import KERNELS  # noqa: E402 (kernel -> its package and holders)


def folder(kernel):
    """The folder of ``kernel``'s C file, relative to the repository."""
    return Path(*KERNELS[kernel].package.split("."))


def sanitized_copy(tmp, kernel, also=()):
    """Copy scatter_cli (and the folders ``also``, such as "tests") into ``tmp``, build
    KERNEL.c there (in its folder of the package) with the sanitizers (``kernel``: a name or a tuple of
    names), and return the environment that runs Python on the copy with the sanitizer
    runtimes preloaded."""
    runtimes = [glob.glob(f"/usr/lib/gcc/x86_64-linux-gnu/*/lib{n}.so")[:1] for n in ("asan", "ubsan")]
    if not all(runtimes):
        sys.exit("needs gcc's libasan and libubsan")
    kernels = (kernel,) if isinstance(kernel, str) else tuple(kernel)
    pkg = Path(tmp) / "scatter_cli"
    shutil.copytree(ROOT / "scatter_cli", pkg,
                    ignore=shutil.ignore_patterns(*(f"{k}*.so" for k in kernels), "__pycache__"))
    for name in also:
        shutil.copytree(ROOT / name, Path(tmp) / name, ignore=shutil.ignore_patterns("__pycache__"))
    for k in kernels:
        out = Path(tmp) / folder(k) / (k + sysconfig.get_config_var("EXT_SUFFIX"))
        subprocess.run(["gcc", "-shared", "-fPIC", "-O1", "-g", "-fsanitize=address,undefined",
                        "-fno-sanitize-recover=undefined", "-ffp-contract=off", "-I" + sysconfig.get_paths()["include"],
                        "-I" + numpy.get_include(), "-I" + str(ROOT / "scatter_cli" / "core"),
                        str(ROOT / folder(k) / f"{k}.c"), "-o", str(out)], check=True)
    env = dict(os.environ, PYTHONPATH=str(tmp), LD_PRELOAD=":".join(r[0] for r in runtimes), ASAN_OPTIONS="detect_leaks=0")
    env.pop("SCATTER_NUMPY", None)
    return env


def run_sanitized(kernel, module, tests, script):
    """Build KERNEL.c with the sanitizers in a temporary copy (tests, testkit and
    benchmarks beside it, samples linked), then run there, on 2 threads: the test file ``tests`` (a conftest
    line checks that the kernel of ``module``, a dotted name under scatter_cli, is the
    sanitized one; a list: pytest's arguments) and the Python ``script`` (the copy's path as its argv[1]). Any report aborts."""
    with tempfile.TemporaryDirectory() as tmp:
        env = sanitized_copy(tmp, kernel, also=("tests", "testkit", "benchmarks"))
        env["SCATTER_REQUIRE_KERNELS"] = "1"
        env["SCATTER_THREADS"] = "2"
        os.symlink(ROOT / "samples", Path(tmp) / "samples")
        with open(Path(tmp) / "tests" / "conftest.py", "a") as conf:
            conf.write(f"\nimport scatter_cli.{module} as _m\nassert {tmp!r} in _m._kernel.__file__\n")
        subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        *([tests] if isinstance(tests, str) else tests)], env=env, check=True, cwd=tmp)
        subprocess.run([sys.executable, "-c", script, tmp], env=env, check=True, cwd=tmp)
