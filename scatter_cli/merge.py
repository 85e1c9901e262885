"""``scatter merge``: join point files of one format and one column layout into one.

The shards of a run (``--shard K/M``), joined in order, give that run's bytes: every
format here is a header that carries the count, then the points as rows, so the joined
file is the header written for the total count followed by each part's rows.

Adding a format is one function ``path -> Part`` registered in ``READERS`` under its
format name (as ``writers.infer_format`` names it). The function reads the file's header,
raises ``ScatterError`` naming the file when it is not a point file of that format, and
returns a ``Part`` with:

- ``layout``: anything comparable; parts join only when their layouts are equal;
- ``count``: the number of points in the part;
- ``body``: ``(offset, end)``, the byte range of the points, copied as they are;
- ``header``: ``header(parts) -> bytes``, the merged file's header for the list of parts
  (the first part's function is called, with all of them: a format whose header holds
  more than the count, such as LAS bounds, computes it from all parts).

A format whose points cannot be copied as bytes (LAZ: compressed chunks) sets
``join(parts, stream)`` instead, which writes the whole merged file.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Callable, Optional

import numpy as np

from .errors import ScatterError, ScatterUsageError
from .writers import PLY_TYPES, infer_format, open_output

COPY_BLOCK = 1 << 22


@dataclasses.dataclass
class Part:
    path: str
    layout: object
    count: int
    body: tuple  # (offset, end) of the points in the file
    header: Callable  # header(parts) -> bytes of the merged file
    join: Optional[Callable] = None  # join(parts, stream): writes the merged file itself


def merge(parts, output, fmt=None):
    """Join the point files ``parts`` (in order) into ``output``; returns the point count.

    The format is ``fmt``, else that of the parts' suffix (they must all have it);
    ``output`` must be of that format too.
    """
    paths = [os.fspath(p) for p in parts]
    if not paths:
        raise ScatterUsageError("merge needs at least one part")
    formats = [infer_format(p, fmt) for p in paths]
    for p, f in zip(paths, formats):
        if f != formats[0]:
            raise ScatterError(f"{p}: a {f.upper()} file, not {formats[0].upper()} like {paths[0]}")
    kind = formats[0]
    if output is not None and str(output) != "-" and infer_format(output, fmt) != kind:
        raise ScatterUsageError(f"{output}: the parts are {kind.upper()}, the output must be too")
    if kind not in READERS:
        raise ScatterUsageError(f"merge cannot join {kind.upper()} files yet (it joins: {', '.join(READERS)})")
    read = READERS[kind]
    loaded = []
    for p in paths:
        part = read(p)
        if loaded and part.layout != loaded[0].layout:
            raise ScatterError(f"{p}: columns or types differ from {paths[0]} ({_describe(part.layout)} "
                               f"against {_describe(loaded[0].layout)})")
        loaded.append(part)
    with open_output(output) as stream:
        first = loaded[0]
        if first.join is not None:
            first.join(loaded, stream)
        else:
            stream.write(first.header(loaded))
            for part in loaded:
                _copy_body(part, stream)
    return sum(p.count for p in loaded)


def _describe(layout):
    return str(layout)[:200]


def _copy_body(part, stream):
    start, end = part.body
    with _open(part.path) as f:
        f.seek(start)
        left = end - start
        while left > 0:
            block = f.read(min(COPY_BLOCK, left))
            if not block:
                raise ScatterError(f"{part.path}: the file ended early (truncated?)")
            stream.write(block)
            left -= len(block)


def _open(path):
    try:
        return open(path, "rb")
    except FileNotFoundError:
        raise ScatterError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise ScatterError(f"{path}: is a directory") from None
    except OSError as exc:
        raise ScatterError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _size(path):
    return os.path.getsize(path)


def _count_lines(path, start):
    """Newline count of the file from byte ``start`` on, checking it ends with one."""
    size = _size(path)
    if size <= start:
        return 0
    lines = 0
    with _open(path) as f:
        f.seek(size - 1)
        if f.read(1) != b"\n":
            raise ScatterError(f"{path}: the last line has no newline (truncated?)")
        f.seek(start)
        while block := f.read(COPY_BLOCK):
            lines += block.count(b"\n")
    return lines


# ---- PLY (binary little-endian and ASCII) ----

def ply_part(path):
    with _open(path) as f:
        head = f.read(65536)
    end = head.find(b"end_header\n")
    if not head.startswith(b"ply\n") or end < 0:
        raise ScatterError(f"{path}: not a PLY file")
    lines = head[:end].decode("ascii", "replace").splitlines()
    fmt = lines[1].split()[1] if len(lines) > 1 and len(lines[1].split()) > 1 else ""
    elements = [ln.split() for ln in lines if ln.startswith("element ")]
    if len(elements) != 1 or elements[0][1] != "vertex" or fmt not in ("ascii", "binary_little_endian"):
        raise ScatterError(f"{path}: not a point PLY of one vertex element (ascii or binary little-endian)")
    count = int(elements[0][2])
    props = tuple(tuple(ln.split()[1:]) for ln in lines if ln.startswith("property "))
    offset = end + len(b"end_header\n")
    size = _size(path)
    if fmt == "binary_little_endian":
        sizes = {v: np.dtype(k).itemsize for k, v in PLY_TYPES.items()}
        row = sum(sizes.get(p[0], 0) for p in props)
        if size - offset != count * row:
            raise ScatterError(f"{path}: {size - offset} bytes of points, the header says {count} of {row} bytes")
    elif _count_lines(path, offset) != count:
        raise ScatterError(f"{path}: the number of rows differs from the header's count {count}")
    return Part(path, (fmt, props), count, (offset, size), _ply_header(lines))


def _ply_header(lines):
    def header(parts):
        total = sum(p.count for p in parts)
        out = [f"element vertex {total}" if ln.startswith("element vertex ") else ln for ln in lines]
        return ("\n".join(out) + "\nend_header\n").encode("ascii")

    return header


# ---- CSV and XYZ ----

def csv_part(path):
    with _open(path) as f:
        first = f.readline()
    if not first.endswith(b"\n"):
        raise ScatterError(f"{path}: not a CSV file with a header line")
    header = first.decode("ascii", "replace").strip()
    count = _count_lines(path, len(first))
    return Part(path, ("csv", header), count, (len(first), _size(path)), lambda parts: first)


def xyz_part(path):
    with _open(path) as f:
        first = f.readline()
    columns = len(first.split())
    return Part(path, ("xyz", columns), _count_lines(path, 0), (0, _size(path)), lambda parts: b"")


# ---- NPY ----

def npy_part(path):
    fmt = np.lib.format
    with _open(path) as f:
        try:
            version = fmt.read_magic(f)
            read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, fortran, dtype = read(f)
        except ValueError as exc:
            raise ScatterError(f"{path}: not an NPY file ({exc})") from None
        offset = f.tell()
    if len(shape) != 1 or fortran or dtype.names is None:
        raise ScatterError(f"{path}: not an NPY array of points (one structured row a point)")
    if _size(path) - offset != shape[0] * dtype.itemsize:
        raise ScatterError(f"{path}: the file size does not match its header (truncated?)")
    descr = fmt.dtype_to_descr(dtype)

    def header(parts):
        import io

        buf = io.BytesIO()
        fmt.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False,
                                         "shape": (sum(p.count for p in parts),)})
        return buf.getvalue()

    return Part(path, ("npy", str(descr)), shape[0], (offset, _size(path)), header)


# ---- PCD (binary and ASCII) ----

def pcd_part(path):
    from .pcd import header_from_lines, read_header

    layout, count, offset = read_header(path)
    size = _size(path)
    if "DATA binary" in layout:
        sizes = next((ln.split()[1:] for ln in layout if ln.startswith("SIZE ")), [])
        row = sum(int(x) for x in sizes)
        if size - offset != count * row:
            raise ScatterError(f"{path}: {size - offset} bytes of points, the header says {count} of {row} bytes")
    elif _count_lines(path, offset) != count:
        raise ScatterError(f"{path}: the number of rows differs from the header's count {count}")
    return Part(path, ("pcd", tuple(layout)), count, (offset, size),
                lambda parts: header_from_lines(layout, sum(p.count for p in parts)))


# ---- LAS / LAZ: re-written through laspy (LAZ points are compressed chunks) ----

def las_part(path):
    from .las import layout_of, read_header, write_joined

    head = read_header(path)
    compress = path.lower().endswith(".laz")
    return Part(path, ("las",) + layout_of(head), head.point_count, (0, 0), None,
                lambda parts, stream: write_joined([p.path for p in parts], head, stream, compress))


READERS = {"ply": ply_part, "csv": csv_part, "xyz": xyz_part, "npy": npy_part, "pcd": pcd_part, "las": las_part,
           "laz": las_part}
