"""Read a point file of any format scatter writes, whole or evenly decimated.

``read_points(path, limit)`` returns a :class:`PointSet`: at most ``limit`` points
``(m, 3) float64``, the named attribute arrays the file has (``color`` (m, 3) uint8,
``normal`` (m, 3), ``inside`` (m,), ``sdf`` (m,)), the file's total point count and its
up axis ("Z" unless the file states one: a USD stage's ``upAxis``).

A file with more points than ``limit`` is decimated without loading it whole: binary
PLY, NPY and binary PCD keep every k-th row, read a few megabytes at a time; text formats (CSV,
XYZ, ASCII PLY and PCD) and LAS/LAZ are read as ``SPANS`` runs of consecutive rows
spread evenly through the file (a run of rows is a fair sample of a ``random`` run,
whose every stretch is). USD stages are read whole (a stage cannot be streamed).

The formats are read here with NumPy (laspy for LAS/LAZ, usd-core for USD), not through
the writers' modules, so that this reader does not depend on how they are arranged.
"""

from __future__ import annotations

import dataclasses
import io
import math
import os

import numpy as np

from ..errors import ScatterError
from .formats import SUFFIXES

POINT_SUFFIXES = tuple("." + s for s in SUFFIXES)  # every suffix scatter writes
SPANS = 64  # runs of consecutive rows read from a large text or LAS/LAZ file
PLY_DTYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2", "int16": "<i2",
              "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
              "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8"}
PCD_KINDS = {"F": "f", "I": "i", "U": "u"}
# Column names of the attributes a preview colours by, as each format spells them.
NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"))
COLOR_NAMES = ("red", "green", "blue")


@dataclasses.dataclass
class PointSet:
    """``points`` (m, 3) float64, ``attributes`` name -> (m, k) or (m,) array, ``total``:
    the points in the file (m <= total when decimated), ``up_axis``: "Z" or "Y"."""

    points: np.ndarray
    attributes: dict
    total: int
    up_axis: str = "Z"


def is_point_file(path) -> bool:
    """True for a point file scatter writes; False for a mesh (a PLY with faces, a USD
    stage without points, or a mesh suffix)."""
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    if suffix == ".ply":
        return not _ply_has_faces(path)
    if suffix in (".usd", ".usda", ".usdc"):
        return _usd_has_points(path)
    return suffix in POINT_SUFFIXES


def read_points(path, limit=None) -> PointSet:
    """The points of the point file ``path``: all, or about ``limit`` spread evenly."""
    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    reader = READERS.get(suffix)
    if reader is None:
        raise ScatterError(f"{path}: not a point file scatter writes ({', '.join(POINT_SUFFIXES)})")
    try:
        return reader(path, limit)
    except ScatterError:
        raise
    except (ValueError, IndexError, KeyError, OSError) as exc:
        raise ScatterError(f"{path}: cannot read the points: {_reason(exc)}") from None


def _reason(exc):
    if isinstance(exc, OSError):
        return exc.strerror or str(exc)
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def stride(total, limit):
    """k: reading every k-th of ``total`` rows keeps at most ``limit``."""
    return 1 if limit is None or total <= limit else math.ceil(total / limit)


def from_columns(columns, total, up_axis="Z"):
    """A PointSet from ``columns``: name -> (m,) array, names as the formats write them."""
    missing = [c for c in "xyz" if c not in columns]
    if missing:
        raise ScatterError(f"no {', '.join(missing)} column")
    points = np.stack([np.asarray(columns[c], dtype=np.float64) for c in "xyz"], axis=1)
    attributes = {}
    for names in NORMAL_NAMES:
        if all(n in columns for n in names):
            attributes["normal"] = np.stack([np.asarray(columns[n], dtype=np.float64) for n in names], axis=1)
    if all(n in columns for n in COLOR_NAMES):
        attributes["color"] = np.stack([np.asarray(columns[n]) for n in COLOR_NAMES], axis=1).astype(np.uint8)
    elif "rgb" in columns:  # PCD: one 4-byte field, bytes b g r a
        packed = np.ascontiguousarray(columns["rgb"])
        word = packed.view(np.uint32) if packed.dtype.itemsize == 4 else packed.astype(np.uint32)
        attributes["color"] = np.stack([(word >> 16) & 255, (word >> 8) & 255, word & 255], axis=1).astype(np.uint8)
    for name in ("inside", "sdf"):
        if name in columns:
            attributes[name] = np.asarray(columns[name], dtype=np.float64)
    return PointSet(points, attributes, total, up_axis)


