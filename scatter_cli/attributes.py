"""Per-point attributes, computed only when asked for.

An :class:`AttributeMaker` is built once per run from the surface and the requested
names; it prepares only the per-geometry tables those names need (never one copy per
instance), then turns each :class:`~scatter_cli.sampling.RawChunk` into the attribute
arrays. Nothing else is touched: no normals without ``normal``/``smooth-normal``, no UV
table without ``uv``/``color``, no image decoded without ``color``.
"""

from __future__ import annotations

import numpy as np

from .errors import ScatterError
from .samples import ATTRIBUTES
from .surface import Surface, apply_matrix, cofactor
from .visuals import color_source, interpolate, uv_table, vertex_normal_table


NORMAL_USERS = ("normal", "smooth-normal", "orient")


class AttributeMaker:
    def __init__(self, surface: Surface, names, seed=0):
        self.surface = surface
        self.seed = seed  # keys the orient spin stream
        self.names = tuple(names)
        self.needs_bary = any(n in ("bary", "smooth-normal", "uv", "color") for n in self.names)
        self._tables = {}
        # Geometries that receive points, in first-use order (instances share them).
        self._used = list(dict.fromkeys(i.geometry for i in surface.instances))
        self._cof = {}
        for k, inst in enumerate(surface.instances):
            if inst.matrix is not None:
                # cof(A) = det(A) inv(A)^T: with sign(det) it is |det| inv(A)^T, the normal
                # transform that keeps normals outward under mirrors (glTF flips winding then).
                a = inst.matrix[:3, :3]
                self._cof[k] = cofactor(a) * (-1.0 if np.linalg.det(a) < 0 else 1.0)
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
        """[(instance k, rows (m,) int64)] for the instances present in the chunk."""
        order = np.argsort(raw.instance, kind="stable")
        bounds = np.searchsorted(raw.instance[order], np.arange(len(self.surface.instances) + 1))
        return [(k, order[bounds[k] : bounds[k + 1]]) for k in range(len(bounds) - 1) if bounds[k + 1] > bounds[k]]

    def _per_group(self, raw, groups, compute, width, dtype=np.float64):
        """Run ``compute(k, face, bary) -> (m, width)`` per instance and scatter the rows."""
        if groups is None:
            return compute(0, raw.face, raw.bary)
        out = np.empty((len(raw.face), width), dtype=dtype)
        for k, rows in groups:
            out[rows] = compute(k, raw.face[rows], None if raw.bary is None else raw.bary[rows])
        return out

    def _missing(self, name, what, geometry):
        g = self.surface.geometries[geometry]
        where = f"object '{g.name}' has" if self.surface.is_scene else "the mesh has"
        hint = " (choose objects that have them with --object)" if self.surface.is_scene else ""
        raise ScatterError(f"{self.surface.source}: cannot write attribute '{name}': {where} no {what}{hint}")

    def _geometry_of(self, k):
        return self.surface.instances[k].geometry

    def _to_world(self, k, n):
        """Directions ``n`` (m, 3) of instance k's frame -> unit world-space normals."""
        cof = self._cof.get(k)
        if cof is not None:
            n = apply_matrix(cof, n)
        with np.errstate(invalid="ignore", divide="ignore"):
            n /= np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
        return n

    # -- face, object, bary -----------------------------------------------------------

    def _make_face(self, raw, real_dtype, groups):
        return raw.face.astype(np.int32)

    def _make_object(self, raw, real_dtype, groups):
        return raw.instance.astype(np.int32)

    def _make_bary(self, raw, real_dtype, groups):
        return raw.bary.astype(real_dtype)

    # -- normal: the geometric face normal --------------------------------------------

    def _prepare_normal(self):
        for gi in self._used:
            if ("normal", gi) in self._tables:
                continue
            g = self.surface.geometries[gi]
            v, f = g.vertices, g.faces
            n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
            with np.errstate(invalid="ignore", divide="ignore"):
                n /= np.linalg.norm(n, axis=1, keepdims=True)
            self._tables["normal", gi] = n

    def _normals(self, raw, groups):
        """(n, 3) float64 unit normals: smooth when smooth-normal is asked for, else the face's."""
        if "smooth-normal" in self.names:
            return self._smooth_normals(raw, groups)
        return self._face_normals(raw, groups)

    def _face_normals(self, raw, groups):
        def compute(k, face, bary):
            n = self._tables["normal", self._geometry_of(k)][face]
            return self._to_world(k, n) if k in self._cof else n

        return self._per_group(raw, groups, compute, 3)

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
            self._tables["vn", gi] = vertex_normal_table(self.surface.geometries[gi].mesh)

    def _smooth_normals(self, raw, groups):
        def compute(k, face, bary):
            gi = self._geometry_of(k)
            n = interpolate(self._tables["vn", gi], self.surface.geometries[gi].faces, face, bary)
            n = self._to_world(k, n)
            bad = ~np.isfinite(n[:, 0]) | (np.abs(n).max(axis=1) < 0.5)  # unit vectors have a component >= 1/sqrt(3)
            if bad.any():
                n[bad] = self._to_world(k, self._tables["normal", gi][face[bad]].copy())
            return n

        return self._per_group(raw, groups, compute, 3)

    # -- uv -----------------------------------------------------------------------------

    def _prepare_uv(self):
        for gi in self._used:
            uv = uv_table(self.surface.geometries[gi].mesh)
            if uv is None:
                self._missing("uv", "texture coordinates", gi)
            self._tables["uv", gi] = uv

    def _make_uv(self, raw, real_dtype, groups):
        def compute(k, face, bary):
            gi = self._geometry_of(k)
            return interpolate(self._tables["uv", gi], self.surface.geometries[gi].faces, face, bary)

        return self._per_group(raw, groups, compute, 2).astype(real_dtype)

    # -- color --------------------------------------------------------------------------

    def _prepare_color(self):
        textures = self.surface._cache.setdefault("textures", {})
        for gi in self._used:
            g = self.surface.geometries[gi]
            src = color_source(g.mesh, g.faces, self.surface.source, textures)
            if src is None:
                self._missing("color", "vertex colours, face colours, texture or material colour", gi)
            src.prepare()
            self._tables["color", gi] = src

    def _make_color(self, raw, real_dtype, groups):
        def compute(k, face, bary):
            return self._tables["color", self._geometry_of(k)].colors(face, bary)

        c = self._per_group(raw, groups, compute, 4)
        return np.rint(np.clip(c, 0.0, 255.0)).astype(np.uint8)
