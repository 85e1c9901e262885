"""The ``scatter`` process: signals, exit codes, standard output, and the way out.

:mod:`scatter_cli.cli` describes the commands; this module runs one of them as a Unix
tool is expected to run: exit 0, 1 or 2 (2 for usage errors), 130 and 143 on SIGINT and
SIGTERM, a quiet 141 when the reader of standard output goes away, one ``error: ...``
line on standard error for every other failure, and no traceback unless ``--debug``.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import sys

from ..errors import STDOUT, OutputClosed, ScatterError, writing
from .interrupts import Interrupted, Terminated, install

_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO)  # a write that cannot go on


class Options:
    """Settings of the whole process, filled in by the root command (``--debug``)."""

    debug = False


install_signal_handlers = install


def echo(text):
    """Write a line of text to standard output now, failing as any output does."""
    with writing(STDOUT):
        sys.stdout.write(text + "\n")
        sys.stdout.flush()


# glibc's mallopt parameters, and what scatter sets them to: blocks under 32 MB come from
# the heap, and freed memory stays there until the process ends, so the arrays a run
# allocates again and again (a block of candidates, a chunk of points) reuse pages that
# are already mapped. Fresh pages cost a fault each, and more on a virtual machine whose
# host has taken idle memory back (docs/speed.md, "Memory").
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MALLOPT = ((_M_MMAP_THRESHOLD, 32 << 20), (_M_TRIM_THRESHOLD, 1 << 30))


# the variables OpenBLAS reads for its thread count, in its order
_BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def single_threaded_blas():
    """Start NumPy's OpenBLAS with one thread (unless the user chose a count): scatter
    multiplies only small matrices, and starting a thread per core costs every command
    about 0.1 CPU s at NumPy's import (its children inherit the setting). Call it before
    NumPy is imported; the Python API leaves the user's settings alone."""
    if not any(os.environ.get(name) for name in _BLAS_THREADS):
        os.environ["OPENBLAS_NUM_THREADS"] = "1"


def keep_freed_memory():
    """Tell glibc's allocator to keep freed memory for reuse (nothing elsewhere, or when
    the user tunes it: MALLOC_MMAP_THRESHOLD_, MALLOC_TRIM_THRESHOLD_, or malloc settings
    in GLIBC_TUNABLES)."""
    if not sys.platform.startswith("linux") or _malloc_tuned(os.environ):
        return
    import ctypes

    try:
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return
    for param, value in _MALLOPT:
        mallopt(param, value)


def _malloc_tuned(env) -> bool:
    return "MALLOC_MMAP_THRESHOLD_" in env or "MALLOC_TRIM_THRESHOLD_" in env or "malloc" in env.get("GLIBC_TUNABLES", "")


def whole_writes():
    """Give standard output a buffered binary layer when it has none (``python -u``,
    PYTHONUNBUFFERED). An unbuffered one hands each write to the OS once: when the
    reader leaves in the middle of a large write, the OS takes part of it without an
    error, the rest is dropped, and a last write ends the run with exit 0 instead of
    141. A buffered one writes the rest and meets the broken pipe."""
    stream = sys.stdout
    if not isinstance(getattr(stream, "buffer", None), io.RawIOBase):
        return
    binary = open(stream.fileno(), "wb", closefd=False)  # fd 1 stays open with the original
    sys.stdout = io.TextIOWrapper(binary, encoding=stream.encoding, errors=stream.errors, line_buffering=True)


def run_command(command, argv):
    """Run the click ``command`` on ``argv``; returns the exit code (never raises)."""
    single_threaded_blas()
    install_signal_handlers()
    keep_freed_memory()
    whole_writes()
    usage_error, click_error = _click_error_types()
    options = Options()
    try:
        code = command.main(args=argv, prog_name="scatter", standalone_mode=False, obj=options)
        code = code if isinstance(code, int) else 0
        with writing(STDOUT):
            sys.stdout.flush()
    except usage_error as exc:
        hint = f" (see '{exc.ctx.command_path} --help')" if getattr(exc, "ctx", None) else ""
        code = fail(exc.format_message() + hint, 2)
    except ScatterError as exc:
        code = fail(str(exc), exc.exit_code)
    except click_error as exc:
        code = fail(exc.format_message(), exc.exit_code)
    except (BrokenPipeError, OutputClosed):
        code = _reader_gone()
    except (KeyboardInterrupt, Interrupted):
        code = fail("interrupted", 130)
    except Terminated:
        code = fail("terminated", 143)
    except MemoryError:
        code = fail("out of memory (try a smaller count or --chunk-size)", 1)
    except Exception as exc:
        if options.debug:
            raise
        code = fail(_stdout_failure(exc) or f"internal error: {type(exc).__name__}: {exc} (run with --debug for a traceback)", 1)
    return code


def _stdout_failure(exc=None):
    """The message for a standard output that cannot take its data (click's own writes, such
    as --help, flush as they go: a long text fails in click's write, a short one at the
    flush), or None when standard output is fine."""
    if isinstance(exc, OSError) and exc.filename is None and exc.errno in _FULL:
        return f"{STDOUT}: cannot write: {exc.strerror or exc}"
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        return None
    except OSError as exc:
        return f"{STDOUT}: cannot write: {exc.strerror or exc}"
    except ValueError:
        pass
    return None


def _reader_gone():
    """The reader of standard output went away (`| head`): stop quietly, as Unix tools do."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    return 141


def _click_error_types():
    import typer

    mro = typer.BadParameter.__mro__
    usage = next(c for c in mro if c.__name__ == "UsageError")
    base = next(c for c in mro if c.__name__ == "ClickException")
    return usage, base


def exit_now(code):
    """Flush the standard streams and leave without tearing the interpreter down.

    Freeing every module and array at exit takes tens of milliseconds after a large job,
    for nothing: the output is complete and closed by then.
    """
    try:
        sys.stdout.flush()
    except (BrokenPipeError, ValueError):  # the reader left; standard output closed
        code = code or 141
    except OSError as exc:
        code = code or fail(f"{STDOUT}: cannot write: {exc.strerror or exc}", 1)
    with contextlib.suppress(OSError, ValueError):
        sys.stderr.flush()
    os._exit(code)


def fail(message, code):
    print(f"error: {message}", file=sys.stderr)
    return code
