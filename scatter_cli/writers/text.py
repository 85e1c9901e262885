"""Text rows: CSV (a header line, comma separated) and XYZ (space separated, no header),
and the encoder ASCII PLY and PCD use too."""

from __future__ import annotations

import numpy as np

from ..errors import ScatterError
from .base import Writer
from .parts import Part, count_lines, open_part, size


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


# -- merge ------------------------------------------------------------------------------

def read_part(path, fmt):
    """A CSV part (its first line is the header) or an XYZ part."""
    if fmt == "csv":
        return csv_part(path)
    return xyz_part(path)


def csv_part(path):
    with open_part(path) as f:
        first = f.readline()
    if not first.endswith(b"\n"):
        raise ScatterError(f"{path}: not a CSV file with a header line")
    header = first.decode("ascii", "replace").strip()
    return Part(path, ("csv", header), count_lines(path, len(first)), (len(first), size(path)), lambda parts: first)


def xyz_part(path):
    with open_part(path) as f:
        first = f.readline()
    columns = len(first.split())
    return Part(path, ("xyz", columns), count_lines(path, 0), (0, size(path)), lambda parts: b"")
