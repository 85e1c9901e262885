"""USD stages (``.usd .usda .usdc .usdz``, with usd-core) -> a :class:`Surface`.

Every ``UsdGeomMesh`` of the stage, placed by its world transform at the stage's earliest
time code (the default value for a static stage). A mesh inside a scene-graph prototype
(instanceable prims) or a point instancer's prototype is one :class:`Geometry`, placed
once per instance by an :class:`Instance` matrix: the vertices are never copied.

Traversal: active, defined, non-abstract prims (classes and ``over`` prims are not
drawn); an ``invisible`` prim or one whose purpose is ``guide`` or ``proxy`` is skipped
with its subtree; the children of a point instancer are drawn only as its prototypes.
Only ``Mesh`` prims are sampled (implicit shapes such as ``Cube`` are not). Subdivision
schemes are ignored: the control mesh is sampled as authored.

Triangulation: polygon k, with corners s .. s+c-1 in ``faceVertexIndices``, becomes the
fan (s, s+j+1, s+j+2) for j = 0 .. c-3, polygons in file order, each polygon's
triangles together; polygons of fewer than three corners and the faces listed in
``holeIndices`` give none; ``leftHanded`` meshes have the last two corners of each
triangle swapped so that face normals follow the right-hand rule.

Instance names (``--object``, ``scatter info``): a mesh's prim path; inside an
instanceable prim, the instance proxy path (``/World/house_2/roof``); inside a point
instancer's prototype, the instancer's path with the instance index, then the mesh's path
below the prototype's parent (``/World/trees[17]/oak/trunk``).
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
import tempfile

import numpy as np

from .errors import ScatterError, ScatterUsageError
from .sourcefile import check_readable, is_stream, stream_bytes
from .surface import Geometry, Instance, Surface
from .visuals import VertexTables

INSTALL_HINT = "pip install 'scatter-cli[usd]'"
# How far an interpolation is from constant: a colour stored at the finest of its parts.
_RANK = {"constant": 0, "uniform": 1, "vertex": 2, "varying": 2, "faceVarying": 3}


def load_usd(path: str, input_format=None, *, objects=None, plain=False) -> Surface:
    """The surface of the USD stage at ``path`` (``-``: standard input, then
    ``input_format`` names the format); ``objects``: prim paths to keep.

    ``plain``: positions and faces only (no primvars are read).
    """
    name = "<stdin>" if path == "-" else path
    _import_pxr(name)
    with _diagnostics() as printed:
        if is_stream(path):  # USD reads files by name: a pipe's bytes go to a file first
            data = stream_bytes(path, f"{name}: no data to read")
            suffix = (input_format or os.path.splitext(path)[1].lstrip(".") or "usd").lower()
            with tempfile.TemporaryDirectory() as tmp:
                copy = os.path.join(tmp, "stage." + suffix)
                with open(copy, "wb") as f:
                    f.write(data)
                surface, aliases = _StageReader(_open(copy, name), name, plain).surface()
        else:
            check_readable(path)
            surface, aliases = _StageReader(_open(path, name), name, plain).surface()
    # USD's own warnings (a reference that does not resolve, ...) as the run's warnings
    surface.warnings += [f"{name}: {m}" for m in map(_diagnostic, printed) if m]
    if objects:
        surface = select_paths(surface, objects, aliases)
    if surface.face_count == 0:
        raise ScatterError(f"{path}: the stage has no mesh faces")
    return surface


@contextlib.contextmanager
def _diagnostics():
    """Collect what USD's C++ code prints on file descriptor 2 while the stage is read
    (its warnings have no Python hook): yields a list, filled with the lines on exit."""
    lines = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            lines += tmp.read().decode("utf-8", "replace").splitlines()


def _diagnostic(line):
    """``Warning: in F at line N of FILE -- MESSAGE (context)`` -> MESSAGE, at most 200
    characters; other lines as they are."""
    text = line.strip()
    if " -- " in text:
        text = text.split(" -- ", 1)[1]
    if text.endswith(")") and " (" in text:
        text = text[: text.rindex(" (")]
    return text[:200]


def _import_pxr(path):
    try:
        from pxr import Usd, UsdGeom  # noqa: F401
    except ImportError:
        raise ScatterError(f"{path}: reading USD stages needs usd-core: {INSTALL_HINT}") from None


def _open(path, name):
    from pxr import Tf, Usd

    try:
        stage = Usd.Stage.Open(path)
    except Tf.ErrorException as exc:
        raise ScatterError(f"{name}: not a readable USD stage ({_reason(exc)})") from None
    if stage is None:
        raise ScatterError(f"{name}: not a readable USD stage")
    return stage


def _reason(exc):
    """The message of a Tf error, without the C++ function and source location."""
    text = " ".join(str(exc).split())
    if " : '" in text:
        text = text.split(" : '", 1)[1].split("'", 1)[0]
    return text[:200] or type(exc).__name__


class _Placed:
    """Meshes placed in a frame: ``geometry`` (r,) int64, ``matrix`` (r, 4, 4) float64
    row-vector matrices into the frame, ``names`` and ``aliases`` (r strings each)."""

    def __init__(self, geometry, matrix, names, aliases):
        self.geometry = np.asarray(geometry, dtype=np.int64).reshape(-1)
        self.matrix = np.asarray(matrix, dtype=np.float64).reshape(-1, 4, 4)
        self.names, self.aliases = list(names), list(aliases)

    @staticmethod
    def join(parts):
        if len(parts) == 1:
            return parts[0]
        return _Placed(np.concatenate([p.geometry for p in parts] + [np.empty(0, np.int64)]),
                       np.concatenate([p.matrix for p in parts] + [np.empty((0, 4, 4))]),
                       [n for p in parts for n in p.names], [a for p in parts for a in p.aliases])


def compose(a, b):
    """``a @ b`` for stacks of 4x4 matrices (broadcast), as a fixed sequence of element-wise
    products and sums: the same bits whatever the stack's size or the BLAS installed."""
    out = a[..., :, 0, None] * b[..., None, 0, :]
    for k in range(1, 4):
        out += a[..., :, k, None] * b[..., None, k, :]
    return out


