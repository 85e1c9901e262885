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

# Every compiled kernel: its module name -> the package it sits in, beside the Python that
# holds it (setup.py builds these).
KERNELS = {
    "_csampling": "scatter_cli.sampling",
    "_cedges": "scatter_cli.sampling",
    "_cthinning": "scatter_cli.sampling.poisson",
    "_cstable": "scatter_cli.sampling.stable",
    "_cenclosure": "scatter_cli.sampling.exterior",
    "_cembree": "scatter_cli.sampling.exterior",
    "_creaders": "scatter_cli.loading",
    "_cwinding": "scatter_cli.volume",
    "_cvolume": "scatter_cli.volume",
}


def kernel(name):
    """The compiled module ``name`` (a key of :data:`KERNELS`), or None when absent or turned off."""
    if _flag("SCATTER_NUMPY"):
        return None
    try:
        module = importlib.import_module(f"{KERNELS[name]}.{name}")
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
