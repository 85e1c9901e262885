"""The optional compiled kernels (C extensions built at install), and the thread count.

Each kernel does the float64 operations of the NumPy code it stands in for, in the same
order, so it changes the time a job takes, never its output (tests/test_kernel_parity.py
holds them to that). Each module that uses one looks it up once, at import, through
:func:`kernel`. The environment is read here, never by the compiled code:
SCATTER_NUMPY=1 runs the NumPy path even when they are built; SCATTER_NO_AVX512=1 gives
the thinning kernel its plain distance loops instead of its AVX-512 ones.
"""

import functools
import importlib
import math
import os
import threading
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


@functools.lru_cache(maxsize=1)  # read once: a batch asks for every mesh
def available_cpus() -> int:
    """The CPUs this process may use: those of its affinity mask, at most its cgroup's CPU
    quota (a container's ``--cpus``, rounded up), at least 1."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # (not Linux)
        cpus = os.cpu_count() or 1
    quota = cgroup_cpu_quota()
    if quota is not None:
        cpus = min(cpus, math.ceil(quota))
    return max(1, cpus)


def cgroup_cpu_quota(root="/sys/fs/cgroup", membership="/proc/self/cgroup"):
    """CPUs the quota of this process's cgroup and of the cgroups above it allows (the least
    of their quota / period), or None without a quota. Reads cgroup v2's ``cpu.max`` and
    v1's ``cpu.cfs_quota_us`` and ``cpu.cfs_period_us``; where the process's cgroup is not
    visible (a container mounts its own as the root), the root's."""
    try:
        with open(membership) as f:
            lines = f.read().splitlines()
    except OSError:
        return None
    least = None
    for line in lines:
        _, controllers, path = line.split(":", 2)
        if controllers == "":  # v2
            folders = [root]
        elif "cpu" in controllers.split(","):  # v1: mounted under the controllers' names
            folders = [os.path.join(root, name) for name in (controllers, "cpu", "cpu,cpuacct")]
        else:
            continue
        for folder in dict.fromkeys(folders):
            for level in _levels(folder, path):
                quota = _quota_at(level)
                if quota is not None and (least is None or quota < least):
                    least = quota
    return least


def _levels(folder, path):
    """The folders of cgroup ``path`` under the mount ``folder``, from it up to the mount."""
    parts = [p for p in path.split("/") if p]
    if not os.path.isdir(os.path.join(folder, *parts)):
        parts = []  # another namespace's path: the mount's root is this process's cgroup
    return [os.path.join(folder, *parts[:k]) for k in range(len(parts), -1, -1)]


def _quota_at(folder):
    """quota / period of the cgroup ``folder`` (v2 or v1), None when it sets none."""
    try:
        with open(os.path.join(folder, "cpu.max")) as f:
            quota, period = f.read().split()[:2]
    except (OSError, ValueError):
        try:
            with open(os.path.join(folder, "cpu.cfs_quota_us")) as f, \
                    open(os.path.join(folder, "cpu.cfs_period_us")) as g:
                quota, period = f.read().strip(), g.read().strip()
        except OSError:
            return None
    try:
        quota, period = int(quota), int(period)
    except ValueError:  # "max": no quota
        return None
    return quota / period if quota > 0 and period > 0 else None


def worker_count() -> int:
    """Threads for the kernels and the pools: SCATTER_THREADS, else :func:`available_cpus`;
    1 on a thread of a :func:`thread_pool`."""
    if getattr(_pool_thread, "on", False):
        return 1
    return _threads(os.environ.get("SCATTER_THREADS", ""))


_pool_thread = threading.local()
PIECES_PER_THREAD = 8  # work cut into this many pieces a thread keeps them all busy (as _cthreads.h does)


def thread_pool(threads, one_level=True):
    """A pool of ``threads`` threads; ``one_level``: the kernels its threads call run on
    their thread alone, so that T threads run T threads, not T kernels of T threads each."""
    from concurrent.futures import ThreadPoolExecutor

    return ThreadPoolExecutor(max_workers=threads, initializer=_one_level if one_level else None)


def _one_level():
    _pool_thread.on = True


@functools.lru_cache(maxsize=8)  # asked several times per mesh
def _threads(env) -> int:
    env = env.strip()
    if not env:
        return available_cpus()
    try:
        return max(1, int(env))
    except ValueError:
        from ..errors import ScatterUsageError

        raise ScatterUsageError(f"SCATTER_THREADS must be a whole number of threads, not {env!r}") from None


def in_blocks(fn, n, min_block=1 << 15):
    """[fn(i, j)] over consecutive blocks covering range(n), on the worker threads: many
    blocks a thread (each of ``min_block`` at least), taken as the threads finish the last.

    For element-wise work only: the blocks depend on n and the thread count, so the
    result must not depend on where the cuts fall.
    """
    threads = worker_count()
    blocks = min(PIECES_PER_THREAD * threads, n // max(min_block, 1))
    if threads == 1 or blocks < 2:
        return [fn(0, n)]
    cuts = [n * k // blocks for k in range(blocks + 1)]
    with thread_pool(threads) as pool:
        return list(pool.map(fn, cuts[:-1], cuts[1:]))
