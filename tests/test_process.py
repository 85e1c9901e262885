"""The process settings of the ``scatter`` command (scatter_cli/core/process.py)."""

import os
import sys

import pytest

from .conftest import run_user

REUSE = """
import resource, sys
import numpy as np
from scatter_cli.core import process
if sys.argv[1] == "keep":
    process.keep_freed_memory()
faults = 0
for mb in (4, 8, 12, 16, 20, 24):  # arrays of growing size, each written and freed
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = np.empty(mb << 17)
    a[:] = 1.0
    del a
    faults += (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) if mb > 4 else 0
print(faults)
"""


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux") or any(k.startswith("MALLOC_") for k in os.environ)
                    or "malloc" in os.environ.get("GLIBC_TUNABLES", ""),
                    reason="glibc's mallopt, with glibc's own defaults (no MALLOC_* or GLIBC_TUNABLES malloc settings)")
def test_freed_memory_is_reused_without_faults():
    """After keep_freed_memory, arrays of growing size (8 to 24 MB, each freed before the
    next) reuse the pages of the ones before: faults only where the heap grows (about
    5,000 pages), against one a page of every array with glibc's defaults (each size
    past the last one freed is mapped afresh: about 20,000)."""
    env = {"NUMPY_MADVISE_HUGEPAGE": "0"}  # (huge pages would hide the faults both ways)
    faults = {mode: int(run_user([sys.executable, "-c", REUSE, mode], env=env, check=True).stdout)
              for mode in ("keep", "default")}
    assert faults["keep"] < faults["default"] / 2, faults


def test_a_users_own_malloc_settings_are_left_alone(monkeypatch):
    """MALLOC_MMAP_THRESHOLD_, MALLOC_TRIM_THRESHOLD_ or GLIBC_TUNABLES malloc settings: no
    mallopt call (the user's choice stands); other variables do not count."""
    from scatter_cli.core import process

    calls = []
    monkeypatch.setattr("ctypes.CDLL", lambda name: type("Libc", (), {"mallopt": lambda self, *a: calls.append(a)})())
    for env, expected in [({}, 2), ({"MALLOC_TRIM_THRESHOLD_": "0"}, 0), ({"MALLOC_MMAP_THRESHOLD_": "1"}, 0),
                          ({"GLIBC_TUNABLES": "glibc.malloc.trim_threshold=0"}, 0),
                          ({"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2"}, 2)]:
        calls.clear()
        with monkeypatch.context() as m:
            for k in ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_", "GLIBC_TUNABLES"):
                m.delenv(k, raising=False)
            for k, v in env.items():
                m.setenv(k, v)
            m.setattr(process.sys, "platform", "linux")
            process.keep_freed_memory()
        assert len(calls) == expected, env



THREADS = """
import os, sys
from scatter_cli.core import process
if sys.argv[1] == "single":
    process.single_threaded_blas()
import numpy as np
np.ones((64, 64)) @ np.ones((64, 64))  # BLAS at work
print(len(os.listdir("/proc/self/task")))
"""


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux") or (os.cpu_count() or 1) < 2,
                    reason="threads counted in /proc; OpenBLAS starts one a core")
def test_blas_runs_on_one_thread_unless_the_user_chose(tmp_path):
    """The command starts NumPy's BLAS with one thread; without the setting (the broken
    variant) it starts more, and a count the user set is kept."""
    from scatter_cli.core.process import _BLAS_THREADS

    unset = dict.fromkeys(_BLAS_THREADS, "")  # empty: OpenBLAS's default, and not a user's choice

    def threads(mode, **extra):
        return int(run_user([sys.executable, "-c", THREADS, mode], cwd=tmp_path, env={**unset, **extra}).stdout)

    assert threads("single") == 1
    assert threads("default") > 1
    assert threads("single", OMP_NUM_THREADS="2") > 1