class _StageReader:
    def __init__(self, stage, source, plain):
        from pxr import Usd, UsdGeom

        self.Usd, self.UsdGeom = Usd, UsdGeom
        self.stage, self.source, self.plain = stage, source, plain
        self.time = Usd.TimeCode.EarliestTime()
        self.xforms = UsdGeom.XformCache(self.time)
        self.geometries: list[Geometry] = []
        self.index: dict[str, int] = {}
        self.in_prototype: set[int] = set()
        self.subtrees: dict[tuple, _Placed] = {}
        self.skip_purposes = {UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy}

    def surface(self):
        """(Surface, aliases): aliases[k] is the prim path of instance k's mesh as authored."""
        placed = self._walk(self.stage.GetPseudoRoot(), None)
        for g, name in zip(placed.geometry.tolist(), placed.names):
            if g in self.in_prototype:  # /__Prototype_1/... is no name a user knows
                self.geometries[g].name = name
                self.in_prototype.discard(g)
        identity = (placed.matrix == np.eye(4)).all(axis=(1, 2)).tolist()
        columns = np.ascontiguousarray(placed.matrix.transpose(0, 2, 1))  # column-vector matrices
        instances = [Instance(name, g, None if same else columns[k])
                     for k, (name, g, same) in enumerate(zip(placed.names, placed.geometry.tolist(), identity))]
        surface = Surface(self.geometries, instances, self.source, is_scene=True)
        surface.up_axis, surface.meters_per_unit = stage_units(self.stage)
        return surface, placed.aliases

    # -- placements -----------------------------------------------------------------------

    def _walk(self, root, base) -> _Placed:
        """Meshes under ``root`` (itself included), each with the matrix that maps its points
        into the frame of ``base`` (an ancestor prim; None: world space)."""
        out = []
        it = iter(self.Usd.PrimRange(root))
        for prim in it:
            if self._skipped(prim):
                it.PruneChildren()
            elif prim.IsInstance():
                it.PruneChildren()
                out.append(self._instance(prim, base))
            elif prim.IsA(self.UsdGeom.PointInstancer):
                it.PruneChildren()
                out.append(self._point_instances(prim, base))
            elif prim.IsA(self.UsdGeom.Mesh):
                path = str(prim.GetPath())
                out.append(_Placed([self._geometry(prim)], self._matrix(prim, base), [path], [path]))
        return _Placed.join(out) if out else _Placed([], [], [], [])

    def _matrix(self, prim, base):
        if base is None:
            m = self.xforms.GetLocalToWorldTransform(prim)
        else:
            m = self.xforms.ComputeRelativeTransform(prim, base)[0]
        return np.array(m, dtype=np.float64)

    def _skipped(self, prim):
        if not prim.IsA(self.UsdGeom.Imageable):
            return False
        image = self.UsdGeom.Imageable(prim)
        if image.GetVisibilityAttr().Get(self.time) == self.UsdGeom.Tokens.invisible:
            return True
        return image.GetPurposeAttr().Get(self.time) in self.skip_purposes

    def _subtree(self, root, base):
        """``_walk(root, base)``, once per prototype whatever its number of instances."""
        key = (str(root.GetPath()), None if base is None else str(base.GetPath()))
        if key not in self.subtrees:
            self.subtrees[key] = self._walk(root, base)
        return self.subtrees[key]

    def _instance(self, prim, base):
        """An instanceable prim: its prototype's meshes under the prim's matrix."""
        proto = prim.GetPrototype()
        if not proto:
            return _Placed([], [], [], [])
        at = self._matrix(prim, base)
        old, new = str(proto.GetPath()), str(prim.GetPath())
        inner = self._subtree(proto, None)  # a prototype is a root prim: its own frame
        self.in_prototype.update(inner.geometry.tolist())
        return _Placed(inner.geometry, compose(inner.matrix, at), [new + n[len(old):] for n in inner.names],
                       inner.aliases)

    def _point_instances(self, prim, base):
        """A point instancer: in instance order, each instance's prototype meshes under the
        instance matrix (arrays over all instances at once)."""
        where = str(prim.GetPath())
        xf, index, shown, targets = self._instancer_arrays(prim, where)
        protos = [self._prototype(self.stage.GetPrimAtPath(t)) for t in targets]
        sizes = np.array([len(p.geometry) for p in protos] + [0], dtype=np.int64)
        table = _Placed.join(protos + [_Placed([], [], [], [])])  # every prototype's meshes, end to end
        suffixes = [s for p in protos for s in p.names]
        first = np.cumsum(sizes) - sizes
        rows = np.flatnonzero(shown & (sizes[index] > 0))
        counts = sizes[index[rows]]
        instance = np.repeat(rows, counts)  # (r,) the instance of each placement
        start = np.cumsum(counts) - counts
        entry = first[index[instance]] + np.arange(len(instance)) - np.repeat(start, counts)
        # the prototype's own transform is in its entries' matrices (ExcludeProtoXform)
        matrix = compose(compose(table.matrix[entry], xf[instance]), self._matrix(prim, base))
        entries = entry.tolist()
        names = [f"{where}[{i}]{suffixes[e]}" for i, e in zip(instance.tolist(), entries)]
        return _Placed(table.geometry[entry], matrix, names, [table.aliases[e] for e in entries])

    def _prototype(self, proto):
        """A point instancer's prototype: its meshes in the frame of its parent, named by
        their path below that parent."""
        if not proto:
            return _Placed([], [], [], [])
        parent = proto.GetParent()
        cut = 0 if parent.IsPseudoRoot() else len(str(parent.GetPath()))
        inner = self._subtree(proto, parent)
        return _Placed(inner.geometry, inner.matrix, [n[cut:] for n in inner.names], inner.aliases)

    def _instancer_arrays(self, prim, where):
        """(transforms (n, 4, 4), prototype index (n,), shown (n,) bool, prototype paths)."""
        UsdGeom = self.UsdGeom
        pi = UsdGeom.PointInstancer(prim)
        targets = pi.GetPrototypesRel().GetTargets()
        try:
            xf = pi.ComputeInstanceTransformsAtTime(
                self.time, self.time, UsdGeom.PointInstancer.ExcludeProtoXform, UsdGeom.PointInstancer.IgnoreMask
            )
            index = np.asarray(pi.GetProtoIndicesAttr().Get(self.time) or [], dtype=np.int64)
        except Exception as exc:
            raise ScatterError(f"{self.source}: point instancer {where}: {_reason(exc)}") from None
        xf = np.array(xf, dtype=np.float64).reshape(-1, 4, 4)
        if len(xf) != len(index):
            raise ScatterError(f"{self.source}: point instancer {where}: bad instance arrays "
                               f"({len(index)} prototype indices, {len(xf)} transforms)")
        if len(index) and (index.min() < 0 or index.max() >= len(targets)):
            raise ScatterError(f"{self.source}: point instancer {where}: prototype index out of range")
        mask = pi.ComputeMaskAtTime(self.time)
        shown = np.asarray(mask, dtype=bool) if len(mask) == len(index) else np.ones(len(index), dtype=bool)
        return xf, index, shown, targets

    # -- geometry -------------------------------------------------------------------------

    def _geometry(self, prim):
        path = str(prim.GetPath())
        if path not in self.index:
            self.index[path] = len(self.geometries)
            self.geometries.append(self._read_mesh(prim, path))
        return self.index[path]

    def _read_mesh(self, prim, path):
        mesh = self.UsdGeom.Mesh(prim)
        t = self.time
        left = mesh.GetOrientationAttr().Get(t) == self.UsdGeom.Tokens.leftHanded
        counts, corners, holes = self._polygons(mesh, path)
        if self.plain:  # the faces, then the polygon arrays let go before the points come
            faces, top = fan_faces(counts, corners, holes, left), _top(corners)
            del counts, corners, holes
            return Geometry(path, self._points(mesh, path, top), faces)
        points = self._points(mesh, path, _top(corners))
        topo = _Topology(counts, corners, holes, left, len(points))
        return _with_primvars(path, mesh, points, topo, self.time)

    def _polygons(self, mesh, path):
        """(faceVertexCounts, faceVertexIndices, holeIndices or None) as integer arrays,
        checked to add up; unauthored: empty (a mesh without faces)."""
        t = self.time
        # The largest array first, while nothing else is held: usd-core decodes it with a
        # transient buffer of its own. They stay the Vt arrays' int32 (no copy).
        corners = _array(mesh.GetFaceVertexIndicesAttr().Get(t) or [], np.int32)
        counts = _array(mesh.GetFaceVertexCountsAttr().Get(t) or [], np.int32)
        if counts is None or corners is None:
            raise ScatterError(f"{self.source}: mesh {path}: malformed points or faces")
        if (len(counts) and counts.min() < 0) or counts.sum() != len(corners):
            raise ScatterError(f"{self.source}: mesh {path}: faceVertexCounts do not add up to faceVertexIndices")
        if len(corners) and corners.min() < 0:
            raise ScatterError(f"{self.source}: mesh {path}: face vertex index out of range")
        return counts, corners, _array(mesh.GetHoleIndicesAttr().Get(t), np.int32)

    def _points(self, mesh, path, top):
        """(V, 3) float64 points; ``top``: the largest vertex index the faces use (-1: none)."""
        points = _array(mesh.GetPointsAttr().Get(self.time) or [], np.float64, 3)
        if points is None:
            raise ScatterError(f"{self.source}: mesh {path}: malformed points or faces")
        if top >= len(points):
            raise ScatterError(f"{self.source}: mesh {path}: face vertex index out of range")
        return points


