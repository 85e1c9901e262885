"""Our point files read back: one reader per format, for ``merge`` and ``preview`` alike.

Each format's module (the format table's ``module``) holds, beside its writer, its reader
``read(path, fmt) -> PointFile``: the file's header, checked against the file (a binary
body's size, a text body's lines), or a one-line ScatterError naming the file (IsMesh
when the file is a mesh, not points). ``scatter merge`` joins files of one ``layout``
(``join``); ``scatter preview`` draws their ``columns`` (:func:`read_points`). Both take a
file from the same reader, so they cannot disagree about it.

A PointFile's rows are read whole or, when there are more than ``limit``, evenly
decimated without loading the file: binary rows (PLY, NPY, PCD) every k-th, read a few
megabytes at a time; text rows (CSV, XYZ, ASCII PLY and PCD) as SPANS runs of consecutive
rows spread evenly through the file (a run of rows is a fair sample of a ``random`` run,
whose every stretch is). LAS/LAZ (las.py) and USD (usd.py) have files of their own with
the same fields and methods: LAS is read in runs too, a USD stage whole.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import os
from typing import Callable

import numpy as np

from ..errors import ScatterError
from .base import copy_range, reading
from .formats import SUFFIXES, load

POINT_SUFFIXES = tuple("." + s for s in SUFFIXES)  # every suffix scatter writes
SPANS = 64  # runs of consecutive rows read from a large text or LAS/LAZ file
BLOCK_ROWS = 8192  # rows kept per block read: a block is k * BLOCK_ROWS rows, a few MB
READ_BLOCK = 1 << 22  # bytes read at a time when counting lines
NORMAL_NAMES = ("nx", "ny", "nz")
COLOR_NAMES = ("red", "green", "blue")


class IsMesh(ScatterError):
    """The file is a mesh (a PLY with faces, a USD stage without points), not points."""


@dataclasses.dataclass(frozen=True)
class PointFile:
    """A point file of rows, as its header describes it.

    ``dtype``: one row, a field per column named as the format names it (for text rows,
    the type a column is read as); ``count`` rows from byte ``offset`` to ``end``,
    ``binary`` (packed as ``dtype``) or lines of text separated by ``sep`` (None: blank
    space); ``layout``: what files must share to be joined; ``head(count)``: the bytes of
    this file's header for ``count`` points; ``up_axis``: "Z" (the formats say nothing).
    """

    path: str
    dtype: np.dtype
    count: int
    offset: int
    end: int
    binary: bool
    layout: object
    head: Callable[[int], bytes]
    sep: str | None = None
    up_axis: str = "Z"

    @classmethod
    def checked(cls, path, dtype, count, offset, binary, layout, head, sep=None):
        """The file whose header says ``count`` rows from ``offset``, once its body holds
        them: ``dtype.itemsize`` bytes each when ``binary``, else a line each."""
        end = file_bytes(path)
        if binary and end - offset != count * dtype.itemsize:
            raise body_error(path, end - offset, count, dtype.itemsize)
        if not binary and (lines := count_lines(path, offset, end)) != count:
            raise ScatterError(f"{path}: {lines} rows, the header says {count}")
        return cls(path, dtype, count, offset, end, binary, layout, head, sep)

    def columns(self, limit=None) -> dict:
        """name -> (m,) array of each column: of every row, or of about ``limit`` rows
        spread evenly through the file (m <= count)."""
        if self.binary:
            rows = every_kth(self.path, self.dtype, self.offset, self.count, limit)
            return {name: rows[name] for name in self.dtype.names}
        table = text_table(self.path, self.offset, self.count, limit, self.sep, len(self.dtype))
        return {name: declared(table[:, j], self.dtype[name]) for j, name in enumerate(self.dtype.names)}

    def join(self, files, stream):
        """Write ``files`` (this one first, all of its layout) to ``stream`` as one file:
        this header for their total count, then the rows of each as they are."""
        stream.write(self.head(sum(f.count for f in files)))
        for f in files:
            copy_range(f.path, f.offset, f.end, stream)


def body_error(path, have, count, row):
    """The error for ``have`` bytes of points where the header says ``count`` rows of ``row``."""
    short = " (truncated?)" if have < count * row else ""
    return ScatterError(f"{path}: {have} bytes of points, the header says {count} of {row} bytes{short}")


def point_format(path):
    """The format scatter writes that the suffix of ``path`` names, or None."""
    return SUFFIXES.get(os.path.splitext(os.fspath(path))[1].lstrip(".").lower())


def read_file(path, fmt=None):
    """The point file ``path`` through the reader of ``fmt`` (else its suffix's format)."""
    path = os.fspath(path)
    fmt = fmt or point_format(path)
    if fmt is None:
        raise ScatterError(f"{path}: not a point file scatter writes ({', '.join(POINT_SUFFIXES)})")
    with plain_errors(path):
        return load(fmt).read(path, fmt)


@contextlib.contextmanager
def plain_errors(path):
    """A reader's or NumPy's error on a malformed file as a one-line ScatterError naming it."""
    try:
        yield
    except ScatterError:
        raise
    except (ValueError, IndexError, KeyError) as exc:
        raise ScatterError(f"{path}: cannot read the points: {reason(exc)}") from None


def reason(exc) -> str:
    """The first line of what ``exc`` says, or the name of its type."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


# ---- preview: points and the columns it colours by ----

@dataclasses.dataclass
class PointSet:
    """``points`` (m, 3) float64, ``attributes`` name -> (m, k) or (m,) array (``color``
    (m, 3) uint8, ``normal`` (m, 3), ``inside`` (m,), ``sdf`` (m,), ``sharp`` (m,)), ``total``: the points
    in the file (m <= total when decimated), ``up_axis``: "Z" or "Y"."""

    points: np.ndarray
    attributes: dict
    total: int
    up_axis: str = "Z"


def read_points(path, limit=None) -> PointSet:
    """The points of the point file ``path``: all, or about ``limit`` spread evenly."""
    f = read_file(path)
    with plain_errors(f.path):
        return from_columns(f.path, f.columns(limit), f.count, f.up_axis)


def from_columns(path, columns, total, up_axis="Z"):
    """A PointSet from ``columns``: name -> (m,) array, named as the contract names them."""
    missing = [c for c in "xyz" if c not in columns]
    if missing:
        raise ScatterError(f"{path}: no {', '.join(missing)} column")
    points = np.stack([np.asarray(columns[c], dtype=np.float64) for c in "xyz"], axis=1)
    attributes = {}
    if all(n in columns for n in NORMAL_NAMES):
        attributes["normal"] = np.stack([np.asarray(columns[n], dtype=np.float64) for n in NORMAL_NAMES], axis=1)
    if all(n in columns for n in COLOR_NAMES):
        attributes["color"] = np.stack([np.asarray(columns[n]) for n in COLOR_NAMES], axis=1).astype(np.uint8)
    for name in ("inside", "sdf", "sharp"):
        if name in columns:
            attributes[name] = np.asarray(columns[name], dtype=np.float64)
    return PointSet(points, attributes, total, up_axis)


def stride(total, limit):
    """k: reading every k-th of ``total`` rows keeps at most ``limit``."""
    return 1 if limit is None or total <= limit else math.ceil(total / limit)


# ---- the rows ----

def file_bytes(path):
    with reading(path):
        return os.path.getsize(path)


def count_lines(path, start, end):
    """The lines of the file from byte ``start`` to its ``end``, checking that the last
    one ends with a newline."""
    if end <= start:
        return 0
    lines = 0
    with reading(path), open(path, "rb") as f:
        f.seek(end - 1)
        if f.read(1) != b"\n":
            raise ScatterError(f"{path}: the last line has no newline (truncated?)")
        f.seek(start)
        while block := f.read(READ_BLOCK):
            lines += block.count(b"\n")
    return lines


def every_kth(path, dtype, offset, total, limit):
    """Every k-th of ``total`` records of ``dtype`` from byte ``offset`` (k from
    ``limit``), as a structured array, reading the file in blocks of k * BLOCK_ROWS rows
    so that memory stays at one block whatever the file's size."""
    k = stride(total, limit)
    out = np.empty(-(-total // k), dtype=dtype)
    with reading(path), open(path, "rb") as f:
        f.seek(offset)
        done = 0
        for start in range(0, total, k * BLOCK_ROWS):
            rows = np.fromfile(f, dtype=dtype, count=min(k * BLOCK_ROWS, total - start))
            kept = rows[::k]
            out[done : done + len(kept)] = kept
            done += len(kept)
    return out


def text_table(path, offset, total, limit, sep, width):
    """(m, width) float64 of the rows of a text file from byte ``offset``: all of them,
    or SPANS runs of consecutive rows spread evenly through the file when over ``limit``."""
    with reading(path), open(path, "rb") as f:
        if limit is None or total <= limit:
            f.seek(offset)
            text = f.read()
        else:
            text = b"".join(_spans(f, offset, os.path.getsize(path), math.ceil(limit / SPANS)))
    if not text.strip():
        return np.empty((0, width))
    table = np.loadtxt(io.BytesIO(text), delimiter=sep, ndmin=2, dtype=np.float64)
    if table.shape[1] != width:
        raise ScatterError(f"{path}: {table.shape[1]} columns, the header names {width}")
    return table


def _spans(f, offset, size, rows):
    """Runs of ``rows`` whole lines starting at SPANS evenly spaced bytes of a file."""
    for j in range(SPANS):
        f.seek(offset + (size - offset) * j // SPANS)
        if j:
            f.readline()  # the rest of a line begun before
        for _ in range(rows):
            line = f.readline()
            if not line.endswith(b"\n"):
                break
            yield line


def declared(column, dtype):
    """A text column (float64) as the integer type its header declares (PCD's packed
    colour, counts); real columns stay float64."""
    return column.astype(dtype) if dtype.kind in "iu" else column
