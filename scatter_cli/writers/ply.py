"""PLY output: one ``vertex`` element, binary little-endian or ASCII; and its reader."""

from __future__ import annotations

from ..errors import ScatterError
from ..loading.ply import MAX_HEADER, HeaderError, contents, parse_header, truncation
from .base import reading
from .binary import BinaryWriter, row_size
from .pointfiles import IsMesh, PointFile
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


# -- the reader ---------------------------------------------------------------------------

def read(path, fmt="ply"):
    """A point PLY: a ``vertex`` element of scalar properties first, any other element
    empty; binary (either byte order) or ASCII. Its header is read by the one PLY header
    parser, the mesh readers' (:func:`scatter_cli.loading.ply.parse_header`)."""
    with reading(path), open(path, "rb") as f:
        head = f.read(MAX_HEADER)
    try:
        header = parse_header(head)
    except HeaderError as exc:
        raise ScatterError(f"{path}: {exc}") from None
    if any(e.name == "face" and e.count for e in header.elements):
        raise IsMesh(f"{path}: a PLY with faces is a mesh, not a point file")
    if header.names()[:1] != ["vertex"] or any(e.count for e in header.elements[1:]):
        raise ScatterError(f"{path}: not a point PLY (a vertex element first, any other empty)")
    vertex = header.elements[0]
    if not vertex.scalar:
        raise ScatterError(f"{path}: vertex list properties are not point columns")
    layout = ("ply", header.encoding, tuple((e.name, e.properties) for e in header.elements))
    try:
        return PointFile.checked(path, vertex.dtype(header.order), vertex.count, header.body,
                                 header.encoding != "ascii", layout, lambda count: with_vertex_count(header, count))
    except ScatterError:
        with contents(path) as data:  # a short body: said where it ends, as the mesh loader says it
            problem = None if data is None else truncation(data)
        if problem:
            raise ScatterError(f"{path}: {problem}") from None
        raise


def with_vertex_count(header, count) -> bytes:
    """The bytes of ``header`` (a parsed Header) with its vertex count set to ``count``."""
    at = next(k for k, line in enumerate(header.lines) if line.split()[:2] == ["element", "vertex"])
    lines = [*header.lines[:at], f"element vertex {count}", *header.lines[at + 1 :]]
    return ("\n".join(lines) + "\n").encode("ascii")