def _top(corners):
    return int(corners.max()) if len(corners) else -1


def stage_units(stage):
    """(up axis "Y" or "Z", metres per unit) of a stage: as authored, else USD's fallbacks
    (Y up, 0.01: centimetres), which is what the stage's coordinates mean."""
    from pxr import UsdGeom

    return str(UsdGeom.GetStageUpAxis(stage)), float(UsdGeom.GetStageMetersPerUnit(stage))


def _array(value, dtype, width=None):
    """A Vt array -> numpy (n,) or (n, width) of ``dtype`` (integers: any integer type, as
    stored, no copy); None when unset or of the wrong shape."""
    if value is None:
        return None
    a = np.asarray(value)
    if not (np.issubdtype(dtype, np.integer) and np.issubdtype(a.dtype, np.integer)):
        a = a.astype(dtype, copy=False)
    if width is None:
        return a.reshape(-1) if a.ndim <= 1 else None
    if a.size == 0:
        return a.reshape(0, width)
    return a if a.ndim == 2 and a.shape[1] == width else None


def fan_faces(counts, corners, holes=None, left_handed=False, block=1 << 16):
    """(F, 3) int64 vertex indices of the fan triangles of polygons, in polygon order:
    polygon k, at positions s .. s+c-1 of ``corners``, gives (s, s+j+1, s+j+2) for j = 0
    .. c-3 (none for fewer than 3 corners, nor for a hole); ``left_handed`` swaps the last
    two corners of each.

    counts (P,), corners (C,) and holes (H,) integer arrays (faceVertexCounts,
    faceVertexIndices, holeIndices). Polygons of one size are a reshape; mixed sizes go
    ``block`` polygons at a time, so no (F,) table is built beside the result.
    """
    hole = _hole_mask(counts, holes)
    if len(counts) and counts.min() == counts.max() >= 3 and not hole.any():
        c = int(counts[0])
        grid = corners.reshape(len(counts), c)
        faces = np.empty((len(counts), c - 2, 3), dtype=np.int64)
        faces[:, :, 0] = grid[:, :1]
        faces[:, :, 1] = grid[:, 1:-1]
        faces[:, :, 2] = grid[:, 2:]
        faces = faces.reshape(-1, 3)
    else:
        faces = np.empty((int(_made(counts, hole).sum()), 3), dtype=np.int64)
        at = row = 0
        for p in range(0, len(counts), block):
            n = np.asarray(counts[p : p + block], dtype=np.int64)
            made = _made(n, hole[p : p + block])
            polygon = np.repeat(np.arange(len(n)), made)
            s = (at + np.cumsum(n) - n)[polygon]
            rows = faces[row : row + len(polygon)]
            rows[:, 0] = corners[s]
            s += np.arange(len(polygon)) - (np.cumsum(made) - made)[polygon]  # s + j
            rows[:, 1] = corners[s + 1]
            rows[:, 2] = corners[s + 2]
            at += int(n.sum())
            row += len(polygon)
    if left_handed:
        second = faces[:, 1].copy()
        faces[:, 1] = faces[:, 2]
        faces[:, 2] = second
    return faces