# ---- binary rows: every k-th row, read in blocks ----

BLOCK_ROWS = 8192  # rows kept per block read: a block is k * BLOCK_ROWS rows, a few MB


def _every_kth(path, dtype, offset, total, limit):
    """Every k-th of ``total`` records of ``dtype`` from byte ``offset`` (k from
    ``limit``), as a structured array, reading the file in blocks of k * BLOCK_ROWS rows
    so that memory stays at one block whatever the file's size."""
    if os.path.getsize(path) < offset + total * dtype.itemsize:
        raise ScatterError(f"{path}: the file is shorter than its header says (truncated?)")
    k = stride(total, limit)
    out = np.empty(-(-total // k), dtype=dtype)
    with _open(path) as f:
        f.seek(offset)
        done = 0
        for start in range(0, total, k * BLOCK_ROWS):
            rows = np.fromfile(f, dtype=dtype, count=min(k * BLOCK_ROWS, total - start))
            kept = rows[::k]
            out[done : done + len(kept)] = kept
            done += len(kept)
    return out


def _structured_columns(rows):
    return {name: rows[name] for name in rows.dtype.names}


# ---- PLY ----

def _ply_header(path):
    """(format, vertex count, [(type, name)] of the vertex properties, data offset, elements)."""
    with _open(path) as f:
        head = f.read(4096)
        if b"end_header" not in head:
            head += f.read((1 << 16) - len(head))
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise ScatterError(f"{path}: not a PLY file")
    offset = head.index(b"\n", end) + 1
    lines = head[:end].decode("ascii", "replace").splitlines()
    fmt, elements, props = "", [], []
    for line in lines:
        words = line.split()
        if words[:1] == ["format"] and len(words) > 1:
            fmt = words[1]
        elif words[:1] == ["element"] and len(words) > 2:
            elements.append((words[1], int(words[2])))
        elif words[:1] == ["property"] and len(elements) == 1 and elements[0][0] == "vertex":
            if words[1] == "list":
                raise ScatterError(f"{path}: vertex list properties are not point columns")
            props.append((words[1], words[2]))
    return fmt, elements, props, offset


def _ply_has_faces(path):
    try:
        _, elements, _, _ = _ply_header(path)
    except ScatterError:
        return False  # reported by the point reader
    return any(name == "face" and count > 0 for name, count in elements)


def read_ply(path, limit):
    fmt, elements, props, offset = _ply_header(path)
    if not elements or elements[0][0] != "vertex":
        raise ScatterError(f"{path}: a PLY without a vertex element first")
    total = elements[0][1]
    if len(elements) > 1 and any(count for _, count in elements[1:]):
        raise ScatterError(f"{path}: a PLY with faces is a mesh, not a point file")
    if fmt == "binary_little_endian":
        dtype = np.dtype([(name, PLY_DTYPES[kind]) for kind, name in props])
        return from_columns(_structured_columns(_every_kth(path, dtype, offset, total, limit)), total)
    if fmt == "ascii":
        names = [name for _, name in props]
        return from_columns(_text_columns(path, offset, total, limit, None, names), total)
    raise ScatterError(f"{path}: PLY format {fmt or '?'} (scatter writes ascii and binary_little_endian)")


# ---- NPY ----

def read_npy(path, limit):
    fmt = np.lib.format
    with _open(path) as f:
        try:
            version = fmt.read_magic(f)
            read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, fortran, dtype = read(f)
        except ValueError as exc:
            raise ScatterError(f"{path}: not an NPY file ({_reason(exc)})") from None
        offset = f.tell()
    if len(shape) != 1 or fortran or dtype.names is None:
        raise ScatterError(f"{path}: not an NPY array of points (one structured row a point)")
    return from_columns(_structured_columns(_every_kth(path, dtype, offset, shape[0], limit)), shape[0])


# ---- PCD ----

def _pcd_header(path):
    """({keyword: words}, data offset) of a PCD file."""
    keys, offset = {}, 0
    with _open(path) as f:
        for raw in iter(lambda: f.readline(4096), b""):
            offset += len(raw)
            words = raw.decode("ascii", "replace").split()
            if words and not words[0].startswith("#"):
                keys[words[0].upper()] = words[1:]
            if words[:1] == ["DATA"]:
                break
    if "DATA" not in keys or "FIELDS" not in keys or "POINTS" not in keys:
        raise ScatterError(f"{path}: not a PCD file")
    return keys, offset


def read_pcd(path, limit):
    keys, offset = _pcd_header(path)
    total = int(keys["POINTS"][0])
    names = keys["FIELDS"]
    if any(c != "1" for c in keys.get("COUNT", ["1"] * len(names))):
        raise ScatterError(f"{path}: PCD fields of more than one value are not point columns")
    data = keys["DATA"][0].lower()
    if data == "binary":
        dtype = np.dtype([(n, f"<{PCD_KINDS[t]}{s}") for n, s, t in zip(names, keys["SIZE"], keys["TYPE"])])
        return from_columns(_structured_columns(_every_kth(path, dtype, offset, total, limit)), total)
    if data == "ascii":
        columns = _text_columns(path, offset, total, limit, None, names)
        if "rgb" in columns:  # scatter writes the packed colour as an integer in ASCII files
            columns["rgb"] = columns["rgb"].astype(np.uint32)
        return from_columns(columns, total)
    raise ScatterError(f"{path}: PCD DATA {data} (scatter writes ascii and binary)")


# ---- CSV and XYZ ----

def read_csv(path, limit):
    with _open(path) as f:
        first = f.readline()
    names = [n.strip() for n in first.decode("ascii", "replace").strip().split(",")]
    total = _count_rows(path, len(first))
    return from_columns(_text_columns(path, len(first), total, limit, ",", names), total)


def read_xyz(path, limit):
    """XYZ has no header: x y z, then nx ny nz when the next three columns are unit vectors
    (the columns scatter writes come in the order normal, orient, face, ...)."""
    total = _count_rows(path, 0)
    table = _text_table(path, 0, total, limit, None)
    if table.shape[1] < 3:
        raise ScatterError(f"{path}: fewer than three columns")
    columns = dict(zip("xyz", table[:, :3].T))
    if table.shape[1] >= 6:
        lengths = np.linalg.norm(table[:, 3:6], axis=1)
        if len(lengths) and np.all(np.abs(lengths - 1.0) < 1e-3):
            columns.update(zip(("nx", "ny", "nz"), table[:, 3:6].T))
    return from_columns(columns, total)


def _count_rows(path, start, block=1 << 22):
    rows, last = 0, b"\n"
    with _open(path) as f:
        f.seek(start)
        while data := f.read(block):
            rows += data.count(b"\n")
            last = data[-1:]
    return rows + (last != b"\n")


def _text_columns(path, offset, total, limit, sep, names):
    table = _text_table(path, offset, total, limit, sep)
    if table.shape[1] != len(names):
        raise ScatterError(f"{path}: {table.shape[1]} columns, the header names {len(names)}")
    return dict(zip(names, table.T))


def _text_table(path, offset, total, limit, sep):
    """(m, k) float64 of the rows of a text file from byte ``offset``: all of them, or
    SPANS runs of consecutive rows spread evenly through the file when over ``limit``."""
    with _open(path) as f:
        if limit is None or total <= limit:
            f.seek(offset)
            text = f.read()
        else:
            text = b"".join(_spans(f, offset, os.path.getsize(path), math.ceil(limit / SPANS)))
    if not text.strip():
        return np.empty((0, 3))
    return np.loadtxt(io.BytesIO(text), delimiter=sep, ndmin=2, dtype=np.float64)


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


# ---- LAS / LAZ ----

def read_las(path, limit):
    try:
        import laspy
    except ImportError:
        raise ScatterError(f"{path}: reading LAS/LAZ needs laspy and lazrs: pip install laspy lazrs") from None
    try:
        with laspy.open(path) as reader:
            total = reader.header.point_count
            if limit is None or total <= limit:
                parts = [reader.read_points(total)] if total else []
            else:
                parts = list(_las_spans(reader, total, math.ceil(limit / SPANS)))
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        raise ScatterError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except Exception as exc:  # laspy raises its own error types for bad files
        raise ScatterError(f"{path}: not a LAS/LAZ file ({_reason(exc)})") from None
    columns = {}
    if parts:
        names = list(parts[0].point_format.dimension_names)
        for name in ("x", "y", "z"):
            columns[name] = np.concatenate([np.asarray(p[name], dtype=np.float64) for p in parts])
        for name in names:
            if name in COLOR_NAMES:  # 16-bit channels; scatter writes 8-bit colour times 257
                columns[name] = np.concatenate([np.asarray(p[name]) >> 8 for p in parts])
            elif name in ("nx", "ny", "nz", "inside", "sdf"):
                columns[name] = np.concatenate([np.asarray(p[name]) for p in parts])
    else:
        columns = {c: np.empty(0) for c in "xyz"}
    return from_columns(columns, total)


def _las_spans(reader, total, rows):
    for j in range(SPANS):
        start = total * j // SPANS
        reader.seek(start)
        yield reader.read_points(min(rows, total - start))


# ---- USD ----

def _pxr():
    try:
        from pxr import Usd, UsdGeom
    except ImportError:
        raise ScatterError("reading USD needs usd-core: pip install usd-core") from None
    return Usd, UsdGeom


def _open_stage(path):
    Usd, _ = _pxr()
    if not os.path.isfile(path):
        raise ScatterError(f"{path}: no such file")
    try:
        stage = Usd.Stage.Open(path)
    except Exception as exc:  # pxr raises Tf errors
        raise ScatterError(f"{path}: not a USD stage ({_reason(exc)})") from None
    if stage is None:
        raise ScatterError(f"{path}: not a USD stage")
    return stage


def _point_prims(stage):
    _, UsdGeom = _pxr()
    return [p for p in stage.Traverse() if p.IsA(UsdGeom.Points) or p.IsA(UsdGeom.PointInstancer)]


def _usd_has_points(path):
    try:
        return bool(_point_prims(_open_stage(os.fspath(path))))
    except ScatterError:
        return True  # reported by the point reader


def read_usd(path, limit):
    """The points of every UsdGeom.Points (``points``) and PointInstancer (``positions``)
    prim, in world space, with their ``normals`` and ``displayColor`` primvars."""
    Usd, UsdGeom = _pxr()
    stage = _open_stage(path)
    up = "Y" if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y else "Z"
    points, normals, colours = [], [], []
    for prim in _point_prims(stage):
        if prim.IsA(UsdGeom.Points):
            value = UsdGeom.Points(prim).GetPointsAttr().Get()
        else:
            value = UsdGeom.PointInstancer(prim).GetPositionsAttr().Get()
        local = np.array(value if value is not None else [], dtype=np.float64).reshape(-1, 3)
        matrix = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))
        points.append(local @ matrix[:3, :3] + matrix[3, :3])  # USD: row vectors
        api = UsdGeom.PrimvarsAPI(prim)
        normals.append(_primvar(api, "normals", len(local)))
        colours.append(_primvar(api, "displayColor", len(local)))
    total = sum(len(p) for p in points)
    every = stride(total, limit)
    columns = dict(zip("xyz", np.concatenate(points or [np.empty((0, 3))])[::every].T))
    if normals and all(n is not None for n in normals):
        columns.update(zip(("nx", "ny", "nz"), np.concatenate(normals)[::every].T))
    if colours and all(c is not None for c in colours):
        rgb = np.clip(np.rint(np.concatenate(colours)[::every] * 255), 0, 255)
        columns.update(zip(COLOR_NAMES, rgb.T))
    return from_columns(columns, total, up)


def _primvar(api, name, n):
    primvar = api.GetPrimvar(name)
    value = primvar.Get() if primvar and primvar.HasValue() else None
    if value is None:
        return None
    values = np.array(value, dtype=np.float64).reshape(-1, 3)
    return values if len(values) == n else None


def _open(path):
    try:
        return open(path, "rb")
    except FileNotFoundError:
        raise ScatterError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise ScatterError(f"{path}: is a directory") from None
    except OSError as exc:
        raise ScatterError(f"{path}: cannot read: {exc.strerror or exc}") from None


READERS = {".ply": read_ply, ".csv": read_csv, ".xyz": read_xyz, ".txt": read_xyz, ".npy": read_npy,
           ".pcd": read_pcd, ".las": read_las, ".laz": read_las, ".usd": read_usd, ".usda": read_usd,
           ".usdc": read_usd}
