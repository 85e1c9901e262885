"""Text rows: CSV (a header line, comma separated) and XYZ (space separated, no header),
and the encoder ASCII PLY and PCD use too; and their reader."""

from __future__ import annotations

import numpy as np

from ..errors import ScatterError
from .base import Writer, reading
from .pointfiles import PointFile, count_lines, file_bytes


class TextEncoder:
    """Rows of text with enough digits to read back the exact binary values.

    float32: 9 significant digits; float64: the shortest repr that round-trips.
    """

    def __init__(self, layout, sep):
        self.layout = layout
        specs = []
        for _, cols, dt in layout:
            spec = {"f4": "%.9g", "f8": "%r"}.get(dt.str[1:], "%d")
            specs += [spec] * len(cols)
        self.ncols = len(specs)
        self.row = sep.join(specs) + "\n"

    def __call__(self, samples):
        n = len(samples)
        flat = [None] * (n * self.ncols)
        j = 0
        for key, cols, dt in self.layout:
            data = samples.points if key == "points" else samples.attributes[key]
            data = np.asarray(data, dtype=dt).reshape(n, len(cols))
            for c in range(len(cols)):
                flat[j :: self.ncols] = data[:, c].tolist()
                j += 1
        return ((self.row * n) % tuple(flat)).encode("ascii")


_TextEncoder = TextEncoder  # the name other branches import


class TextWriter(Writer):
    def __init__(self, stream, layout, count, sep, with_header):
        super().__init__(stream, layout, count)
        self.encode = TextEncoder(layout, sep)
        self.sep = sep
        self.with_header = with_header

    def header(self):
        if self.with_header:
            cols = [c for _, names, _ in self.layout for c in names]
            self.stream.write((self.sep.join(cols) + "\n").encode("ascii"))


def make(fmt, stream, layout, count, **options):
    """The writer of ``fmt`` (csv or xyz)."""
    return TextWriter(stream, layout, count, "," if fmt == "csv" else " ", fmt == "csv")


# -- the reader ---------------------------------------------------------------------------

class XyzFile(PointFile):
    def columns(self, limit=None):
        """x, y, z, then nx, ny, nz when the next three columns are unit vectors (the
        columns scatter writes come in the order normal, orient, face, ...)."""
        columns = super().columns(limit)
        if len(columns) >= 6:
            names = self.dtype.names[3:6]
            lengths = np.linalg.norm(np.stack([columns[n] for n in names], axis=1), axis=1)
            if len(lengths) and np.all(np.abs(lengths - 1.0) < 1e-3):
                columns.update((normal, columns.pop(n)) for normal, n in zip(("nx", "ny", "nz"), names))
        return columns


def read(path, fmt):
    """A CSV file (its first line names the columns) or an XYZ file (no header: x y z
    first, as many columns as its first line has)."""
    with reading(path), open(path, "rb") as f:
        first = f.readline()
    end = file_bytes(path)
    return csv_file(path, first, end) if fmt == "csv" else xyz_file(path, first, end)


def csv_file(path, first, end):
    if not first.endswith(b"\n"):
        raise ScatterError(f"{path}: not a CSV file with a header line")
    header = first.decode("ascii", "replace").strip()
    dtype = real_columns(n.strip() for n in header.split(","))
    return PointFile(path, dtype, count_lines(path, len(first), end), len(first), end, False, ("csv", header),
                     lambda count: first, ",")


def xyz_file(path, first, end):
    width = len(first.split())
    if 0 < width < 3:
        raise ScatterError(f"{path}: fewer than three columns")
    dtype = real_columns(["x", "y", "z", *(f"column {j}" for j in range(3, width))])
    return XyzFile(path, dtype, count_lines(path, 0, end), 0, end, False, ("xyz", width), lambda count: b"")


def real_columns(names):
    """The row of text columns ``names``, each read as float64."""
    return np.dtype([(n, "<f8") for n in names])
