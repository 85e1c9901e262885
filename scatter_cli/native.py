"""The optional compiled kernels (C extensions built at install), and the worker count.

Each kernel does the float64 operations of the NumPy code it stands in for, in the same
order, so it changes the time a job takes, never its output (tests/test_native.py holds
them to that). Set SCATTER_NUMPY=1 to run the NumPy path even when they are built.
"""

import importlib
import os


def kernel(name):
    """The compiled module ``scatter_cli.<name>``, or None when absent or turned off."""
    if os.environ.get("SCATTER_NUMPY", "") not in ("", "0"):
        return None
    try:
        return importlib.import_module(f"scatter_cli.{name}")
    except ImportError:
        return None


def worker_count() -> int:
    """Threads for sampling and thinning: SCATTER_THREADS, else the cores, at most 4."""
    env = os.environ.get("SCATTER_THREADS", "").strip()
    if not env:
        return max(1, min(4, os.cpu_count() or 1))
    try:
        return max(1, int(env))
    except ValueError:
        from .errors import ScatterUsageError

        raise ScatterUsageError(f"SCATTER_THREADS must be a whole number of threads, not {env!r}") from None
