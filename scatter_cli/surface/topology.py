"""Whether a surface is closed: every edge shared by exactly two faces, consistently
oriented (the two faces run along it in opposite directions).

Vertices are welded by exact position first (an STL repeats each corner per face); a
face with a repeated corner (no area) has only the edges between distinct corners, so
the faces it folds back on count as its neighbours there, as in Thingi10K's statistics. Each geometry is judged on its
own; a scene is closed when every geometry it places is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Edges:
    """Edge counts of one geometry, and which faces touch the boundary.

    boundary: edges of one face; non_manifold: edges of three or more; inconsistent:
    edges of two faces that run along it the same way; at_boundary: (F,) bool, the faces
    with a boundary edge.
    """

    boundary: int
    non_manifold: int
    inconsistent: int
    at_boundary: np.ndarray

    @property
    def closed(self) -> bool:
        return self.boundary == 0 and self.non_manifold == 0 and self.inconsistent == 0


def welded(vertices, faces):
    """faces (F, 3) int64 -> (F, 3) int64 indices of the distinct positions of
    ``vertices`` (V, 3) float64 (-0.0 and 0.0 are one position)."""
    v = np.ascontiguousarray(vertices + 0.0)  # -0.0 + 0.0 is 0.0
    rows = v.view(np.dtype((np.void, v.dtype.itemsize * 3))).reshape(-1)
    _, index = np.unique(rows, return_inverse=True)
    return index.reshape(-1)[faces]


def edges(vertices, faces) -> Edges:
    """The :class:`Edges` of a triangle list: vertices (V, 3) float64, faces (F, 3) int64."""
    f = welded(vertices, faces) if len(faces) else np.zeros((0, 3), np.int64)
    a = f.reshape(-1)  # the corners, face by face
    b = f[:, [1, 2, 0]].reshape(-1)  # the next corner of each
    edge = np.flatnonzero(a != b)  # (a corner repeated makes no edge)
    a, b = a[edge], b[edge]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * (int(f.max(initial=0)) + 1) + hi
    _, which, count = np.unique(key, return_inverse=True, return_counts=True)
    which = which.reshape(-1)
    way = np.bincount(which, weights=np.where(a < b, 1.0, -1.0), minlength=len(count))  # +1 and -1 cancel
    at_boundary = np.zeros(len(faces), bool)
    at_boundary[edge[count[which] == 1] // 3] = True
    return Edges(int(np.sum(count == 1)), int(np.sum(count > 2)), int(np.sum((count == 2) & (way != 0))),
                 at_boundary)
