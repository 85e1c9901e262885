"""An input path before any format reads it: checks that word the error, and the bytes of
standard input or a pipe (read once: no size, no second pass)."""

from __future__ import annotations

import os
import stat
import sys

from ..errors import ScatterError


def check_readable(path) -> bool:
    """Raise ScatterError when ``path`` is missing, a folder, unreadable or an empty file;
    else return whether it is a stream: standard input, or a pipe, socket or device, read
    once with no size. One stat: a batch asks this of every mesh."""
    if path == "-":
        return True
    try:
        status = os.stat(path)
    except OSError:
        raise ScatterError(f"{path}: no such file") from None
    if stat.S_ISDIR(status.st_mode):
        raise ScatterError(f"{path}: is a directory, not a mesh file")
    if not os.access(path, os.R_OK):
        raise ScatterError(f"{path}: permission denied")
    stream = not stat.S_ISREG(status.st_mode)
    if not stream and status.st_size == 0:
        raise ScatterError(f"{path}: the file is empty")
    return stream


def stream_bytes(path, empty):
    """All the bytes of standard input (``-``) or the pipe ``path``; ScatterError(``empty``)
    when there are none."""
    if path == "-":
        data = sys.stdin.buffer.read()
    else:
        with open(path, "rb") as f:
            data = f.read()
    if not data:
        raise ScatterError(empty)
    return data
