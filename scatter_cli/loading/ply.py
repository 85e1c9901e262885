"""PLY files: the one header parser (mesh files and point files alike), and a NumPy reader
for binary PLY triangle meshes, so a plain job need not import trimesh.

:func:`parse_header` reads a header as the PLY specification writes it and names, in one
line, what is wrong with one that is not: :mod:`scatter_cli.loading.fast` (ASCII meshes),
the mesh loader's error for a file trimesh cannot read, and the point files of
:mod:`scatter_cli.writers.ply` (``merge`` and ``preview``) all read headers through it.

Importing trimesh costs about 0.12 s, more than a whole small job. The mesh reader handles
the common case only: a binary PLY (either byte order) whose elements are ``vertex``
(scalar properties including x, y, z) and then ``face`` (one list property of three
indices per face, and scalar properties beside it, such as an STL attribute or face
colours, which trimesh keeps apart from the triangles: skipped, and read only for jobs
not asking for colours). For anything else it returns None and the caller loads
the file with trimesh. When it answers, it gives the arrays trimesh gives with
``process=False``.
"""

import contextlib
import mmap
import os
from typing import NamedTuple

import numpy as np

PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
BYTE_ORDERS = {"ascii": "<", "binary_little_endian": "<", "binary_big_endian": ">"}  # ASCII: as it is read
MAX_HEADER = 1 << 16  # bytes a header may take
SKIPPED = ("comment", "obj_info")  # header lines that say nothing of the body
INDEX_NAMES = {"vertex_indices", "vertex_index"}  # the face list trimesh reads as triangles


class HeaderError(ValueError):
    """A PLY header that is not one; the message says what is wrong, in one line."""


class Element(NamedTuple):
    """One element of a header: its ``name``, ``count`` and ``properties``, each
    ``(type, name)`` or ``("list", count type, item type, name)``, as the header words them."""

    name: str
    count: int
    properties: tuple

    @property
    def scalar(self) -> bool:
        """Whether every property is a scalar (no list)."""
        return all(len(p) == 2 for p in self.properties)

    def dtype(self, order="<") -> np.dtype:
        """The record of one row of scalar properties, in the byte ``order`` ("<" or ">")."""
        return np.dtype([(name, order + PLY_TYPES[kind]) for kind, name in self.properties])


class Header(NamedTuple):
    """A parsed PLY header: ``encoding`` (ascii, binary_little_endian or
    binary_big_endian), its ``elements`` in file order, its ``lines`` (from ``ply`` to
    ``end_header``, as in the file, without their newline) and ``body``, the offset of
    the first byte after it."""

    encoding: str
    elements: tuple
    lines: tuple
    body: int

    @property
    def order(self) -> str:
        return BYTE_ORDERS[self.encoding]

    def names(self):
        return [e.name for e in self.elements]


def parse_header(head) -> Header:
    """The Header at the start of ``head`` (the file's first bytes, up to MAX_HEADER);
    HeaderError saying what is wrong with a header that is not one.

    The header is the lines from ``ply`` to the first ``end_header``: a ``format`` line
    (ascii, binary_little_endian or binary_big_endian, version 1.0), ``element NAME
    COUNT`` lines each followed by its ``property`` lines, and ``comment`` or
    ``obj_info`` lines anywhere. Blank space is any run of spaces or tabs; a line may end
    in CR LF."""
    lines, body = _header_lines(head)
    encoding, elements = None, []
    for number, line in enumerate(lines[1:-1], 2):
        words = line.split()
        if words[:1] == ["format"] and len(words) == 3 and words[1] in BYTE_ORDERS and words[2] == "1.0":
            if encoding is None:
                encoding = words[1]
                continue
        elif words[:1] == ["element"] and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
            continue
        elif words[:1] == ["property"] and elements and _is_property(words[1:]):
            elements[-1][2].append(tuple(words[1:]))
            continue
        elif words[:1] and words[0] in SKIPPED:
            continue
        raise _malformed(number, line)
    if encoding is None:
        raise HeaderError("malformed PLY header: no format line")
    return Header(encoding, tuple(Element(n, c, tuple(p)) for n, c, p in elements), lines, body)


