"""Build the optional compiled kernels (see scatter_cli/native.py).

Everything else lives in pyproject.toml. The extensions are optional: without a C
compiler the install goes on and scatter runs its NumPy path, which gives the same bytes.
"""

import numpy
from setuptools import Extension, setup

# No fused multiply-add and no fast math: the kernels must round exactly as the NumPy path
# does. (-fno-math-errno only lets sqrt be inlined: no input of ours is negative;
# -fno-trapping-math lets loops with comparisons vectorise: nothing traps floating-point
# exceptions here, and it changes no result.)
FLAGS = ["-O3", "-ffp-contract=off", "-fno-fast-math", "-fno-math-errno", "-fno-trapping-math",
         "-Wno-stringop-overflow", "-Werror=implicit-function-declaration"]


def kernel(name):
    return Extension(f"scatter_cli.{name}", [f"scatter_cli/{name}.c"], include_dirs=[numpy.get_include()],
                     extra_compile_args=FLAGS, optional=True)


setup(ext_modules=[kernel("_csampling"), kernel("_cthinning"), kernel("_cstable")])
