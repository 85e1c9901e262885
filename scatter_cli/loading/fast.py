"""Fast readers for plain jobs: OBJ, OFF, PLY, STL and GLB without trimesh.

Each reader gives the triangles trimesh gives with ``process=False`` (same corners, same
order, same split into geometries), or None when the file holds anything it is not sure
of; the caller then loads the file with trimesh, which also words the error for a
malformed file. The text formats are parsed by the compiled ``_creaders`` (without it,
or with SCATTER_NUMPY=1, they go to trimesh); binary STL and GLB (gltfread.py) are
read with NumPy. The rules and the measurements behind the choice are in docs/loading.md.
"""

from __future__ import annotations

import os

import numpy as np

from ..core import native
from ..core.native import worker_count
from .ply import _TYPES, _contents

_STL_RECORD = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
_MAX_HEADER = 1 << 16
_kernel = native.kernel("_creaders")  # the text parsers; None: trimesh reads those files


def read_file(path, read, smooth=False, color=False, uv=False):
    """``read`` (one of the ``read_*`` functions below, as loaders.LOADERS names them) of
    the bytes of the file at ``path``: a list of (vertices (V, 3) float64, faces (F, 3)
    int64), one per geometry in trimesh's order; for a GLB, a scene: (geometries [(name,
    vertices, faces)], instances [(name, geometry index, (4, 4) matrix or None)])
    (gltfread.py); or None (hand the file to trimesh).

    ``smooth``: smooth normals are wanted: a PLY's own normals come as a third item of its
    geometry, a dict (plyread.vertex_tables); other files with normals or UVs of their
    own are handed over (the caller computes smooth normals from the faces, as trimesh
    does for the others). ``color``: vertex colours are wanted: only PLY is read (its
    colours in that dict), every other format handed over. ``uv``: texture coordinates
    are wanted: only OBJ is read. An OBJ read for ``smooth`` or ``uv`` has the geometries
    trimesh makes of groups with ``vt`` or ``vn`` refs (its vertex split, objsplit.py)
    and their UVs and normals in that dict.
    """
    try:
        with open(path, "rb") as f:
            data = _contents(f)
    except OSError:
        return None
    try:
        return read(data, path, smooth, color, uv)
    finally:
        if hasattr(data, "close"):
            try:
                data.close()
            except BufferError:  # an array still views the mapping: it closes with it
                pass


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
    try:
        with open(path, "rb") as f:
            data = _contents(f)
    except OSError:
        return None
    try:
        name = _material_library(data)
    finally:
        if hasattr(data, "close"):
            data.close()
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
    got = c and c.read_obj(data, tables)
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
    got = c and c.read_off(data)
    return [got] if got else None


def _stl(data):
    """Binary when the size matches the count in the header (trimesh's test), else ASCII."""
    if len(data) >= 84:
        count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
        if len(data) == 84 + count * _STL_RECORD.itemsize:
            if count == 0:
                return None
            corners = np.frombuffer(data, dtype=_STL_RECORD, count=count, offset=84)["corners"]
            vertices = np.empty((3 * count, 3))
            vertices.reshape(count, 3, 3)[...] = corners  # one pass from the strided records
            return [(vertices, np.arange(3 * count, dtype=np.int64).reshape(-1, 3))]
    c = _kernel
    vertices = c and c.read_stl_ascii(data, worker_count())  # large files: parts on several threads
    if vertices is None or vertices is False:
        return None
    return [(vertices, np.arange(len(vertices), dtype=np.int64).reshape(-1, 3))]


def _ply(data, smooth=False, color=False):
    from .ply import read_triangles_from

    got = read_triangles_from(data, smooth, color)
    if got is not None:
        return [got]
    layout = _ascii_layout(bytes(data[:_MAX_HEADER]))
    c = _kernel
    if layout is None or not c:
        return None
    if smooth or color:
        return _ply_ascii_tables(c, data, *layout, smooth, color)
    got = c.read_ply_ascii(data, *layout[0])
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
    got = c.read_ply_ascii(data, *args, bytes(wanted))
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


def _ascii_layout(head):
    """((body offset, vertex count, face count, vertex properties, x, y, z columns, and
    whether each of x, y, z is float32), [(name, NumPy type) of each vertex property])
    for an ASCII PLY of ``vertex`` (scalar properties) then ``face`` (one list of int
    indices), or None."""
    end = head.find(b"end_header\n")
    if not head.startswith(b"ply\n") or end < 0 or b"\r" in head[:end]:
        return None
    try:
        lines = head[:end].decode("ascii").split("\n")
    except UnicodeDecodeError:
        return None
    elements = []
    for words in (line.split(" ") for line in lines[1:-1]):  # the last: the text before end_header
        if words[0] in ("comment", "obj_info"):
            continue
        if words == ["format", "ascii", "1.0"]:
            continue
        if words[0] == "element" and len(words) == 3 and words[2].isdigit() and len(words[2]) < 19:
            elements.append((words[1], int(words[2]), []))  # (a count past int64 cannot fit the file)
        elif words[0] == "property" and elements:
            elements[-1][2].append(words[1:])
        else:
            return None
    if lines[-1] or "format ascii 1.0" not in lines or [e[0] for e in elements] != ["vertex", "face"]:
        return None
    (_, n_vertex, vprops), (_, n_face, fprops) = elements
    names = [p[1] if len(p) == 2 else None for p in vprops]
    if None in names or len(set(names)) != len(names) or any(p[0] not in _TYPES for p in vprops):
        return None
    if {"x", "y", "z"} - set(names) or len(fprops) != 1 or len(fprops[0]) != 4:
        return None
    kind, count_type, index_type, name = fprops[0]
    if kind != "list" or name not in ("vertex_indices", "vertex_index") or count_type not in _TYPES:
        return None
    if _TYPES.get(index_type) not in ("i4", "u4"):
        return None
    columns = [names.index(a) for a in "xyz"]
    kinds = [_TYPES[vprops[k][0]] for k in columns]
    if any(t not in ("f4", "f8") for t in kinds):
        return None
    args = (end + len(b"end_header\n"), n_vertex, n_face, len(vprops), *columns, *(int(t == "f4") for t in kinds))
    return args, [(name, _TYPES[p[0]]) for name, p in zip(names, vprops)]
