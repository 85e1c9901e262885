"""What every writer shares: the writer protocol and atomic output files.

A file is written to a temporary name beside it and renamed into place only when
complete, so a failure never leaves a partial file and an existing one stays untouched.
Imports no format module and no NumPy.
"""

from __future__ import annotations

import contextlib
import os
import stat
import sys

from ..core.interrupts import held
from ..errors import STDOUT, ScatterError, writing


class Writer:
    """The writer protocol: ``header()``, ``write(samples)`` per chunk, ``finish()``, and
    ``close()`` in every case. ``report``: what the writer tells ``--stats``."""

    def __init__(self, stream, layout, count):
        self.stream = stream
        self.layout = layout
        self.count = count
        self.written = 0
        self.report = {}

    def header(self):
        pass

    def write(self, samples):
        self.written += len(samples)
        self.stream.write(self.encode(samples))

    def finish(self):
        if self.count is not None and self.written != self.count:
            raise ScatterError(f"internal error: wrote {self.written} points, announced {self.count}")

    def close(self):
        """Release what the writer holds before its stream is closed, finished or not."""


def copy_range(path, start, end, stream, block=1 << 22):
    """Copy bytes ``start`` to ``end`` of the file ``path`` into ``stream`` (for merging);
    a file that ends before ``end`` is an error naming it."""
    with reading(path), open(path, "rb") as f:
        f.seek(start)
        left = end - start
        while left > 0:
            data = f.read(min(block, left))
            if not data:
                raise ScatterError(f"{path}: the file ended early (truncated?)")
            stream.write(data)
            left -= len(data)


@contextlib.contextmanager
def reading(path):
    """Turn OS errors while reading ``path`` into one-line ScatterErrors naming it."""
    try:
        yield
    except FileNotFoundError:
        raise ScatterError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise ScatterError(f"{path}: is a directory") from None
    except OSError as exc:
        raise ScatterError(f"{path}: cannot read: {exc.strerror or exc}") from None


def is_stdout(path) -> bool:
    return path is None or str(path) == "-"


def _check_room(path, folder, size):
    """Refuse, before any work, a file of ``size`` bytes that the file system of ``folder``
    cannot take (its temporary copy is written there); a file system that does not say
    is not checked."""
    try:
        room = room_of(os.statvfs(folder))
    except OSError:
        return  # a missing folder is open_output's to report
    if room is not None and size > room:
        raise ScatterError(f"{path}: the output needs {_bytes(size)}, its file system has {_bytes(room)} free")


def room_of(fs):
    """The bytes free to a user on a file system (``os.statvfs``), or None when it keeps
    no count of blocks (/proc, /sys: writing there fails for another reason)."""
    return fs.f_bavail * fs.f_frsize if fs.f_blocks else None


def _stat(path):
    """os.stat of ``path``, or None when there is nothing there (or it cannot be seen:
    then creating the file says why)."""
    try:
        return os.stat(path)
    except OSError:
        return None


def _bytes(n):
    """``n`` bytes for a person: ``12 TB (12,000,000,000,000 bytes)``."""
    value = float(n)
    for unit in ("bytes", "kB", "MB", "GB", "TB", "PB"):
        if value < 1000:
            break
        value /= 1000
    return f"{n:,} bytes" if unit == "bytes" else f"{value:.3g} {unit} ({n:,} bytes)"


@contextlib.contextmanager
def open_output(path, size=None):
    """A binary stream for ``path``; ``None`` or ``'-'`` is standard output.

    Regular files are written atomically through a temporary file in the same folder
    (``.NAME.XXXXXXXX.part``), which gets the mode an ordinary ``open(path, 'w')`` would
    give: the existing file's, or 0666 less the umask. Devices and pipes (``/dev/null``,
    a FIFO) are written in place. ``size``: the bytes the file will have, when known: a
    file system without that room is refused first (devices and pipes are not checked).
    """
    if is_stdout(path):
        with writing(STDOUT):
            yield sys.stdout.buffer
            sys.stdout.buffer.flush()
        return
    path = os.fspath(path)
    existing = _stat(path)
    if existing is not None and not stat.S_ISREG(existing.st_mode):
        if stat.S_ISDIR(existing.st_mode):
            raise ScatterError(f"{path}: is a directory")
        with writing(path), open(path, "wb") as stream:
            yield stream
        return
    folder = os.path.dirname(os.path.abspath(path))
    if size is not None:
        _check_room(path, folder, size)
    tmp = stream = None
    try:
        # A signal between the temporary file's creation and its stream would leave the
        # file behind: it is held until both exist (then raised, and the file removed).
        with held(), writing(path):
            fd, tmp = _create_temp(path, folder)
            stream = os.fdopen(fd, "wb", buffering=1 << 20)
        with writing(path), stream:
            yield stream
        with writing(path):
            if existing is not None:
                os.chmod(tmp, stat.S_IMODE(existing.st_mode))
            os.replace(tmp, path)
    except BaseException:
        if stream is not None:
            with contextlib.suppress(OSError):
                stream.close()
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise


_NAME_CHARACTERS = "abcdefghijklmnopqrstuvwxyz0123456789_"
_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


def _create_temp(path, folder):
    """(fd, name) of a new file ``.NAME.XXXXXXXX.part`` beside ``path`` in ``folder``,
    created with mode 0666 less the umask."""
    base = os.path.basename(path)
    for _ in range(100):
        name = "".join(_NAME_CHARACTERS[b % len(_NAME_CHARACTERS)] for b in os.urandom(8))
        tmp = os.path.join(folder, f".{base}.{name}.part")
        try:
            return os.open(tmp, _CREATE, 0o666), tmp
        except FileExistsError:
            continue
        except (FileNotFoundError, NotADirectoryError) as exc:
            shown = os.path.dirname(path) or "."
            if os.path.isdir(folder):  # there, but it takes no new files (/proc)
                raise ScatterError(f"{path}: cannot write: folder '{shown}' takes no new files ({exc.strerror})") from None
            raise ScatterError(f"{path}: cannot write: folder '{shown}' does not exist") from None
    raise FileExistsError(f"no free temporary name beside {path}")
