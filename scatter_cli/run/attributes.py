"""Per-point attributes, computed only when asked for.

An :class:`AttributeMaker` is built once per run from the surface and the requested
names; it prepares only the per-geometry tables those names need (never one copy per
instance), then turns each :class:`~scatter_cli.sampling.plan.RawChunk` into the attribute
arrays. Nothing else is touched: no normals without ``normal``/``smooth-normal``, no UV
table without ``uv``/``color``, no image decoded without ``color``.
"""

from __future__ import annotations

import numpy as np

from ..errors import ScatterError
from ..loading import textures as textures_named
from .columns import ATTRIBUTES
from ..sampling.normals import face_normals
from ..surface.model import Surface, normal_transforms
from ..surface.data import color_source, interpolate, uv_table, vertex_normal_table


NORMAL_USERS = ("normal", "smooth-normal", "orient")


class AttributeMaker:
    split_chunks = True  # chunks may be cut into pieces on the threads (sampling.plan.run_chunks)

    def __init__(self, surface: Surface, names, seed=0):
        self.surface = surface
        self.seed = seed  # keys the orient spin stream
        self.names = tuple(names)
        self.needs_bary = any(n in ("bary", "smooth-normal", "uv", "color") for n in self.names)
        self._tables = {}
        # Geometries that receive points, in first-use order (instances share them).
        self._used = list(dict.fromkeys(i.geometry for i in surface.instances))
        # per instance: its geometry, whether it has a matrix, and the normal transform
        self._geometry = np.array([i.geometry for i in surface.instances], dtype=np.int64)
        self._moved = np.array([i.matrix is not None for i in surface.instances], dtype=bool)
        self._cof = normal_transforms([i.matrix for i in surface.instances])
        for name in self.names:
            getattr(self, "_prepare_" + name.replace("-", "_"), lambda: None)()

    def make(self, raw, real_dtype):
        """dict key -> array for the requested names, from one raw chunk."""
        out = {}
        groups = self._groups(raw) if len(self.surface.instances) > 1 else None
        normals = None  # float64, shared by normal/smooth-normal and orient
        for name in self.names:
            key = ATTRIBUTES[name][0]
            if name in NORMAL_USERS:
                if normals is None:
                    normals = self._normals(raw, groups)
                out[key] = (self._orient(raw, normals) if name == "orient" else normals).astype(real_dtype)
            else:
                out[key] = getattr(self, "_make_" + name.replace("-", "_"))(raw, real_dtype, groups)
        return out

    # -- plumbing ---------------------------------------------------------------------

    def _groups(self, raw):
        """[(geometry gi, rows (m,) int64)] for the geometries of the chunk's points."""
        geometry = self._geometry[raw.instance]
        order = np.argsort(geometry, kind="stable")
        bounds = np.searchsorted(geometry[order], np.arange(len(self.surface.geometries) + 1))
        return [(g, order[bounds[g] : bounds[g + 1]]) for g in range(len(bounds) - 1) if bounds[g + 1] > bounds[g]]

    def _per_geometry(self, raw, groups, compute, width, dtype=np.float64):
        """Run ``compute(gi, face, bary) -> (m, width)`` per geometry and scatter the rows."""
        if groups is None:
            return compute(int(self._geometry[0]), raw.face, raw.bary)
        out = np.empty((len(raw.face), width), dtype=dtype)
        for gi, rows in groups:
            out[rows] = compute(gi, raw.face[rows], None if raw.bary is None else raw.bary[rows])
        return out

    def _missing(self, name, what, geometry):
        g = self.surface.geometries[geometry]
        where = f"object '{g.name}' has" if self.surface.is_scene else "the mesh has"
        hint = " (choose objects that have them with --object)" if self.surface.is_scene else ""
        raise ScatterError(f"{self.surface.source}: cannot write attribute '{name}': {where} no {what}{hint}")

    def _to_world(self, instance, n, rows=None):
        """Directions ``n`` (m, 3) of the points' instances (m,) -> unit world-space normals,
        in place. ``rows``: only those rows (default: all) are transformed and normalised."""
        if rows is None:
            rows = np.arange(len(n))
        moved = rows[self._moved[instance[rows]]]
        if len(moved):
            cof = self._cof[instance[moved]]
            v = n[moved]
            for c, col in enumerate(_row_by_row(cof, v)):
                n[moved, c] = col
        m = n[rows]
        with np.errstate(invalid="ignore", divide="ignore"):
            m /= np.sqrt(np.einsum("ij,ij->i", m, m))[:, None]
        n[rows] = m
        return n

    # -- face, object, bary -----------------------------------------------------------

    def _make_face(self, raw, real_dtype, groups):
        return raw.face.astype(np.int32)

    def _make_object(self, raw, real_dtype, groups):
        index = self.surface.object_index  # the whole file's numbering, under --object too
        return (raw.instance if index is None else index[raw.instance]).astype(np.int32)

    def _make_bary(self, raw, real_dtype, groups):
        return raw.bary.astype(real_dtype)

    def _make_sharp(self, raw, real_dtype, groups):
        """1 for the points drawn on sharp edges (``--edges``), else 0."""
        if raw.sharp is None:
            return np.zeros(len(raw.face), dtype=np.uint8)
        return raw.sharp.astype(np.uint8)

    # -- normal: the geometric face normal --------------------------------------------

    def _prepare_normal(self):
        for gi in self._used:
            if ("normal", gi) in self._tables:
                continue
            g = self.surface.geometries[gi]
            self._tables["normal", gi] = face_normals(g.vertices, g.faces)  # 0 on faces that get no points

    def _normals(self, raw, groups):
        """(n, 3) float64 unit normals: smooth when smooth-normal is asked for, else the face's."""
        if "smooth-normal" in self.names:
            return self._smooth_normals(raw, groups)
        return self._face_normals(raw, groups)

    def _face_normals(self, raw, groups):
        """(n, 3) float64 world-space unit normals of the points' faces; an edge point
        (``--edges``) gets its edge's normal instead."""
        n = self._per_geometry(raw, groups, lambda gi, face, bary: np.take(self._tables["normal", gi], face, axis=0), 3)
        n = self._to_world(raw.instance, n, np.flatnonzero(self._moved[raw.instance]))
        if raw.sharp is not None:
            on_edge = np.flatnonzero(raw.sharp)
            n[on_edge] = raw.normal[on_edge]
        return n

    # -- orient: +Z onto the normal, then a spin about it from the seed ------------------

    def _prepare_orient(self):
        if "smooth-normal" not in self.names:
            self._prepare_normal()

    def _orient(self, raw, normals):
        from .orient import point_orientations

        return point_orientations(normals, self.seed, raw.start)

    # -- smooth-normal: vertex normals, interpolated and normalised -------------------

    def _prepare_smooth_normal(self):
        self._prepare_normal()  # the fallback where interpolated normals cancel out
        for gi in self._used:
            self._tables["vn", gi] = vertex_normal_table(self.surface.geometries[gi])

    def _smooth_normals(self, raw, groups):
        def compute(gi, face, bary):
            return interpolate(self._tables["vn", gi], self.surface.geometries[gi].faces, face, bary)

        n = self._to_world(raw.instance, self._per_geometry(raw, groups, compute, 3))
        bad = np.flatnonzero(~np.isfinite(n[:, 0]) | (np.abs(n).max(axis=1) < 0.5))  # unit vectors have a component >= 1/sqrt(3)
        if len(bad):
            sub = raw.take(bad)
            flat = self._per_geometry(sub, None if groups is None else self._groups(sub),
                                      lambda gi, face, bary: np.take(self._tables["normal", gi], face, axis=0), 3)
            n[bad] = self._to_world(sub.instance, flat)
        return n

    # -- uv -----------------------------------------------------------------------------

    def _prepare_uv(self):
        for gi in self._used:
            uv = uv_table(self.surface.geometries[gi].mesh)
            if uv is None:
                self._missing("uv", "texture coordinates", gi)
            self._tables["uv", gi] = uv

    def _make_uv(self, raw, real_dtype, groups):
        def compute(gi, face, bary):
            return interpolate(self._tables["uv", gi], self.surface.geometries[gi].faces, face, bary)

        return self._per_geometry(raw, groups, compute, 2).astype(real_dtype)

    # -- color --------------------------------------------------------------------------

    def _prepare_color(self):
        textures_named.require_pillow(self.surface.source)
        textures = self.surface._cache.setdefault("textures", {})
        for gi in self._used:
            g = self.surface.geometries[gi]
            src = color_source(g.mesh, g.faces, self.surface.source, textures)
            if src is None:
                self._missing("color", "vertex colours, face colours, texture or material colour", gi)
            src.prepare()
            self._tables["color", gi] = src

    def _make_color(self, raw, real_dtype, groups):
        def compute(gi, face, bary):
            return self._tables["color", gi].colors(face, bary)

        c = self._per_geometry(raw, groups, compute, 4)
        return np.rint(np.clip(c, 0.0, 255.0)).astype(np.uint8)


def _row_by_row(m, v):
    """Columns of ``m[i] @ v[i]`` for m (n, 3, 3), v (n, 3): [x, y, z] each (n,), with the
    element-wise operations of :func:`surface.apply_matrix` in its order (the same bits)."""
    x, y, z = (v[:, c] for c in range(3))
    out = []
    for c in range(3):
        col = m[:, c, 0] * x
        col += m[:, c, 1] * y
        col += m[:, c, 2] * z
        out.append(col)
    return out