def _hole_mask(counts, holes):
    """(P,) bool: the polygons ``holes`` names (indices out of range ignored)."""
    hole = np.zeros(len(counts), dtype=bool)
    if holes is not None and len(holes):
        hole[holes[(holes >= 0) & (holes < len(counts))]] = True
    return hole


def _made(counts, hole):
    """(P,) int64 triangles each polygon's fan makes: corners - 2, none for a hole."""
    made = np.maximum(np.asarray(counts, dtype=np.int64) - 2, 0)
    made[hole] = 0
    return made


class _Topology:
    """A mesh's polygons and triangles, for expanding primvars to the rows a table needs;
    the per-triangle tables are made only when a primvar needs them."""

    def __init__(self, counts, corners, holes, left_handed, n_points):
        self.counts, self.corners, self.n_points = counts, corners, n_points
        self.hole, self.left_handed = _hole_mask(counts, holes), left_handed
        self.triangles = int(_made(counts, self.hole).sum())
        self.sizes = {"constant": 1, "uniform": len(counts), "vertex": n_points, "varying": n_points,
                      "faceVarying": len(corners)}

    def faces(self):
        """(F, 3) int64 vertex indices of the triangles."""
        return fan_faces(self.counts, self.corners, np.flatnonzero(self.hole), self.left_handed)

    @functools.cached_property
    def tri(self):
        """(F, 3) int64 positions in faceVertexIndices of the triangles' corners."""
        return fan_faces(self.counts, np.arange(len(self.corners)), np.flatnonzero(self.hole), self.left_handed)

    @functools.cached_property
    def polygon(self):
        """(F,) int64 the polygon of each triangle."""
        return np.repeat(np.arange(len(self.counts)), _made(self.counts, self.hole))

    @functools.cached_property
    def polygon_of_corner(self):
        return np.repeat(np.arange(len(self.counts)), self.counts)

    def expand(self, values, interpolation, rows):
        """Primvar values (n, C) -> one row per ``rows`` ("point", "corner" or "triangle"),
        or None when that interpolation cannot give such rows."""
        if interpolation == "constant":
            n = {"point": self.n_points, "corner": len(self.corners), "triangle": self.triangles}[rows]
            return np.broadcast_to(values[:1], (n, values.shape[1]))
        if interpolation == "uniform":
            return {"corner": lambda: values[self.polygon_of_corner], "triangle": lambda: values[self.polygon]}.get(
                rows, lambda: None)()
        if interpolation in ("vertex", "varying"):
            return {"point": lambda: values, "corner": lambda: values[self.corners]}.get(rows, lambda: None)()
        return values if rows == "corner" else None


