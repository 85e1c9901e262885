"""Build the optional compiled kernels (see scatter_cli/native.py).

Everything else lives in pyproject.toml. The extensions are optional: without a C
compiler the install goes on and scatter runs its NumPy path, which gives the same bytes.
"""

import os

import numpy
from setuptools import Extension, setup

# No fused multiply-add and no fast math: the kernels must round exactly as the NumPy path
# does. (-fno-math-errno only lets sqrt be inlined: no input of ours is negative;
# -fno-trapping-math lets loops with comparisons vectorise: nothing traps floating-point
# exceptions here, and it changes no result.)
FLAGS = ["-O3", "-ffp-contract=off", "-fno-fast-math", "-fno-math-errno", "-fno-trapping-math",
         "-Wno-stringop-overflow", "-Werror=implicit-function-declaration"]


# SCATTER_SANITIZE=1 builds with AddressSanitizer and UndefinedBehaviorSanitizer, for
# benchmarks/sanitize_readers.sh (run Python with the ASan runtime preloaded); never for an install.
SANITIZE = ["-fsanitize=address,undefined", "-fno-omit-frame-pointer", "-fno-sanitize-recover=undefined", "-g"]
SANITIZED = os.environ.get("SCATTER_SANITIZE", "") not in ("", "0")


def kernel(name):
    flags = FLAGS + SANITIZE if SANITIZED else FLAGS
    return Extension(f"scatter_cli.{name}", [f"scatter_cli/{name}.c"], depends=["scatter_cli/_ckernel.h", "scatter_cli/_cmorton.h", "scatter_cli/_cthreads.h"],
                     include_dirs=[numpy.get_include()],
                     extra_compile_args=flags, extra_link_args=SANITIZE if SANITIZED else [], optional=True)


setup(ext_modules=[kernel("_csampling"), kernel("_cthinning"), kernel("_cstable"), kernel("_creaders"),
                     kernel("_cenclosure"), kernel("_cembree"), kernel("_cwinding"), kernel("_cvolume")])
