"""USD output (optional extra ``usd``: usd-core): a ``UsdGeomPoints`` prim, or with
``orient`` a ``UsdGeomPointInstancer`` with one placeholder prototype.

USD arrays live in memory whole (a stage cannot be streamed), so the writer gathers the
points into preallocated arrays and refuses up front a count that would not fit. Points
are ``point3f``: float64 runs store them relative to a double-precision translate (the
centre of the sampled box) so large coordinates keep their precision.

Layout under the default prim ``/Scatter`` (an Xform):
- ``Points``: ``points``, primvars ``normals``, ``displayColor``/``displayOpacity``, ``st``,
  and every other column under its own name (``face_index``, ``bary``, ``object_index``,
  ``sharp``; volume labels ``sdf``, ``inside``, ``winding``, and ``closest``, a point3f
  array in the space of ``points``), all of vertex interpolation; ``extent``;
- with orient, ``Instancer``: ``positions``, ``orientations`` (quath, what every reader
  knows) and ``orientationsf`` (quatf, full precision), ``protoIndices`` all 0, the same
  primvars per instance, and ``prototypes`` -> ``Instancer/Prototypes/Placeholder``, a
  cone along +Z sized to the point spacing, for the user to retarget.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile

import numpy as np

from ..errors import ScatterError
from .base import Writer
from ..loading.usd import open_stage
from .pointfiles import COLOR_NAMES, NORMAL_NAMES, IsMesh, stride

# Bytes per point of each value as the stage holds it (float32 values, colour as rgb and
# opacity, orient as quatf, quath and a protoIndices int), once as a Vt array and once
# serialised; the gathered NumPy arrays come on top (see check_fits).
USD_BYTES = {"points": 12, "normal": 12, "color": 16, "uv": 8, "face": 4, "bary": 12, "object": 4, "orient": 28,
             "closest": 12}
DEFAULT_UP_AXIS, DEFAULT_METERS_PER_UNIT = "Y", 1.0
# key -> (primvar name, Sdf value type name, NumPy type of its values): every column but
# the points, the colour and orient. Values are float32 as USD's points are, but for the
# labels computed in float64 whatever the points' precision (sdf, winding).
PRIMVARS = {
    "normal": ("normals", "Normal3fArray", np.float32),
    "bary": ("bary", "Float3Array", np.float32),
    "uv": ("st", "TexCoord2fArray", np.float32),
    "face": ("face_index", "IntArray", np.int32),
    "object": ("object_index", "IntArray", np.int32),
    "sdf": ("sdf", "DoubleArray", np.float64),
    "inside": ("inside", "UCharArray", np.uint8),
    "winding": ("winding", "DoubleArray", np.float64),
    "closest": ("closest", "Point3fArray", np.float32),  # in the points' space: under their translate
    "sharp": ("sharp", "UCharArray", np.uint8),
}
POSITIONS = ("points", "closest")  # float64 ones are stored relative to the translate


def _pxr(doing="USD output"):
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    except ImportError:
        raise ScatterError(f"{doing} needs usd-core: pip install usd-core") from None
    return Gf, Sdf, Usd, UsdGeom, Vt


def available_memory():
    """Bytes of memory available to this process now (MemAvailable), or None when unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def bytes_per_point(layout):
    """Memory the stage needs per point: the gathered arrays (the layout's dtypes, and a
    centred copy of float64 points), plus each value as a Vt array and serialised."""
    total = 0
    for key, cols, dt in layout:
        gathered = dt.itemsize * len(cols)
        total += gathered * (2 if key in POSITIONS and dt == np.float64 else 1) + 2 * USD_BYTES.get(key, gathered)
    return total


def check_fits(count, layout, available=None, path=None):
    """Refuse, in one line, a count whose stage would not fit in the memory available."""
    need = bytes_per_point(layout) * count
    available = available_memory() if available is None else available
    if available is not None and need > available:
        where = f"{path}: " if path else ""
        raise ScatterError(f"{where}USD output is built in memory (it cannot stream): {count:,} points need about "
                           f"{need / 1e9:.3g} GB, more than the {available / 1e9:.3g} GB available; "
                           "write PLY, PCD or LAS instead, or split the run with --shard")


