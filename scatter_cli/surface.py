"""Loading a surface: a mesh file, a trimesh object or a scene -> float64 arrays.

A :class:`Surface` is a list of geometries (local vertices and triangles) and a list
of instances, each placing one geometry in world space with a 4x4 matrix. An
instanced geometry is stored once, whatever the number of nodes that place it.
"""

from __future__ import annotations

import io
import logging
import os
import stat
import sys
from dataclasses import dataclass, field

import numpy as np

from .errors import ScatterError, ScatterUsageError
from .inputs import INPUT_FORMATS, USD_FORMATS

# Called before trimesh is first imported, when set: the command line imports it with
# SciPy hidden (see cli.py). Nothing imports trimesh before a mesh needs it.
import_trimesh = None


@dataclass
class Geometry:
    """One triangle list in its own frame.

    vertices: (V, 3) float64; faces: (F, 3) int64, in the order trimesh loads them.
    ``mesh`` is the trimesh object it came from, kept for attributes (UVs, colours).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    mesh: object = None

    def __post_init__(self):
        # C order and these types, as the compiled kernels read them (no copy if already so)
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int64)


@dataclass
class Instance:
    """A geometry placed in world space; ``matrix`` is (4, 4) float64, None for identity."""

    name: str
    geometry: int
    matrix: np.ndarray | None = None


@dataclass
class Surface:
    geometries: list[Geometry]
    instances: list[Instance]
    source: str = "<mesh>"
    is_scene: bool = False
    _cache: dict = field(default_factory=dict, repr=False)
    # The scene's up axis ("Y" or "Z") and metres per unit, where the format says them
    # (USD stages; glTF by its specification); None where it does not.
    up_axis: str | None = None
    meters_per_unit: float | None = None
    # (n_instances,) int64: the index `scatter info` lists each instance under in the
    # whole file (what `-a object` writes); None: its position in ``instances``.
    object_index: np.ndarray | None = None

    def keeping(self, instances) -> "Surface":
        """The same scene with only ``instances`` (a list of this surface's instances),
        each keeping its object index."""
        position = {id(inst): k for k, inst in enumerate(self.instances)}
        index = np.array([position[id(inst)] for inst in instances], dtype=np.int64)
        if self.object_index is not None:
            index = self.object_index[index]
        return Surface(self.geometries, instances, self.source, self.is_scene, up_axis=self.up_axis,
                       meters_per_unit=self.meters_per_unit, object_index=index)

    @property
    def face_count(self) -> int:
        """Faces in world space, every instance counted."""
        return sum(len(self.geometries[i.geometry].faces) for i in self.instances)

    def world_vertices(self, instance: Instance) -> np.ndarray:
        """(V, 3) float64 vertices of one instance's geometry in world space."""
        v = self.geometries[instance.geometry].vertices
        if instance.matrix is None:
            return v
        m = instance.matrix
        return v @ m[:3, :3].T + m[:3, 3]


def load_surface(source, *, input_format: str | None = None, objects=None, plain=False, smooth=False,
                 color=False, uv=False) -> Surface:
    """Load ``source`` (path, ``'-'`` for standard input, trimesh.Trimesh or trimesh.Scene).

    ``plain``: only vertices and faces are wanted (no colours, UVs or normals from the
    file), so the fast readers (readers.py) may read it without importing trimesh.
    ``smooth``: smooth vertex normals are wanted too; the fast readers then read a
    PLY's own normals and otherwise only files without normals or UVs of their own (the
    normals are computed from the faces, as for trimesh's mesh of such a file).
    ``color``: vertex colours are wanted too; the fast readers then read only PLY.
    ``uv``: texture coordinates are wanted too; the fast readers then read only OBJ.
    """
    if isinstance(source, (str, os.PathLike)) and _suffix(source, input_format) in USD_FORMATS:
        from .usdread import load_usd

        # smooth normals: a stage's own (primvars:normals, normals) when it has them
        return load_usd(os.fspath(source), input_format, objects=objects, plain=plain and not (smooth or color or uv))
    if plain and not objects and isinstance(source, (str, os.PathLike)) and not _is_stream(os.fspath(source)):
        fast = _read_plain(os.fspath(source), input_format, smooth, color, uv)
        if fast is not None:
            return _with_units(fast, source, input_format)
    if import_trimesh is not None and "trimesh" not in sys.modules:
        import_trimesh()
    import trimesh

    logging.getLogger("trimesh").setLevel(logging.ERROR)
    name = "<mesh>"
    if isinstance(source, (str, os.PathLike)):
        name = "<stdin>" if str(source) == "-" else os.fspath(source)
        loaded = _read_file(source, input_format)
    else:
        loaded = source
    if isinstance(loaded, trimesh.Trimesh):
        surface = Surface([_geometry(name, loaded, name)], [Instance(os.path.basename(name), 0)], name)
    elif isinstance(loaded, trimesh.Scene):
        surface = _from_scene(loaded, name)
    else:
        raise ScatterError(f"{name}: not a surface mesh (trimesh loaded a {type(loaded).__name__})")
    if objects:
        surface = select_objects(surface, objects)
    if surface.face_count == 0:
        raise ScatterError(f"{name}: the mesh has no faces")
    return _with_units(surface, source, input_format)


def _with_units(surface, source, input_format):
    """glTF is Y up in metres by its specification: the surface says so (other formats
    this module reads carry no such metadata)."""
    if isinstance(source, (str, os.PathLike)) and _suffix(source, input_format) in ("glb", "gltf"):
        surface.up_axis, surface.meters_per_unit = "Y", 1.0
    return surface


def _suffix(source, input_format):
    return (input_format or os.path.splitext(os.fspath(source))[1].lstrip(".")).lower()


def _read_plain(path, input_format, smooth=False, color=False, uv=False):
    """The Surface of a mesh file read by the fast readers, or None (use trimesh).

    One geometry makes a mesh, several a scene, as trimesh.load makes them; the names
    follow trimesh's for an OBJ split by material (file name, then name_1, name_2...).
    """
    from .readers import read_mesh

    _check_readable(path)
    parts = read_mesh(path, (input_format or os.path.splitext(path)[1].lstrip(".")).lower(), smooth, color, uv)
    if parts is None:
        return None
    tables = [p[2] if len(p) > 2 else {} for p in parts] if isinstance(parts, list) else None
    surface = _plain_surface(path, parts if tables is None else [p[:2] for p in parts])
    if smooth or color or uv:
        from .visuals import VertexTables

        for g, t in zip(surface.geometries, tables or [{}] * len(surface.geometries)):
            g.mesh = VertexTables(g.vertices, g.faces, **t)  # normals computed from the faces unless given
    return surface


def _plain_surface(path, parts):
    if isinstance(parts, tuple):  # a GLB scene
        geometries = [_checked_geometry(n, v, f, path) for n, v, f in parts[0]]
        surface = Surface(geometries, [Instance(*i) for i in parts[1]], path, is_scene=True)
    elif len(parts) == 1:
        surface = Surface([_checked_geometry(path, *parts[0], path)], [Instance(os.path.basename(path), 0)], path)
    else:
        base = os.path.basename(path)
        names = [base] + [f"{base}_{k}" for k in range(1, len(parts))]
        geometries = [_checked_geometry(n, *arrays, path) for n, arrays in zip(names, parts)]
        surface = Surface(geometries, [Instance(n, k) for k, n in enumerate(names)], path, is_scene=True)
    if surface.face_count == 0:
        raise ScatterError(f"{path}: the mesh has no faces")
    return surface


def _read_file(source, input_format):
    import trimesh

    path = os.fspath(source)
    if path == "-":
        if not input_format:
            raise ScatterUsageError("reading a mesh from standard input needs --input-format (ply, obj, stl, off, glb)")
        data = sys.stdin.buffer.read()
        if not data:
            raise ScatterError("<stdin>: no data on standard input")
        file_obj, file_type = io.BytesIO(data), input_format.lower()
    else:
        _check_readable(path)
        stream = _is_stream(path)
        file_type = (input_format or os.path.splitext(path)[1].lstrip(".")).lower()
        if not file_type:
            pipe = "a pipe has " if stream else ""
            raise ScatterUsageError(f"{path}: {pipe}no file suffix to tell the format; pass --input-format")
        file_obj = path
        if stream:  # a pipe, e.g. `scatter sample <(gunzip -c mesh.ply.gz)`: read it once
            with open(path, "rb") as f:
                data = f.read()
            if not data:
                raise ScatterError(f"{path}: no data in the pipe")
            file_obj = io.BytesIO(data)
    if file_type not in trimesh.available_formats():
        raise ScatterUsageError(f"{path}: unknown mesh format '{file_type}' (try one of: {', '.join(INPUT_FORMATS)})")
    if file_type in ("glb", "gltf"):
        from .draco import check_decoder

        check_decoder(path, file_type, file_obj)
    try:
        with np.errstate(all="ignore"):
            return trimesh.load(file_obj, file_type=file_type, process=False)
    except MemoryError:
        raise ScatterError(f"{path}: out of memory while reading the mesh") from None
    except Exception as exc:  # trimesh raises many kinds on malformed input
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ScatterError(f"{path}: not a readable {file_type.upper()} mesh ({reason[:200]})") from None


def _check_readable(path):
    if not os.path.exists(path):
        raise ScatterError(f"{path}: no such file")
    if os.path.isdir(path):
        raise ScatterError(f"{path}: is a directory, not a mesh file")
    if not os.access(path, os.R_OK):
        raise ScatterError(f"{path}: permission denied")
    if not _is_stream(path) and os.path.getsize(path) == 0:
        raise ScatterError(f"{path}: the file is empty")


def _is_stream(path):
    """Whether ``path`` is standard input or a pipe, socket or device: read once, no size."""
    if path == "-":
        return True
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _geometry(name, mesh, source) -> Geometry:
    try:  # trimesh builds some arrays lazily: a malformed file can fail only here
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
    except (ValueError, TypeError, IndexError, OverflowError) as exc:
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ScatterError(f"{source}: malformed geometry '{name}' ({reason[:200]})") from None
    return _checked_geometry(name, vertices, faces, source, mesh)


def _checked_geometry(name, vertices, faces, source, mesh=None) -> Geometry:
    if vertices.size == 0:
        vertices = vertices.reshape(0, 3)
    if faces.size == 0:
        faces = faces.reshape(0, 3)
    # Never reshape blindly: (V, 2) vertices read as (V * 2 / 3, 3) would be wrong points.
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise ScatterError(f"{source}: malformed geometry '{name}' (vertices {vertices.shape}, faces {faces.shape})")
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ScatterError(f"{source}: face indices out of range in geometry '{name}'")
    return Geometry(name, vertices, faces, mesh)


def _from_scene(scene, source) -> Surface:
    import trimesh

    geometries, index, instances = [], {}, []
    for node in scene.graph.nodes_geometry:
        try:
            matrix, geom_name = scene.graph[node]
        except (ValueError, KeyError, AssertionError) as exc:  # a graph trimesh cannot walk, e.g. a cycle
            raise ScatterError(f"{source}: malformed scene graph at node '{node}' ({str(exc).strip()[:200]})") from None
        mesh = scene.geometry.get(geom_name)
        if not isinstance(mesh, trimesh.Trimesh):
            continue
        if geom_name not in index:
            index[geom_name] = len(geometries)
            geometries.append(_geometry(geom_name, mesh, source))
        matrix = np.asarray(matrix, dtype=np.float64)
        instances.append(Instance(str(node), index[geom_name], None if np.array_equal(matrix, np.eye(4)) else matrix))
    return Surface(geometries, instances, source, is_scene=True)


def select_objects(surface: Surface, names) -> Surface:
    """Keep the instances whose node or geometry name is in ``names`` (instance order kept)."""
    wanted = set(names)
    known = {i.name for i in surface.instances} | {g.name for g in surface.geometries}
    missing = sorted(wanted - known)
    if missing:  # a failure of this mesh (another may have them), not a usage error
        raise ScatterError(
            f"{surface.source}: no object named {', '.join(map(repr, missing))} "
            f"(objects: {', '.join(sorted(known)) or 'none'})"
        )
    kept = [i for i in surface.instances if i.name in wanted or surface.geometries[i.geometry].name in wanted]
    return surface.keeping(kept)


def corners(vertices, faces):
    """The three corners of each face: (F, 9) float64 rows ``[v0, v1, v2]``."""
    return np.take(vertices, faces, axis=0).reshape(len(faces), 9)


def doubled_areas(tri, matrix=None):
    """Twice the area of each face, in world space under ``matrix`` (4, 4).

    tri: (F, 9) float64 corners -> (F,) float64; non-finite faces give NaN.
    Under a linear map A, (A e1) x (A e2) = cof(A) (e1 x e2), so one 3x3 product per face
    gives world areas, for non-uniform scales too, without moving the vertices.
    """
    n = face_cross(tri)
    if matrix is not None:
        n = apply_matrix(cofactor(matrix[:3, :3]), n, out=n)
    s = n[:, 0] * n[:, 0]  # in this order, as the compiled kernel sums it
    s += n[:, 1] * n[:, 1]
    s += n[:, 2] * n[:, 2]
    return np.sqrt(s, out=s)


def column_bounds(v, rows=1 << 16):
    """(lo, hi): the (3,) minimum and maximum of each column of ``v`` (n, 3), n > 0.

    Column by column over blocks of ``rows`` that stay in cache: ``v.min(axis=0)`` runs
    its inner loop over the 3 columns, 10 times slower on a large (n, 3) array
    (docs/loading.md: binary STL)."""
    blocks = np.empty((2, -(-len(v) // rows), 3))
    for k, s in enumerate(range(0, len(v), rows)):
        b = v[s : s + rows]
        for c in range(3):
            blocks[0, k, c], blocks[1, k, c] = b[:, c].min(), b[:, c].max()
    return blocks[0].min(axis=0), blocks[1].max(axis=0)


def face_cross(tri):
    """(v1 - v0) x (v2 - v0) for each face: (F, 9) corners -> (F, 3) float64."""
    t = tri.T
    e1 = [t[3 + c] - t[c] for c in range(3)]
    e2 = [t[6 + c] - t[c] for c in range(3)]
    n = np.empty((tri.shape[0], 3))
    for c in range(3):
        a, b = (c + 1) % 3, (c + 2) % 3
        np.subtract(e1[a] * e2[b], e1[b] * e2[a], out=n[:, c])
    return n


def apply_matrix(m, v, out=None):
    """``v @ m[:3, :3].T (+ m[:3, 3])`` for rows v (n, 3), one element-wise column at a time.

    m: (3, 3) or (3, 4) float64. Unlike a BLAS product, the rounding of a row does not
    depend on how many rows come with it, so chunked output stays byte-identical.
    """
    out = np.empty(v.shape) if out is None else out
    x, y, z = (v[:, c].copy() for c in range(3))
    for c in range(3):
        col = m[c, 0] * x
        col += m[c, 1] * y
        col += m[c, 2] * z
        if m.shape[1] > 3:
            col += m[c, 3]
        out[:, c] = col
    return out


def cofactor(a):
    """Cofactor matrix of a (3, 3) matrix, defined for singular ones too.

    Row i is ``cross(a[i+1], a[i+2])``, worked out on Python floats: the same products
    and differences as np.cross (so the same bits) without its per-call cost, which a
    scene of many instances pays once per instance.
    """
    r0, r1, r2 = np.asarray(a, dtype=np.float64)[:3, :3].tolist()
    return np.array([_cross(r1, r2), _cross(r2, r0), _cross(r0, r1)])


def cofactors(a):
    """Cofactor matrices of a stack (k, 3, 3) (or (k, 4, 4), its upper-left blocks) ->
    (k, 3, 3) float64: :func:`cofactor` of each, the same products in the same order,
    so the same bits."""
    a = np.asarray(a, dtype=np.float64)
    r = [[a[:, i, j] for j in range(3)] for i in range(3)]
    out = np.empty((len(a), 3, 3))
    for i in range(3):
        x, y = r[(i + 1) % 3], r[(i + 2) % 3]
        out[:, i, 0] = x[1] * y[2] - x[2] * y[1]
        out[:, i, 1] = x[2] * y[0] - x[0] * y[2]
        out[:, i, 2] = x[0] * y[1] - x[1] * y[0]
    return out


def transformed_columns(m, v):
    """The columns of ``v @ m[k, :3, :3].T (+ m[k, :3, 3])`` for every matrix of a stack:
    m (k, 3, 3) or (k, 3|4, 4), v (n, 3) -> [x, y, z], each (k, n) float64, with the
    element-wise operations of :func:`apply_matrix` in its order (the same bits)."""
    cols = [np.ascontiguousarray(v[:, c]) for c in range(3)]
    out = []
    for c in range(3):
        col = m[:, c, 0, None] * cols[0]
        col += m[:, c, 1, None] * cols[1]
        col += m[:, c, 2, None] * cols[2]
        if m.shape[2] > 3:
            col += m[:, c, 3, None]
        out.append(col)
    return out


def _cross(x, y):
    return [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]
