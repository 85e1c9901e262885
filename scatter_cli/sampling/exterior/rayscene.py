"""Triangles in one Embree scene, for occlusion rays (the optional extra ``exterior``).

Two ways to the same scene and the same verdicts: the compiled ``_cembree`` calls the
Embree library that the embreex wheel ships, sharing the caller's arrays; without it
(or with SCATTER_NUMPY=1), embreex's own API, which copies them element by element.
"""

from __future__ import annotations

import glob
import importlib.util
import os

import numpy as np

from ...core import native
from ...errors import ScatterError

INSTALL_HINT = "--exterior needs Embree: pip install embreex"
# Where the embreex wheels keep their Embree library: Linux (auditwheel), macOS (delocate).
# (_cembree opens it with dlopen: elsewhere the embreex path runs.)
LIBRARY_GLOBS = ("../embreex.libs/libembree4*.so*", ".dylibs/libembree4*.dylib")


def embree_library() -> str | None:
    """The path of the Embree 4 library in the installed embreex, or None."""
    spec = importlib.util.find_spec("embreex")
    if spec is None or not spec.submodule_search_locations:
        return None
    root = list(spec.submodule_search_locations)[0]
    for pattern in LIBRARY_GLOBS:
        found = sorted(glob.glob(os.path.join(root, pattern)))
        if found:
            return found[0]
    return None


_kernel = native.kernel("_cembree")


def _compiled():
    """``_cembree`` with the library loaded, or None (not built, turned off, not found)."""
    module = _kernel
    path = embree_library() if module is not None else None
    if path is None:
        return None
    try:
        module.load(path)
    except OSError:
        return None
    return module


class RayScene:
    """Triangle meshes in float32 in one robust Embree scene; occlusion queries once built."""

    def __init__(self):
        self._c = _compiled()
        self._keep = []  # the arrays the compiled scene shares
        if self._c is not None:
            self._scene = self._c.new_scene()
            return
        try:
            from embreex import rtcore_scene
        except ImportError:
            raise ScatterError(INSTALL_HINT) from None
        self._scene = rtcore_scene.EmbreeScene(robust=True)  # watertight: no ray slips between two faces

    def add(self, vertices, faces, center):
        """Add the triangles ``faces`` (m, 3) int of ``vertices`` (n, 3) float64 less
        ``center`` (3,) float64, cast to float32."""
        if self._c is not None:
            v, f = self._c.buffers(np.ascontiguousarray(vertices, np.float64), np.asarray(center, np.float64),
                                   np.ascontiguousarray(faces, np.int64))
            self._keep += [v, f]
            self._c.add(self._scene, v, f)
        else:
            from embreex.mesh_construction import TriangleMesh

            local = (vertices - center).astype(np.float32)
            TriangleMesh(self._scene, local, np.asarray(faces, np.int32))

    def commit(self):
        """Build the tree (Embree's threads)."""
        if self._c is not None:
            self._c.commit(self._scene)
        else:  # embreex builds at its first query
            self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED")

    def occluded(self, origins, directions) -> np.ndarray:
        """(m,) bool: the ray from each of ``origins`` (m, 3) float32 along ``directions``
        (m, 3) float32 hits a triangle."""
        origins = np.ascontiguousarray(origins, dtype=np.float32)
        directions = np.ascontiguousarray(directions, dtype=np.float32)
        if self._c is not None:
            out = np.empty(len(origins), bool)
            self._c.occluded(self._scene, origins, directions, out)
            return out
        return self._scene.run(origins, directions, query="OCCLUDED") != -1
