"""Unit face normals, computed one way everywhere: the compiled kernel and its NumPy twin
give the values ``np.cross`` and ``np.linalg.norm`` give, bit for bit."""

from __future__ import annotations

import numpy as np

from ..core import native
from ..core.native import in_blocks

_kernel = native.kernel("_csampling")


def face_normals(vertices, faces, center=None) -> np.ndarray:
    """(m, 3) float64 unit normals of ``faces`` (m, 3) int64 of ``vertices`` (n, 3) float64
    less ``center`` (3,) (default: none), zero where undefined (a face of zero area, a
    non-finite corner); on the worker threads."""
    center = np.zeros(3) if center is None else np.asarray(center, dtype=np.float64)
    if _kernel is not None:
        out = np.empty((len(faces), 3))
        vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        faces = np.ascontiguousarray(faces, dtype=np.int64)
        in_blocks(lambda i, j: _kernel.unit_normals(vertices, faces[i:j], out[i:j], center), len(faces))
        return out
    return _numpy_face_normals(vertices - center, faces)


def _numpy_face_normals(vertices, faces):
    """face_normals in NumPy, on contiguous coordinate rows (np.cross on (m, 3) rows is slower)."""
    columns = np.ascontiguousarray(vertices.T)
    a, b, c = (columns[:, faces[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    n = np.stack([e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]])
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    return np.where(np.isfinite(n), n, 0.0).T
