"""Per-point attributes, computed only when asked for.

An :class:`AttributeMaker` is built once per run from the surface and the requested
names; it prepares only the per-face or per-vertex tables those names need, then turns
each :class:`~scatter_cli.sampling.RawChunk` into the attribute arrays.
"""

from __future__ import annotations

import numpy as np

from .errors import ScatterError
from .samples import ATTRIBUTES
from .surface import Surface, cofactor


class AttributeMaker:
    def __init__(self, surface: Surface, names):
        self.surface = surface
        self.names = tuple(names)
        self.needs_bary = any(n in ("bary", "smooth-normal", "uv", "color") for n in self.names)
        self._face_normals = {}
        for name in self.names:
            getattr(self, "_prepare_" + name.replace("-", "_"), lambda: None)()

    def make(self, raw, real_dtype):
        """dict key -> array for the requested names, from one raw chunk."""
        out = {}
        for name in self.names:
            key = ATTRIBUTES[name][0]
            out[key] = getattr(self, "_make_" + name.replace("-", "_"))(raw, real_dtype)
        return out

    def _make_face(self, raw, real_dtype):
        return raw.face.astype(np.int32)

    def _make_object(self, raw, real_dtype):
        return raw.instance.astype(np.int32)

    def _make_bary(self, raw, real_dtype):
        return raw.bary.astype(real_dtype)

    def _prepare_normal(self):
        for k, inst in enumerate(self.surface.instances):
            g = self.surface.geometries[inst.geometry]
            v = g.vertices
            n = np.cross(v[g.faces[:, 1]] - v[g.faces[:, 0]], v[g.faces[:, 2]] - v[g.faces[:, 0]])
            if inst.matrix is not None:
                n = n @ cofactor(inst.matrix[:3, :3]).T
            with np.errstate(invalid="ignore", divide="ignore"):
                n /= np.linalg.norm(n, axis=1, keepdims=True)
            self._face_normals[k] = n

    def _make_normal(self, raw, real_dtype):
        return self._per_instance(raw, self._face_normals, lambda table, face: table[face]).astype(real_dtype)

    def _per_instance(self, raw, tables, gather):
        if len(tables) == 1:
            return gather(tables[0], raw.face)
        out = None
        for k, table in tables.items():
            rows = np.flatnonzero(raw.instance == k)
            if rows.size:
                part = gather(table, raw.face[rows])
                if out is None:
                    out = np.empty((len(raw.face),) + part.shape[1:], dtype=part.dtype)
                out[rows] = part
        return out

    def _unsupported(self, name):
        raise ScatterError(f"{self.surface.source}: attribute '{name}' is not supported yet")

    def _prepare_smooth_normal(self):
        self._unsupported("smooth-normal")

    def _prepare_uv(self):
        self._unsupported("uv")

    def _prepare_color(self):
        self._unsupported("color")