def _header_lines(head):
    """(the header's lines, from ``ply`` to the first line with the word ``end_header``,
    which must be that word alone; the offset of the byte after it)."""
    raw = bytes(head[:MAX_HEADER]).split(b"\n")
    if raw[0].strip() != b"ply":
        raise HeaderError("not a PLY file (its first line is not 'ply')")
    last = next((k for k, line in enumerate(raw) if b"end_header" in line.split()), len(raw) - 1)
    if last == len(raw) - 1:  # none, or in the last line read, which may go on
        raise HeaderError(f"malformed PLY header: no end_header line (within its first {MAX_HEADER >> 10} KiB)")
    try:
        lines = tuple(line.decode("ascii") for line in raw[: last + 1])
    except UnicodeDecodeError:
        raise HeaderError("malformed PLY header: it is not ASCII text") from None
    if lines[-1].split() != ["end_header"]:
        raise _malformed(len(lines), lines[-1])
    return lines, sum(len(line) + 1 for line in raw[: last + 1])


def _malformed(number, line):
    return HeaderError(f"malformed PLY header at line {number}: {line.strip()[:80]!r}")


def _is_property(words):
    """Whether ``words`` (after ``property``) declare a scalar or a list of known types."""
    if len(words) == 2:
        return words[0] in PLY_TYPES
    return len(words) == 4 and words[0] == "list" and words[1] in PLY_TYPES and words[2] in PLY_TYPES


def header_error(head):
    """What is wrong with the PLY header at the start of ``head``, or None."""
    try:
        parse_header(head)
    except HeaderError as exc:
        return str(exc)
    return None


def truncation(data):
    """Where a PLY ends that holds fewer rows than its header declares, in words for a
    message ("truncated: the file ends at byte B, at face 8 of 20 ..."); None when it
    holds them all, or when that cannot be told (a header that is not one, binary lists
    of varying length). ``data``: the file's bytes (any buffer)."""
    try:
        header = parse_header(data)
    except HeaderError:
        return None
    rows = _ascii_rows(header, data) if header.encoding == "ascii" else _binary_rows(header, data)
    short = next(((e, k) for e, k in zip(header.elements, rows or ()) if k < e.count), None)
    if short is None:
        return None
    element, held = short
    declared = " and ".join(f"{e.count:,} {e.name}" for e in header.elements)
    return (f"truncated: the file ends at byte {len(data):,}, at {element.name} {held + 1:,} of {element.count:,} "
            f"(of the {declared} rows its header declares)")


def _ascii_rows(header, data):
    """The rows of each element an ASCII body holds, a row a line. A last line without its
    newline counts when it holds as many values as its row has (a file may end without
    one, as trimesh and the fast reader take it); else it was cut short."""
    body = bytes(data[header.body :])
    if body.count(b"\n") >= sum(e.count for e in header.elements):
        return None
    lines = [line for line in body.split(b"\n") if line.strip()]
    held = len(lines)
    if lines and not body.endswith(b"\n") and not _whole_row(lines[-1].split(), header.elements, held - 1):
        held -= 1
    return _share_out(held, header.elements)


def _whole_row(values, elements, row):
    """Whether ``values`` (the words of a line) are as many as row ``row`` of the body has:
    one a scalar property, a list's length and then that many."""
    for e in elements:
        if row < e.count:
            break
        row -= e.count
    else:
        return False
    at = 0
    for p in e.properties:
        if len(p) == 2:
            at += 1
            continue
        try:
            at += 1 + int(values[at])
        except (IndexError, ValueError):
            return False
    return at == len(values)


def _share_out(held, elements):
    """``held`` rows, in element order: the rows of each element."""
    rows = []
    for e in elements:
        rows.append(min(held, e.count))
        held -= rows[-1]
    return rows


