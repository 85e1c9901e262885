"""The optional compiled kernels (C extensions built at install), and the worker count.

Each kernel does the float64 operations of the NumPy code it stands in for, in the same
order, so it changes the time a job takes, never its output (tests/test_kernel_parity.py
holds them to that). Each module that uses one looks it up once, at import, through
:func:`kernel`. The environment is read here, never by the compiled code:
SCATTER_NUMPY=1 runs the NumPy path even when they are built; SCATTER_NO_AVX512=1 gives
the thinning kernel its plain distance loops instead of its AVX-512 ones.
"""

import functools
import importlib
import os
from typing import NamedTuple


class Kernel(NamedTuple):
    package: str  # where it sits, beside the Python that holds it (setup.py builds it there)
    holders: tuple  # the modules of that package that hold it, each as its ``_kernel``


# Every compiled kernel and every module that holds it. SCATTER_NUMPY=1 leaves all of those
# None; tests/test_kernel_parity.py switches all of them off to compute the NumPy twin, and
# tests/test_native.py checks that the modules looking a kernel up are exactly these.
KERNELS = {
    "_csampling": Kernel("scatter_cli.sampling", ("plan", "normals")),
    "_cedges": Kernel("scatter_cli.sampling", ("sharp",)),
    "_cthinning": Kernel("scatter_cli.sampling.poisson", ("pairs",)),
    "_cstable": Kernel("scatter_cli.sampling.stable", ("source", "faces", "order")),
    "_cenclosure": Kernel("scatter_cli.sampling.exterior", ("enclosure",)),
    "_cembree": Kernel("scatter_cli.sampling.exterior", ("rayscene",)),
    "_creaders": Kernel("scatter_cli.loading", ("fast",)),
    "_cwinding": Kernel("scatter_cli.volume", ("winding",)),
    "_cvolume": Kernel("scatter_cli.volume", ("distance", "parity")),
}


def holders(name):
    """The dotted names of the modules that hold kernel ``name``."""
    package, modules = KERNELS[name]
    return [f"{package}.{module}" for module in modules]


def kernel(name):
    """The compiled module ``name`` (a key of :data:`KERNELS`), or None when absent or turned off."""
    if _flag("SCATTER_NUMPY"):
        return None
    try:
        module = importlib.import_module(f"{KERNELS[name].package}.{name}")
    except ImportError:
        return None
    if name == "_cthinning":
        module.use_avx512(not _flag("SCATTER_NO_AVX512"))
    return module


def _flag(variable):
    """Whether an environment switch is on: set to anything but empty or 0."""
    return os.environ.get(variable, "") not in ("", "0")


@functools.lru_cache(maxsize=1)
def _cores() -> int:
    """The machine's cores (os.cpu_count reads /sys each time)."""
    return os.cpu_count() or 1


def worker_count() -> int:
    """Threads for sampling and thinning: SCATTER_THREADS, else the cores, at most 4."""
    return _threads(os.environ.get("SCATTER_THREADS", ""))


@functools.lru_cache(maxsize=8)  # asked several times per mesh
def _threads(env) -> int:
    env = env.strip()
    if not env:
        return max(1, min(4, _cores()))
    try:
        return max(1, int(env))
    except ValueError:
        from ..errors import ScatterUsageError

        raise ScatterUsageError(f"SCATTER_THREADS must be a whole number of threads, not {env!r}") from None
