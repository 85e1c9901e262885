"""Fast readers for plain jobs: OBJ, OFF, PLY, STL and GLB without trimesh.

Each reader gives the triangles trimesh gives with ``process=False`` (same corners, same
order, same split into geometries), or None when the file holds anything it is not sure
of; the caller then loads the file with trimesh, which also words the error for a
malformed file. The text formats are parsed by the compiled ``_creaders`` (without it,
or with SCATTER_NUMPY=1, they go to trimesh); binary STL and GLB (gltf.py) are
read with NumPy. The rules and the measurements behind the choice are in docs/loading.md.
"""

from __future__ import annotations

import os

import numpy as np

from ..core import native
from ..core.native import in_blocks, worker_count
from .ply import INDEX_NAMES, PLY_TYPES, HeaderError, contents, parse_header

_STL_RECORD = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
MAX_COUNT = 10**18  # a count of 19 digits or more: no file holds it, nor the compiled reader's int64
_kernel = native.kernel("_creaders")  # the text parsers; None: trimesh reads those files


def read_file(path, read, smooth=False, color=False, uv=False):
    """``read`` (one of the ``read_*`` functions below, as load.LOADERS names them) of
    the bytes of the file at ``path``: a list of (vertices (V, 3) float64, faces (F, 3)
    int64), one per geometry in trimesh's order; for a GLB, a scene: (geometries [(name,
    vertices, faces)], instances [(name, geometry index, (4, 4) matrix or None)])
    (gltf.py); or None (hand the file to trimesh).

    ``smooth``: smooth normals are wanted: a PLY's own normals come as a third item of its
    geometry, a dict (ply.vertex_tables); other files with normals or UVs of their
    own are handed over (the caller computes smooth normals from the faces, as trimesh
    does for the others). ``color``: vertex colours are wanted: only PLY is read (its
    colours in that dict), every other format handed over. ``uv``: texture coordinates
    are wanted: only OBJ is read. An OBJ read for ``smooth`` or ``uv`` has the geometries
    trimesh makes of groups with ``vt`` or ``vn`` refs (its vertex split, obj.py)
    and their UVs and normals in that dict.
    """
    with contents(path) as data:
        return None if data is None else read(data, path, smooth, color, uv)


def read_ply(data, path, smooth, color, uv):
    return None if uv else _ply(data, smooth, color)


def read_obj(data, path, smooth, color, uv):
    if color or _materials_resolve(data, path):
        return None
    return _obj(data, tables=smooth or uv)


def read_stl(data, path, smooth, color, uv):
    return None if color or uv else _stl(data)  # smooth: normals from the faces, as trimesh


def read_off(data, path, smooth, color, uv):
    return None if color or uv else _off(data)


def read_glb(data, path, smooth, color, uv):
    from .gltf import read_glb as glb

    return None if color or uv else glb(data, without_normals=smooth)  # it looks for NORMAL attributes


def _materials_resolve(data, path):
    """Whether trimesh would find the material library an OBJ names (its first
    ``mtllib``, even in a comment): then it names the geometries by material (with more
    than one) and gives them material visuals, which the fast reader does not."""
    name = _material_library(data)
    return name is not None and _resolves(name, path)


def missing_material_library(path):
    """The material library the OBJ at ``path`` names (its first ``mtllib``) when trimesh
    would not find it beside the file; None when it names none or it is there."""
    with contents(path) as data:
        name = None if data is None else _material_library(data)
    return name if name is not None and not _resolves(name, path) else None


def _material_library(data):
    at = data.find(b"mtllib")
    if at < 0:
        return None
    end = data.find(b"\n", at)
    return bytes(data[at + 6 : end if end >= 0 else len(data)]).decode("utf-8", "replace").strip()


def _resolves(name, path):
    folder = os.path.dirname(os.path.abspath(path))
    return any(os.path.exists(os.path.join(folder, c)) for c in (name, name.lstrip("/"), os.path.split(name)[-1]) if c)


def _obj(data, tables=False):
    """``tables``: with the UVs and normals of groups whose refs carry them (a third
    item, a dict), their vertices split as trimesh splits them."""
    c = _kernel
    got = c and c.read_obj(data, tables, worker_count())  # large files: parts on several threads
    if not got:
        return None
    vertices, faces, counts = got[:3]
    ends = np.cumsum(counts)
    if not tables:
        return [(vertices, faces[end - n : end]) for n, end in zip(counts, ends)]
    from .obj import split_group

    forms, vt, vn = got[3:]
    del got
    parts = []
    for n, end, form in zip(counts, ends, forms):
        if form == 1:  # plain v refs: the file's vertices, normals computed from the faces
            parts.append((vertices, faces[end - n : end], {}))
            continue
        part = split_group(vertices, faces[end - n : end], form.bit_length() - 1, vt, vn)
        if part is None:
            return None
        parts.append(part)
    return parts