def _binary_rows(header, data):
    """The rows of each element a binary body holds; None when a list's length varies
    from row to row (its rows cannot be counted without reading them all)."""
    pos, rows = header.body, []
    for e in header.elements:
        size = _row_size(e, data, pos, header.order)
        if size is None:
            return None
        rows.append(min(e.count, (len(data) - pos) // size) if size else e.count)
        if rows[-1] < e.count:
            return rows
        pos += size * e.count
    return rows


def _row_size(element, data, pos, order):
    """The bytes of each row of ``element`` whose rows start at ``pos``: fixed for scalar
    properties; for lists, those of the first row when every row present has the same
    list lengths, else None. 1 when even the first row is cut short (none held)."""
    size, lists = 0, []
    for p in element.properties:
        if len(p) == 2:
            size += np.dtype(PLY_TYPES[p[0]]).itemsize
            continue
        count_type = np.dtype(order + PLY_TYPES[p[1]])
        if pos + size + count_type.itemsize > len(data):
            return 1
        n = int(np.frombuffer(data, count_type, 1, pos + size)[0])
        lists.append((size, count_type, n))
        size += count_type.itemsize + n * np.dtype(PLY_TYPES[p[2]]).itemsize
    fit = min(element.count, (len(data) - pos) // size) if size else 0
    for at, count_type, n in lists:
        counts = np.ndarray((fit,), count_type, data, pos + at, (size,))
        if (counts != n).any():
            return None
    return size


def read_triangles(path):
    """(vertices (V, 3) float64, faces (F, 3) int64) of a binary PLY, or None."""
    with contents(path) as data:
        return None if data is None else read_triangles_from(data)


def read_triangles_from(data, smooth=False, color=False):
    """read_triangles on the bytes of a file (any buffer). ``smooth``, ``color``: also
    the vertex normals, colours trimesh would give (:func:`vertex_tables`), as a third
    item, a dict; None when the file has what the tables do not cover."""
    try:
        header = parse_header(data)
        layout = _layout(header)
        if layout is None:
            return None
        vertex, n_vertex, face, n_face = layout
        if color and len(face.names) > 2:
            return None  # face colours: trimesh's visuals decide which colours count
        sizes = (vertex.itemsize * n_vertex, face.itemsize * n_face)
        if header.body + sum(sizes) != len(data):
            return None  # truncated, trailing bytes or counts that do not fit: trimesh says which
    except (ValueError, TypeError):  # a header that is not one, a property named twice
        return None
    v = np.frombuffer(data, dtype=vertex, count=n_vertex, offset=header.body)
    t = np.frombuffer(data, dtype=face, count=n_face, offset=header.body + sizes[0])
    if n_face and not (t["n"] == 3).all():
        return None  # polygons: trimesh triangulates them
    vertices = np.empty((n_vertex, 3))
    for k, axis in enumerate("xyz"):
        vertices[:, k] = v[axis]
    if not (smooth or color):
        return vertices, t["i"].astype(np.int64)
    tables = vertex_tables({n: v[n] for n in v.dtype.names}, smooth, color)
    return None if tables is None else (vertices, t["i"].astype(np.int64), tables)


_NORMALS = ("nx", "ny", "nz")
_COLORS = ("red", "green", "blue", "alpha")
_TEXTURE_COORDINATES = {"texture_u", "texture_v", "u", "v", "s", "t"}


def vertex_tables(columns, smooth, color):
    """The keyword arguments of a :class:`~scatter_cli.surface.data.VertexTables` for what a
    PLY's vertex properties give, as trimesh's PLY loader and Trimesh give them.

    columns: property name -> (V,) array of the property's own type, as trimesh holds
    it. Gives ``normals`` (V, 3) float64 (nx, ny, nz as they are, when all three are
    there) and ``vertex_colors`` (V, 4) float64 (trimesh's ``to_rgba`` of red, green,
    blue and alpha: integers cast to uint8, floats times 255, clipped and rounded, alpha
    255 when absent), each only when asked for. None (hand the file to trimesh) when the
    vertices carry texture coordinates: trimesh then splits them by UV and keeps neither.
    """
    if _TEXTURE_COORDINATES & set(columns):
        return None
    tables = {}
    if smooth and set(_NORMALS) <= set(columns):
        tables["normals"] = np.column_stack([columns[n] for n in _NORMALS]).astype(np.float64)
    if color and set(_COLORS[:3]) <= set(columns):
        tables["vertex_colors"] = _rgba(np.column_stack([columns[n] for n in _COLORS if n in columns]))
    return tables


def _rgba(c):
    """(V, 3|4) colours of any type -> (V, 4) float64 of trimesh's uint8 RGBA (to_rgba)."""
    if c.dtype.kind == "f":
        c[~np.isfinite(c)] = 0.0
        with np.errstate(over="ignore"):  # float32 beyond 3.4e38 / 255: inf, clipped to 255
            c = np.clip(c * 255, 0.0, 255).round()
    if c.shape[1] == 3:
        c = np.column_stack((c, 255 * np.ones(len(c))))
    return c.astype(np.uint8).astype(np.float64)


MAP_FROM = 1 << 20  # bytes: a smaller file is read (mapping it costs more system calls than it saves)


@contextlib.contextmanager
def contents(path):
    """The bytes of the file at ``path`` (:func:`_contents`), None when it cannot be read.
    A mapping is closed on leaving, unless an array still views it: it then closes with
    the last such array."""
    try:
        with open(path, "rb") as f:
            data = _contents(f)
    except OSError:
        data = None
    try:
        yield data
    finally:
        if hasattr(data, "close"):
            try:
                data.close()
            except BufferError:
                pass


def _contents(f):
    """The bytes of file ``f``: a large file mapped read-only where possible (reading it
    into fresh memory costs more than converting it), else read. A mapping stays open
    only as long as arrays view it."""
    try:
        if os.fstat(f.fileno()).st_size < MAP_FROM:
            return f.read()
        return mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
    except (OSError, ValueError):  # a file system that cannot map
        f.seek(0)
        return f.read()


def _layout(header):
    """(vertex dtype, vertex count, face dtype, face count) of a binary mesh of ``vertex``
    (scalar properties including x, y, z) then ``face`` elements, or None."""
    if header.encoding == "ascii" or header.names() != ["vertex", "face"]:
        return None
    vertex, face = header.elements
    if not vertex.scalar or {"x", "y", "z"} - {name for _, name in vertex.properties}:
        return None
    face_dtype = _face_dtype(face.properties)
    if face_dtype is None:
        return None
    return vertex.dtype(header.order), vertex.count, face_dtype.newbyteorder(header.order), face.count


def _face_dtype(fprops):
    """The face record: ``n`` (the corner count), ``i`` (three indices) and the scalar
    properties beside the list (``e0``, ``e1``... in file order), or None. One list only
    (a second, such as ``texcoord``, trimesh reads), named as trimesh looks for it, and no
    other property with that name or a name given twice (trimesh keeps one of each name)."""
    lists = [k for k, p in enumerate(fprops) if p[0] == "list"]
    if len(lists) != 1:
        return None
    _, count_type, index_type, name = fprops[lists[0]]
    if name not in INDEX_NAMES or PLY_TYPES[index_type][0] == "f":
        return None
    names = [p[-1] for p in fprops]
    if len(set(names)) != len(names) or len(INDEX_NAMES & set(names)) != 1:
        return None
    fields = []
    for k, p in enumerate(fprops):
        if k == lists[0]:
            fields += [("n", PLY_TYPES[count_type]), ("i", PLY_TYPES[index_type], 3)]
        else:
            fields.append((f"e{k}", PLY_TYPES[p[0]]))
    return np.dtype(fields)

