"""PLY output: one ``vertex`` element, binary little-endian or ASCII."""

from __future__ import annotations

import numpy as np

from ..errors import ScatterError
from .binary import BinaryWriter, row_size
from .parts import Part, check_rows, open_part, size
from .text import TextEncoder

PLY_TYPES = {"f4": "float", "f8": "double", "i4": "int", "u1": "uchar"}


def header(layout, count, ascii=False) -> bytes:
    """The PLY header for ``count`` points of ``layout``."""
    lines = ["ply", f"format {'ascii' if ascii else 'binary_little_endian'} 1.0",
             "comment made by scatter", f"element vertex {count}"]
    for _, cols, dt in layout:
        lines += [f"property {PLY_TYPES[dt.str[1:]]} {c}" for c in cols]
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("ascii")


class PlyWriter(BinaryWriter):
    def __init__(self, stream, layout, count, ascii=False):
        super().__init__(stream, layout, count)
        self.ascii = ascii
        if ascii:
            self.encode = TextEncoder(layout, " ")

    def header(self):
        self.stream.write(header(self.layout, self.count, self.ascii))


def make(fmt, stream, layout, count, ascii=False, **options):
    return PlyWriter(stream, layout, count, ascii)


def file_size(fmt, layout, count, **options):
    """Bytes of a binary PLY file of ``count`` points of ``layout``."""
    return len(header(layout, count)) + count * row_size(layout)


# -- merge ------------------------------------------------------------------------------

def read_part(path, fmt="ply"):
    """A binary little-endian or ASCII PLY of one vertex element."""
    with open_part(path) as f:
        head = f.read(65536)
    end = head.find(b"end_header\n")
    if not head.startswith(b"ply\n") or end < 0:
        raise ScatterError(f"{path}: not a PLY file")
    lines = head[:end].decode("ascii", "replace").splitlines()
    encoding = lines[1].split()[1] if len(lines) > 1 and len(lines[1].split()) > 1 else ""
    elements = [ln.split() for ln in lines if ln.startswith("element ")]
    if len(elements) != 1 or elements[0][1] != "vertex" or encoding not in ("ascii", "binary_little_endian"):
        raise ScatterError(f"{path}: not a point PLY of one vertex element (ascii or binary little-endian)")
    count = int(elements[0][2])
    props = tuple(tuple(ln.split()[1:]) for ln in lines if ln.startswith("property "))
    offset = end + len(b"end_header\n")
    sizes = {v: np.dtype(k).itemsize for k, v in PLY_TYPES.items()}
    row = sum(sizes.get(p[0], 0) for p in props)
    check_rows(path, encoding == "binary_little_endian", offset, count, row)
    return Part(path, (encoding, props), count, (offset, size(path)), _merged_header(lines))


def _merged_header(lines):
    def merged(parts):
        total = sum(p.count for p in parts)
        out = [f"element vertex {total}" if ln.startswith("element vertex ") else ln for ln in lines]
        return ("\n".join(out) + "\nend_header\n").encode("ascii")

    return merged