def _off(data):
    c = _kernel
    got = c and c.read_off(data, worker_count())  # large files: parts on several threads
    return [got] if got else None


def _stl(data):
    """Binary when the size matches the count in the header (trimesh's test), else ASCII."""
    if len(data) >= 84:
        count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
        if len(data) == 84 + count * _STL_RECORD.itemsize:
            if count == 0:
                return None
            return [_stl_binary(np.frombuffer(data, dtype=_STL_RECORD, count=count, offset=84)["corners"])]
    c = _kernel
    vertices = c and c.read_stl_ascii(data, worker_count())  # large files: parts on several threads
    if vertices is None or vertices is False:
        return None
    return [(vertices, np.arange(len(vertices), dtype=np.int64).reshape(-1, 3))]


def _stl_binary(corners):
    """(vertices (3n, 3) float64, faces (n, 3) int64) of a binary STL's ``corners`` (n, 3, 3)
    float32, each face its own three vertices: one pass from the strided records, in
    blocks on the worker threads (on a 1.3M-face file, most of the time is the first
    touch of 125 MB of new pages, and threads share that too)."""
    n = len(corners)
    vertices, faces = np.empty((3 * n, 3)), np.empty(3 * n, dtype=np.int64)
    rows = vertices.reshape(n, 3, 3)

    def fill(i, j):
        rows[i:j] = corners[i:j]
        faces[3 * i : 3 * j] = np.arange(3 * i, 3 * j)

    in_blocks(fill, n, min_block=1 << 16)
    return vertices, faces.reshape(n, 3)


def _ply(data, smooth=False, color=False):
    from .ply import read_triangles_from

    got = read_triangles_from(data, smooth, color)
    if got is not None:
        return [got]
    layout = _ascii_layout(data)
    c = _kernel
    if layout is None or not c:
        return None
    if smooth or color:
        return _ply_ascii_tables(c, data, *layout, smooth, color)
    got = c.read_ply_ascii(data, *layout[0], b"", worker_count())
    return [got] if got else None


def _ply_ascii_tables(c, data, args, props, smooth, color):
    """_ply's answer for an ASCII PLY with the vertex tables asked for (the columns
    converted to their declared types from the parsed doubles, as trimesh does), or None."""
    from .ply import _COLORS, _NORMALS, _TEXTURE_COORDINATES, vertex_tables

    if _TEXTURE_COORDINATES & {name for name, _ in props}:
        return None
    names = (_NORMALS if smooth else ()) + (_COLORS if color else ())
    wanted = [k for k, (name, _) in enumerate(props) if name in names]
    if any(k > 255 for k in wanted):
        return None
    got = c.read_ply_ascii(data, *args, bytes(wanted), worker_count())
    if not got:
        return None
    vertices, faces, parsed = got if wanted else (*got, None)
    columns = {props[k][0]: _declared(parsed[:, j], props[k][1]) for j, k in enumerate(wanted)}
    del got, parsed
    if any(column is None for column in columns.values()):
        return None
    tables = vertex_tables(columns, smooth, color)
    return None if tables is None else [(vertices, faces, tables)]


def _declared(column, kind):
    """(V,) parsed doubles -> the declared type (trimesh's ``astype``), or None where a
    cast to an integer type would be undefined (outside its range, not finite)."""
    if kind[0] in "iu":
        info = np.iinfo(kind)
        if not ((column > info.min - 1) & (column < info.max + 1)).all():
            return None
    return column.astype(kind)


def _ascii_layout(data):
    """((body offset, vertex count, face count, vertex properties, x, y, z columns, and
    whether each of x, y, z is float32), [(name, NumPy type) of each vertex property])
    for an ASCII PLY of ``vertex`` (scalar properties) then ``face`` (one list of int
    indices), or None."""
    try:
        header = parse_header(data)
    except HeaderError:
        return None
    if header.encoding != "ascii" or header.names() != ["vertex", "face"] or any("\r" in s for s in header.lines):
        return None
    vertex, face = header.elements
    names = [name for _, name in vertex.properties]
    if not vertex.scalar or len(set(names)) != len(names) or {"x", "y", "z"} - set(names):
        return None
    if max(vertex.count, face.count) >= MAX_COUNT or len(face.properties) != 1 or face.properties[0][0] != "list":
        return None
    _, _, index_type, name = face.properties[0]
    if name not in INDEX_NAMES or PLY_TYPES[index_type] not in ("i4", "u4"):
        return None
    columns = [names.index(a) for a in "xyz"]
    kinds = [PLY_TYPES[vertex.properties[k][0]] for k in columns]
    if any(t not in ("f4", "f8") for t in kinds):
        return None
    args = (header.body, vertex.count, face.count, len(names), *columns, *(int(t == "f4") for t in kinds))
    return args, [(name, PLY_TYPES[kind]) for kind, name in vertex.properties]