class UsdWriter(Writer):
    def __init__(self, stream, layout, count, path=None, up_axis=None, meters_per_unit=None, spacing=None):
        super().__init__(stream, layout, count)
        _pxr()
        self.path = None if path is None or str(path) == "-" else os.fspath(path)
        check_fits(count, layout, path=self.path or "<stdout>")
        self.up_axis = up_axis or DEFAULT_UP_AXIS
        self.meters_per_unit = meters_per_unit or DEFAULT_METERS_PER_UNIT
        self.spacing = spacing
        self.report = {"usd": {"up_axis": self.up_axis, "meters_per_unit": self.meters_per_unit,
                               "from_input": up_axis is not None or meters_per_unit is not None}}
        self.data = {key: np.empty((count, len(cols)), dtype=dt) for key, cols, dt in layout}

    def write(self, samples):
        a, b = self.written, self.written + len(samples)
        for key, cols, _ in self.layout:
            src = samples.points if key == "points" else samples.attributes[key]
            self.data[key][a:b] = src.reshape(len(samples), len(cols))
        self.written = b

    def finish(self):
        super().finish()
        stage = self.stage()
        if self.path is None or self.path.lower().endswith(".usda"):
            self.stream.write(stage.GetRootLayer().ExportToString().encode())
            return
        self.stream.write(export_crate(stage))

    def stage(self):
        """The Usd.Stage holding the points."""
        Gf, Sdf, Usd, UsdGeom, Vt = _pxr()
        stage = Usd.Stage.CreateInMemory()
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if self.up_axis == "Y" else UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, self.meters_per_unit)
        root = UsdGeom.Xform.Define(stage, "/Scatter")
        stage.SetDefaultPrim(root.GetPrim())
        points = self.data["points"]
        centre = None
        if points.dtype == np.float64 and len(points):
            lo, hi = points.min(axis=0), points.max(axis=0)
            centre = 0.5 * (lo + hi)
            root.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*centre.tolist()))
        local = self._local("points", centre)
        extent = Vt.Vec3fArray.FromNumpy(np.stack([local.min(axis=0), local.max(axis=0)]) if len(local)
                                         else np.zeros((2, 3), np.float32))
        if "orient" in self.data:
            prim = self._instancer(stage, local, extent)
        else:
            prim = UsdGeom.Points.Define(stage, "/Scatter/Points")
            prim.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(local))
            prim.CreateExtentAttr(extent)
        self._primvars(prim, centre)
        return stage

    def _local(self, key, centre):
        """(n, 3) float32 positions of the column ``key`` under the root's translate ``centre`` (or None)."""
        values = self.data[key]
        return np.ascontiguousarray(values if centre is None else values - centre, dtype=np.float32)

    def _instancer(self, stage, local, extent):
        Gf, Sdf, Usd, UsdGeom, Vt = _pxr()
        inst = UsdGeom.PointInstancer.Define(stage, "/Scatter/Instancer")
        inst.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(local))
        q = np.ascontiguousarray(self.data["orient"], dtype=np.float32)  # Gf's memory order: x y z, then w
        if hasattr(inst, "CreateOrientationsfAttr"):  # usd-core releases before 2024 lack it
            inst.CreateOrientationsfAttr(Vt.QuatfArray.FromNumpy(q))
        inst.CreateOrientationsAttr(Vt.QuathArray.FromNumpy(q.astype(np.float16)))
        inst.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.zeros(len(local), dtype=np.int32)))
        UsdGeom.Scope.Define(stage, "/Scatter/Instancer/Prototypes")
        cone = UsdGeom.Cone.Define(stage, "/Scatter/Instancer/Prototypes/Placeholder")
        size = self.spacing or 1.0
        cone.CreateAxisAttr(UsdGeom.Tokens.z)
        cone.CreateHeightAttr(size)
        cone.CreateRadiusAttr(size / 4)
        cone.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-size / 4, -size / 4, -size / 2),
                                             Gf.Vec3f(size / 4, size / 4, size / 2)]))
        cone.AddTranslateOp().Set(Gf.Vec3d(0, 0, size / 2))  # base on the surface, tip along the normal
        inst.CreatePrototypesRel().SetTargets([cone.GetPath()])
        return inst

    def _primvars(self, prim, centre):
        Gf, Sdf, Usd, UsdGeom, Vt = _pxr()
        api = UsdGeom.PrimvarsAPI(prim)
        vertex = UsdGeom.Tokens.vertex
        for key, (name, type_name, kind) in PRIMVARS.items():
            if key not in self.data:
                continue
            values = self._local(key, centre) if key in POSITIONS else self.data[key]
            values = np.ascontiguousarray(values[:, 0] if values.shape[1] == 1 else values, dtype=kind)
            value_type = getattr(Sdf.ValueTypeNames, type_name)
            api.CreatePrimvar(name, value_type, vertex).Set(value_type.type.pythonClass.FromNumpy(values))
        if "color" in self.data:
            c = self.data["color"].astype(np.float32) / 255.0
            api.CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, vertex).Set(
                Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(c[:, :3])))
            api.CreatePrimvar("displayOpacity", Sdf.ValueTypeNames.FloatArray, vertex).Set(
                Vt.FloatArray.FromNumpy(np.ascontiguousarray(c[:, 3])))


