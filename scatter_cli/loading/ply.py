"""A NumPy reader for binary PLY triangle meshes, so a plain job need not import trimesh.

Importing trimesh costs about 0.12 s, more than a whole small job. This reader handles
the common case only: a binary PLY (either byte order) whose elements are ``vertex``
(scalar properties including x, y, z) and then ``face`` (one list property of three
indices per face, and scalar properties beside it, such as an STL attribute or face
colours, which trimesh keeps apart from the triangles: skipped, and read only for jobs
not asking for colours). For anything else it returns None and the caller loads
the file with trimesh, which also reports what is wrong with a malformed file. When it
answers, it gives the arrays trimesh gives with ``process=False``.
"""

import mmap
import os

import numpy as np

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_MAX_HEADER = 1 << 16
_INDEX_NAMES = {"vertex_indices", "vertex_index"}


def read_triangles(path):
    """(vertices (V, 3) float64, faces (F, 3) int64) of a binary PLY, or None."""
    try:
        with open(path, "rb") as f:
            data = _contents(f)
    except OSError:
        return None
    return read_triangles_from(data)


def read_triangles_from(data, smooth=False, color=False):
    """read_triangles on the bytes of a file (any buffer). ``smooth``, ``color``: also
    the vertex normals, colours trimesh would give (:func:`vertex_tables`), as a third
    item, a dict; None when the file has what the tables do not cover."""
    try:
        head = bytes(data[:_MAX_HEADER])
        end = head.find(b"end_header")
        if not head.startswith(b"ply") or end < 0:
            return None
        body_at = head.index(b"\n", end) + 1
        layout = _layout(head[:end].decode("ascii").split("\n"))
        if layout is None:
            return None
        order, vertex, n_vertex, face, n_face = layout
        if color and len(face.names) > 2:
            return None  # face colours: trimesh's visuals decide which colours count
        vertex, face = vertex.newbyteorder(order), face.newbyteorder(order)
        sizes = (vertex.itemsize * n_vertex, face.itemsize * n_face)
        if body_at + sum(sizes) != len(data):
            return None  # truncated, trailing bytes or counts that do not fit: trimesh says which
    except (ValueError, UnicodeDecodeError, TypeError):
        return None
    v = np.frombuffer(data, dtype=vertex, count=n_vertex, offset=body_at)
    t = np.frombuffer(data, dtype=face, count=n_face, offset=body_at + sizes[0])
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


def _layout(lines):
    """(byte order, vertex dtype, vertex count, face dtype, face count), or None."""
    fmt = [line.split() for line in lines if line.startswith("format")]
    if len(fmt) != 1 or len(fmt[0]) != 3:
        return None
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt[0][1])
    elements = []
    for k, words in enumerate(line.split() for line in lines):
        if not words and k < len(lines) - 1:
            return None  # a blank header line: trimesh's header parser fails on it
        if not words or words[0] in ("ply", "format", "comment", "obj_info"):
            continue
        if words[0] == "element" and len(words) == 3:
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            elements[-1][2].append(words[1:])
        else:
            return None
    if order is None or [e[0] for e in elements] != ["vertex", "face"]:
        return None
    (_, n_vertex, vprops), (_, n_face, fprops) = elements
    if any(len(p) != 2 or p[0] not in _TYPES for p in vprops) or {"x", "y", "z"} - {p[1] for p in vprops}:
        return None
    face = _face_dtype(fprops)
    if face is None or n_vertex < 0 or n_face < 0:
        return None
    vertex = np.dtype([(p[1], _TYPES[p[0]]) for p in vprops])
    return order, vertex, n_vertex, face, n_face


def _face_dtype(fprops):
    """The face record: ``n`` (the corner count), ``i`` (three indices) and the scalar
    properties beside the list (``e0``, ``e1``... in file order), or None. One list only
    (a second, such as ``texcoord``, trimesh reads), named as trimesh looks for it, and no
    other property with that name or a name given twice (trimesh keeps one of each name)."""
    lists = [k for k, p in enumerate(fprops) if p[:1] == ["list"]]
    if len(lists) != 1 or len(fprops[lists[0]]) != 4:
        return None
    _, count_type, index_type, name = fprops[lists[0]]
    if name not in _INDEX_NAMES or count_type not in _TYPES or index_type not in _TYPES:
        return None
    if _TYPES[index_type][0] == "f":
        return None
    names = [p[-1] for p in fprops]
    if len(set(names)) != len(names) or len(_INDEX_NAMES & set(names)) != 1:
        return None
    fields = []
    for k, p in enumerate(fprops):
        if k == lists[0]:
            fields += [("n", _TYPES[count_type]), ("i", _TYPES[index_type], 3)]
        elif len(p) == 2 and p[0] in _TYPES:
            fields.append((f"e{k}", _TYPES[p[0]]))
        else:
            return None
    return np.dtype(fields)
