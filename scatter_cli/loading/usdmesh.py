"""A USD mesh's polygons as triangles, and its primvars (UVs, normals, colours) as the
per-vertex tables of a :class:`Geometry` (usdread.py walks the stage).

Triangulation: polygon k, with corners s .. s+c-1 in ``faceVertexIndices``, becomes the
fan (s, s+j+1, s+j+2) for j = 0 .. c-3, polygons in file order, each polygon's
triangles together; polygons of fewer than three corners and the faces listed in
``holeIndices`` give none; ``leftHanded`` meshes have the last two corners of each
triangle swapped so that face normals follow the right-hand rule.
"""

from __future__ import annotations

import functools

import numpy as np

from ..surface.model import Geometry
from ..surface.data import VertexTables

# How far an interpolation is from constant: a colour stored at the finest of its parts.
_RANK = {"constant": 0, "uniform": 1, "vertex": 2, "varying": 2, "faceVarying": 3}


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


class Topology:
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


def with_primvars(path, mesh, points, topo, time):
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
