"""What ``scatter merge`` needs to know of a file a writer made: a ``Part``.

Every mergeable format is a header that carries the count, then the points as rows, so a
joined file is the header written for the total count followed by each part's rows.
A format module's ``read_part(path) -> Part`` reads the file's header, raises
``ScatterError`` naming the file when it is not a point file of that format, and fills:

- ``layout``: anything comparable; parts join only when their layouts are equal;
- ``count``: the number of points in the part;
- ``body``: ``(offset, end)``, the byte range of the points, copied as they are;
- ``header``: ``header(parts) -> bytes``, the merged file's header for the list of parts
  (the first part's function is called, with all of them).

A format whose points cannot be copied as bytes (LAZ: compressed chunks) sets
``join(parts, stream)`` instead, which writes the whole merged file.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Callable, Optional

from ..errors import ScatterError
from .base import reading

COPY_BLOCK = 1 << 22


@dataclasses.dataclass
class Part:
    path: str
    layout: object
    count: int
    body: tuple  # (offset, end) of the points in the file
    header: Callable  # header(parts) -> bytes of the merged file
    join: Optional[Callable] = None  # join(parts, stream): writes the merged file itself


def open_part(path):
    """``path`` opened for reading, or a one-line error naming it."""
    with reading(path):
        return open(path, "rb")


def size(path):
    with reading(path):
        return os.path.getsize(path)


def copy_body(part, stream):
    """Copy the points of ``part`` (its byte range) into ``stream``."""
    start, end = part.body
    with open_part(part.path) as f:
        f.seek(start)
        left = end - start
        while left > 0:
            block = f.read(min(COPY_BLOCK, left))
            if not block:
                raise ScatterError(f"{part.path}: the file ended early (truncated?)")
            stream.write(block)
            left -= len(block)


def count_lines(path, start):
    """Newline count of the file from byte ``start`` on, checking it ends with one."""
    total = size(path)
    if total <= start:
        return 0
    lines = 0
    with open_part(path) as f:
        f.seek(total - 1)
        if f.read(1) != b"\n":
            raise ScatterError(f"{path}: the last line has no newline (truncated?)")
        f.seek(start)
        while block := f.read(COPY_BLOCK):
            lines += block.count(b"\n")
    return lines


def check_rows(path, binary, offset, count, row):
    """Check that the file holds ``count`` points after ``offset``: ``row`` bytes each when
    ``binary``, else one line each."""
    if binary:
        have = size(path) - offset
        if have != count * row:
            raise ScatterError(f"{path}: {have} bytes of points, the header says {count} of {row} bytes")
    elif count_lines(path, offset) != count:
        raise ScatterError(f"{path}: the number of rows differs from the header's count {count}")