def make(fmt, stream, layout, count, path=None, up_axis=None, meters_per_unit=None, spacing=None, **options):
    return UsdWriter(stream, layout, count, path, up_axis, meters_per_unit, spacing)


def export_crate(stage):
    """The stage's root layer as .usdc bytes (crate files are written by file name only)."""
    fd, tmp = tempfile.mkstemp(suffix=".usdc")
    os.close(fd)
    try:
        if not stage.GetRootLayer().Export(tmp):
            raise ScatterError("USD could not encode the stage as .usdc")
        with open(tmp, "rb") as f:
            return f.read()
    finally:
        os.unlink(tmp)


# -- the reader ---------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class UsdFile:
    """The points of a USD stage, read whole (a stage cannot be streamed; see
    :mod:`.pointfiles`): ``data``, name -> (count,) array of each column; ``up_axis``, the
    stage's. Not joined: USD is not mergeable."""

    path: str
    data: dict
    count: int
    up_axis: str

    def columns(self, limit=None):
        """Every column, of every point or of every k-th when there are more than ``limit``."""
        every = stride(self.count, limit)
        return {name: column[::every] for name, column in self.data.items()}


def read(path, fmt="usd"):
    """The points of every UsdGeom.Points (``points``) and PointInstancer (``positions``)
    prim of the stage at ``path``, in world space (x, y, z), with their ``normals`` (nx,
    ny, nz) and ``displayColor`` (red, green, blue) primvars where every prim has them."""
    Gf, Sdf, Usd, UsdGeom, Vt = _pxr(f"{path}: reading USD")
    if not os.path.isfile(path):
        raise ScatterError(f"{path}: no such file")
    stage = open_stage(path, path)  # in the mesh loader's words, so that sample and preview say the same
    prims = [p for p in stage.Traverse() if p.IsA(UsdGeom.Points) or p.IsA(UsdGeom.PointInstancer)]
    if not prims:
        raise IsMesh(f"{path}: a USD stage without points is a mesh, not a point file")
    points, normals, colours = zip(*(_prim_points(prim, Usd, UsdGeom) for prim in prims))
    data = dict(zip("xyz", np.concatenate(points).T))
    if all(n is not None for n in normals):
        data.update(zip(NORMAL_NAMES, np.concatenate(normals).T))
    if all(c is not None for c in colours):
        data.update(zip(COLOR_NAMES, np.clip(np.rint(np.concatenate(colours) * 255), 0, 255).T))
    up = "Y" if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y else "Z"
    return UsdFile(path, data, sum(len(p) for p in points), up)


def _prim_points(prim, Usd, UsdGeom):
    """(points (n, 3) in world space, normals (n, 3) or None, colours (n, 3) or None) of
    a Points or PointInstancer prim."""
    if prim.IsA(UsdGeom.Points):
        value = UsdGeom.Points(prim).GetPointsAttr().Get()
    else:
        value = UsdGeom.PointInstancer(prim).GetPositionsAttr().Get()
    local = np.array(value if value is not None else [], dtype=np.float64).reshape(-1, 3)
    matrix = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))
    api = UsdGeom.PrimvarsAPI(prim)
    return (local @ matrix[:3, :3] + matrix[3, :3],  # USD: row vectors
            _primvar(api, "normals", len(local)), _primvar(api, "displayColor", len(local)))


def _primvar(api, name, n):
    """(n, 3) float64 of the primvar ``name``, or None when it is missing or not one a point."""
    primvar = api.GetPrimvar(name)
    value = primvar.Get() if primvar and primvar.HasValue() else None
    if value is None:
        return None
    values = np.array(value, dtype=np.float64).reshape(-1, 3)
    return values if len(values) == n else None