def _primvar(api, name, topo, time, inherited=False):
    """(values (n, C) float64, interpolation) of an authored primvar, or None."""
    pv = api.FindPrimvarWithInheritance(name) if inherited else api.GetPrimvar(name)
    if not pv or not pv.HasValue():
        return None
    return _checked(pv.ComputeFlattened(time), pv.GetInterpolation(), topo)


def _checked(values, interpolation, topo):
    if values is None or interpolation not in topo.sizes:
        return None
    a = np.asarray(values, dtype=np.float64)
    a = a.reshape(len(a), -1) if a.ndim else a.reshape(1, 1)
    return (a, interpolation) if len(a) == topo.sizes[interpolation] else None


def _uv_primvar(api, topo, time):
    """``primvars:st``, else the first texture-coordinate primvar."""
    found = _primvar(api, "st", topo, time)
    if found is not None:
        return found
    for pv in api.GetPrimvarsWithValues():
        if str(pv.GetTypeName().role) == "TextureCoordinate":
            return _primvar(api, pv.GetPrimvarName(), topo, time)
    return None


def _with_primvars(path, mesh, points, topo, time):
    """The Geometry with its uv, colour and normal tables (per point, or per corner when a
    face-varying or uniform value needs it)."""
    from pxr import UsdGeom

    api = UsdGeom.PrimvarsAPI(mesh.GetPrim())
    uv = _uv_primvar(api, topo, time)
    normals = _primvar(api, "normals", topo, time)
    if normals is None and mesh.GetNormalsAttr().HasAuthoredValue():
        normals = _checked(mesh.GetNormalsAttr().Get(time), mesh.GetNormalsInterpolation(), topo)
    rgb = _primvar(api, "displayColor", topo, time, inherited=True)
    alpha = _primvar(api, "displayOpacity", topo, time, inherited=True)
    color = [c for c in (rgb, alpha) if c is not None] if rgb is not None else []
    color_rank = max((_RANK[i] for _, i in color), default=0)
    per_point = [p for p in (uv, normals) if p is not None] + (color if color_rank >= 2 else [])
    rows = "corner" if any(_RANK[i] in (1, 3) for _, i in per_point) else "point"

    def table(p, width):
        return None if p is None else np.ascontiguousarray(topo.expand(p[0], p[1], rows)[:, :width])

    if rows == "corner":
        vertices, faces, point_of = points[topo.corners], topo.tri, topo.corners
    else:
        vertices, faces, point_of = points, topo.faces(), None
    tables = VertexTables(vertices, faces, uv=table(uv, 2), normals=table(normals, 3), point_of=point_of)
    if color:
        kind = {0: "constant_color", 1: "face_colors"}.get(color_rank, "vertex_colors")
        at = {0: "triangle", 1: "triangle"}.get(color_rank, rows)
        rgba = np.empty((topo.triangles if at == "triangle" else len(vertices), 4))
        rgba[:, :3] = topo.expand(rgb[0], rgb[1], at)[:, :3] * 255.0
        rgba[:, 3] = 255.0 if alpha is None else topo.expand(alpha[0], alpha[1], at)[:, 0] * 255.0
        setattr(tables, kind, rgba[0] if kind == "constant_color" else rgba)
    return Geometry(path, vertices, faces, tables)


def select_paths(surface: Surface, paths, aliases) -> Surface:
    """Keep the instances at or below the given prim paths (by instance name, or by the
    prototype mesh's own path), in instance order."""
    wanted = [p.rstrip("/") or "/" for p in paths]

    def under(name, p):
        return p == "/" or name == p or name.startswith(p + "/") or name.startswith(p + "[")

    hits = {p: [k for k, inst in enumerate(surface.instances) if under(inst.name, p) or under(aliases[k], p)]
            for p in wanted}
    missing = [p for p in wanted if not hits[p]]
    if missing:
        names = [i.name for i in surface.instances]
        shown = ", ".join(names[:20]) + (f", ... ({len(names)} in all)" if len(names) > 20 else "")
        raise ScatterUsageError(f"{surface.source}: no mesh at or under {', '.join(map(repr, missing))} "
                                f"(meshes: {shown or 'none'})")
    kept = sorted(set().union(*hits.values()))
    return surface.keeping([surface.instances[k] for k in kept])

