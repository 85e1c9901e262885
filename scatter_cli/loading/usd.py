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

Triangulation and primvars: usdmesh.py.

Instance names (``--object``, ``scatter info``): a mesh's prim path; inside an
instanceable prim, the instance proxy path (``/World/house_2/roof``); inside a point
instancer's prototype, the instancer's path with the instance index, then the mesh's path
below the prototype's parent (``/World/trees[17]/oak/trunk``).
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile

import numpy as np

from ..errors import ScatterError
from .sourcefile import check_readable, stream_bytes
from ..surface.model import Geometry, Instance, Surface, Unsampled, corners, doubled_areas
from .usdmesh import Topology, fan_faces, with_primvars

INSTALL_HINT = "pip install usd-core"


def load_usd(path: str, input_format=None, *, objects=None, plain=False) -> Surface:
    """The surface of the USD stage at ``path`` (``-``: standard input, then
    ``input_format`` names the format); ``objects``: prim paths to keep.

    ``plain``: positions and faces only (no primvars are read).
    """
    name = "<stdin>" if path == "-" else path
    _import_pxr(name)
    with _diagnostics() as printed:
        if check_readable(path):  # USD reads files by name: a pipe's bytes go to a file first
            data = stream_bytes(path, f"{name}: no data to read")
            suffix = (input_format or os.path.splitext(path)[1].lstrip(".") or "usd").lower()
            with tempfile.TemporaryDirectory() as tmp:
                copy = os.path.join(tmp, "stage." + suffix)
                with open(copy, "wb") as f:
                    f.write(data)
                surface, aliases = _StageReader(open_stage(copy, name), name, plain).surface()
        else:
            surface, aliases = _StageReader(open_stage(path, name), name, plain).surface()
    # USD's own warnings (a reference that does not resolve, ...) as the run's warnings
    surface.warnings += [f"{name}: {m}" for m in map(_diagnostic, printed) if m]
    surface.warnings += unsampled_warning(name, surface.unsampled)
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


def unsampled_warning(name, unsampled):
    """The run's warning (a list of one line, or none) when prims that are not sampled hold area."""
    held = [u for u in unsampled if u.area > 0]
    if not held:
        return []
    reasons = sorted({u.reason for u in held})
    return [f"{name}: {len(held)} prim(s) holding {sum(u.area for u in held):.6g} units of area are not sampled "
            f"({'; '.join(reasons)}): `scatter info` lists them"]


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


