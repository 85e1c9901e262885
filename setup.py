"""Build the optional compiled kernels (see scatter_cli/core/native.py).

Everything else lives in pyproject.toml. The extensions are optional: without a C
compiler the install goes on and scatter runs its NumPy path, which gives the same bytes.
"""

import importlib.util
import os

import numpy
from setuptools import Extension, setup


def _registry():
    """native.KERNELS (kernel -> its package and holders), read without importing the package."""
    spec = importlib.util.spec_from_file_location("_native", os.path.join("scatter_cli", "core", "native.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.KERNELS

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


def kernel(name, package):
    flags = FLAGS + SANITIZE if SANITIZED else FLAGS
    folder = package.replace(".", "/")
    return Extension(f"{package}.{name}", [f"{folder}/{name}.c"], depends=HEADERS,
                     include_dirs=[numpy.get_include(), "scatter_cli/core"],
                     extra_compile_args=flags, extra_link_args=SANITIZE if SANITIZED else [], optional=True)


# the headers every kernel may include (-I scatter_cli/core)
HEADERS = ["scatter_cli/core/_ckernel.h", "scatter_cli/core/_cmorton.h", "scatter_cli/core/_cthreads.h"]
# the kernels compile side by side, one a core
setup(ext_modules=[kernel(name, entry.package) for name, entry in _registry().items()],
      options={"build_ext": {"parallel": True}})