def open_stage(path, name):
    """The stage at ``path`` (``name``: the file as messages call it); a one-line
    ScatterError when it is not one (the words of sample, batch and preview alike)."""
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
        self.unsampled: list[Unsampled] = []
        # A point instancer's prototypes are drawn wherever they are defined, under a class
        # (abstract) prim too; the stage itself is walked with USD's default predicate.
        self.anywhere = Usd.PrimIsActive & Usd.PrimIsLoaded

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
        surface = Surface(self.geometries, instances, self.source, is_scene=True, unsampled=self.unsampled)
        surface.up_axis, surface.meters_per_unit = stage_units(self.stage)
        return surface, placed.aliases

    # -- placements -----------------------------------------------------------------------

    def _walk(self, root, base, predicate=None) -> _Placed:
        """Meshes under ``root`` (itself included), each with the matrix that maps its points
        into the frame of ``base`` (an ancestor prim; None: world space); ``predicate``:
        which prims the walk visits (None: USD's default)."""
        out = []
        it = iter(self.Usd.PrimRange(root) if predicate is None else self.Usd.PrimRange(root, predicate))
        for prim in it:
            why = self._skipped(prim)
            if why:
                it.PruneChildren()
                self._note(prim, why, base, predicate)
            elif prim.IsInstance():
                it.PruneChildren()
                out.append(self._instance(prim, base))
            elif prim.IsA(self.UsdGeom.PointInstancer):
                it.PruneChildren()
                out.append(self._point_instances(prim, base))
            elif prim.IsA(self.UsdGeom.Mesh):
                path = str(prim.GetPath())
                out.append(_Placed([self._geometry(prim)], self._matrix(prim, base), [path], [path]))
            elif prim.IsA(self.UsdGeom.Gprim):
                self._note(prim, f"a {prim.GetTypeName()} prim, not a mesh", base, predicate)
        return _Placed.join(out) if out else _Placed([], [], [], [])

    def _note(self, prim, why, base, predicate):
        """Record the geometry under ``prim`` (itself included) as not sampled, ``why``; area
        in the frame of ``base`` (world space when None: inside a prototype, one instance's)."""
        rng = self.Usd.PrimRange(prim) if predicate is None else self.Usd.PrimRange(prim, predicate)
        for p in rng:
            if p.IsA(self.UsdGeom.Gprim):
                self.unsampled.append(Unsampled(str(p.GetPath()), why, self._area(p, base)))

    def _area(self, prim, base):
        """The area of a gprim in the frame of ``base``: a mesh's triangles; an implicit
        shape's formula, under the matrix's mean scale (exact for uniform scales); 0.0 for
        prims without a surface (points, curves) or an unreadable one."""
        matrix = self._matrix(prim, base)
        try:
            if prim.IsA(self.UsdGeom.Mesh):
                mesh = self.UsdGeom.Mesh(prim)
                counts, corner, holes = self._polygons(mesh, str(prim.GetPath()))
                faces = fan_faces(counts, corner, holes)
                points = self._points(mesh, str(prim.GetPath()), _top(corner))
                with np.errstate(all="ignore"):
                    a = 0.5 * doubled_areas(corners(points, faces), matrix.T)
                return float(a[np.isfinite(a)].sum())
            local = shape_area(prim.GetTypeName(), lambda name: prim.GetAttribute(name).Get(self.time))
        except ScatterError:
            return 0.0
        return local * abs(float(np.linalg.det(matrix[:3, :3]))) ** (2 / 3)

    def _matrix(self, prim, base):
        if base is None:
            m = self.xforms.GetLocalToWorldTransform(prim)
        else:
            m = self.xforms.ComputeRelativeTransform(prim, base)[0]
        return np.array(m, dtype=np.float64)

    def _skipped(self, prim):
        """Why ``prim`` and its subtree are not drawn ("invisible", "guide purpose"...), or None."""
        if not prim.IsA(self.UsdGeom.Imageable):
            return None
        image = self.UsdGeom.Imageable(prim)
        if image.GetVisibilityAttr().Get(self.time) == self.UsdGeom.Tokens.invisible:
            return "invisible"
        purpose = image.GetPurposeAttr().Get(self.time)
        return f"{purpose} purpose" if purpose in self.skip_purposes else None

    def _subtree(self, root, base, predicate=None):
        """``_walk(root, base, predicate)``, once per prototype whatever its number of instances."""
        key = (str(root.GetPath()), None if base is None else str(base.GetPath()), predicate is None)
        if key not in self.subtrees:
            self.subtrees[key] = self._walk(root, base, predicate)
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
        inner = self._subtree(proto, parent, self.anywhere)
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
        topo = Topology(counts, corners, holes, left, len(points))
        return with_primvars(path, mesh, points, topo, self.time)

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


def shape_area(kind, get):
    """The area of an implicit USD shape of type ``kind`` in its own frame, its attributes
    read by ``get(name)`` (USD's fallbacks when unauthored); 0.0 for other types."""
    def value(name, fallback):
        v = get(name)
        return float(fallback if v is None else v)

    pi = np.pi
    if kind == "Cube":
        return 6.0 * value("size", 2.0) ** 2
    if kind == "Sphere":
        return 4.0 * pi * value("radius", 1.0) ** 2
    r, h = value("radius", 1.0), value("height", 2.0)
    if kind == "Cylinder":
        return 2.0 * pi * r * h + 2.0 * pi * r * r
    if kind == "Cone":
        return pi * r * r + pi * r * float(np.hypot(r, h))
    if kind == "Capsule":
        return 2.0 * pi * r * h + 4.0 * pi * r * r
    if kind == "Plane":
        return value("width", 2.0) * value("length", 2.0)
    return 0.0


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
        raise ScatterError(f"{surface.source}: no mesh at or under {', '.join(map(repr, missing))} "
                                f"(meshes: {shown or 'none'})")
    kept = sorted(set().union(*hits.values()))
    return surface.keeping([surface.instances[k] for k in kept])

