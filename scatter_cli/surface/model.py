"""The surface model: float64 arrays, no I/O (loaders.py fills it from files).

A :class:`Surface` is a list of geometries (local vertices and triangles) and a list
of instances, each placing one geometry in world space with a 4x4 matrix. An
instanced geometry is stored once, whatever the number of nodes that place it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .areas import cross_columns, norms
from ..errors import ScatterError


@dataclass
class Geometry:
    """One triangle list in its own frame.

    vertices: (V, 3) float64; faces: (F, 3) int64, in the order trimesh loads them.
    ``mesh`` is the trimesh object it came from, kept for attributes (UVs, colours).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    mesh: object = None

    def __post_init__(self):
        # C order and these types, as the compiled kernels read them (no copy if already so)
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int64)


@dataclass
class Instance:
    """A geometry placed in world space; ``matrix`` is (4, 4) float64, None for identity."""

    name: str
    geometry: int
    matrix: np.ndarray | None = None


@dataclass
class Unsampled:
    """Something the file held that is not sampled: ``path`` (its name in the file),
    ``reason`` (e.g. "invisible", "guide purpose", "a Cube prim, not a mesh") and its
    world-space ``area`` where it has one (0.0 where it has none or it is not known)."""

    path: str
    reason: str
    area: float = 0.0


@dataclass
class Surface:
    geometries: list[Geometry]
    instances: list[Instance]
    source: str = "<mesh>"
    is_scene: bool = False
    _cache: dict = field(default_factory=dict, repr=False)  # decoded textures, shared by attributes
    # The scene's up axis ("Y" or "Z") and metres per unit, where the format says them
    # (USD stages; glTF by its specification); None where it does not.
    up_axis: str | None = None
    meters_per_unit: float | None = None
    # (n_instances,) int64: the index `scatter info` lists each instance under in the
    # whole file (what `-a object` writes); None: its position in ``instances``.
    object_index: np.ndarray | None = None
    # What the loader has to say about the file (one line each, naming it), for the run to print.
    warnings: list[str] = field(default_factory=list)
    # What the file held that is not sampled, and why.
    unsampled: list[Unsampled] = field(default_factory=list)

    def keeping(self, instances) -> "Surface":
        """The same scene with only ``instances`` (a list of this surface's instances),
        each keeping its object index."""
        position = {id(inst): k for k, inst in enumerate(self.instances)}
        index = np.array([position[id(inst)] for inst in instances], dtype=np.int64)
        if self.object_index is not None:
            index = self.object_index[index]
        return Surface(self.geometries, instances, self.source, self.is_scene, up_axis=self.up_axis,
                       meters_per_unit=self.meters_per_unit, object_index=index, warnings=self.warnings,
                       unsampled=self.unsampled)

    @property
    def face_count(self) -> int:
        """Faces in world space, every instance counted."""
        return sum(len(self.geometries[i.geometry].faces) for i in self.instances)

    def world_vertices(self, instance: Instance) -> np.ndarray:
        """(V, 3) float64 vertices of one instance's geometry in world space."""
        v = self.geometries[instance.geometry].vertices
        if instance.matrix is None:
            return v
        m = instance.matrix
        return v @ m[:3, :3].T + m[:3, 3]


def select_objects(surface: Surface, names) -> Surface:
    """Keep the instances whose node or geometry name is in ``names`` (instance order kept)."""
    wanted = set(names)
    known = {i.name for i in surface.instances} | {g.name for g in surface.geometries}
    missing = sorted(wanted - known)
    if missing:  # a failure of this mesh (another may have them), not a usage error
        raise ScatterError(
            f"{surface.source}: no object named {', '.join(map(repr, missing))} "
            f"(objects: {', '.join(sorted(known)) or 'none'})"
        )
    kept = [i for i in surface.instances if i.name in wanted or surface.geometries[i.geometry].name in wanted]
    return surface.keeping(kept)


def corners(vertices, faces):
    """The three corners of each face: (F, 9) float64 rows ``[v0, v1, v2]``."""
    return np.take(vertices, faces, axis=0).reshape(len(faces), 9)


def doubled_areas(tri, matrix=None):
    """Twice the area of each face, in world space under ``matrix`` (4, 4).

    tri: (F, 9) float64 corners -> (F,) float64; non-finite faces give NaN.
    Under a linear map A, (A e1) x (A e2) = cof(A) (e1 x e2), so one 3x3 product per face
    gives world areas, for non-uniform scales too, without moving the vertices.
    """
    n = face_cross(tri)
    if matrix is not None:
        n = apply_matrix(cofactor(matrix[:3, :3]), n, out=n)
    return norms([n[:, 0], n[:, 1], n[:, 2]])


def column_bounds(v, rows=1 << 16):
    """(lo, hi): the (3,) minimum and maximum of each column of ``v`` (n, 3), n > 0.

    Column by column over blocks of ``rows`` that stay in cache: ``v.min(axis=0)`` runs
    its inner loop over the 3 columns, 10 times slower on a large (n, 3) array
    (docs/loading.md: binary STL)."""
    blocks = np.empty((2, -(-len(v) // rows), 3))
    for k, s in enumerate(range(0, len(v), rows)):
        b = v[s : s + rows]
        for c in range(3):
            blocks[0, k, c], blocks[1, k, c] = b[:, c].min(), b[:, c].max()
    return blocks[0].min(axis=0), blocks[1].max(axis=0)


def face_cross(tri):
    """(v1 - v0) x (v2 - v0) for each face: (F, 9) corners -> (F, 3) float64."""
    n = np.empty((tri.shape[0], 3))
    for c, col in enumerate(cross_columns(tri.T)):
        n[:, c] = col
    return n


def apply_matrix(m, v, out=None):
    """``v @ m[:3, :3].T (+ m[:3, 3])`` for rows v (n, 3), one element-wise column at a time.

    m: (3, 3) or (3, 4) float64. Unlike a BLAS product, the rounding of a row does not
    depend on how many rows come with it, so chunked output stays byte-identical.
    """
    out = np.empty(v.shape) if out is None else out
    x, y, z = (v[:, c].copy() for c in range(3))
    for c in range(3):
        col = m[c, 0] * x
        col += m[c, 1] * y
        col += m[c, 2] * z
        if m.shape[1] > 3:
            col += m[c, 3]
        out[:, c] = col
    return out


def cofactor(a):
    """Cofactor matrix of a (3, 3) matrix, defined for singular ones too.

    Row i is ``cross(a[i+1], a[i+2])``, worked out on Python floats: the same products
    and differences as np.cross (so the same bits) without its per-call cost, which a
    scene of many instances pays once per instance.
    """
    r0, r1, r2 = np.asarray(a, dtype=np.float64)[:3, :3].tolist()
    return np.array([_cross(r1, r2), _cross(r2, r0), _cross(r0, r1)])


def cofactors(a):
    """Cofactor matrices of a stack (k, 3, 3) (or (k, 4, 4), its upper-left blocks) ->
    (k, 3, 3) float64: :func:`cofactor` of each, the same products in the same order,
    so the same bits."""
    a = np.asarray(a, dtype=np.float64)
    r = [[a[:, i, j] for j in range(3)] for i in range(3)]
    out = np.empty((len(a), 3, 3))
    for i in range(3):
        x, y = r[(i + 1) % 3], r[(i + 2) % 3]
        out[:, i, 0] = x[1] * y[2] - x[2] * y[1]
        out[:, i, 1] = x[2] * y[0] - x[0] * y[2]
        out[:, i, 2] = x[0] * y[1] - x[1] * y[0]
    return out


def normal_transforms(matrices):
    """(K, 3, 3) float64 normal transform of each (4, 4) matrix or None (rows of None
    matrices are left zero): cof(A) = det(A) inv(A)^T, times sign(det A), which is
    |det| inv(A)^T, the transform that keeps normals outward under mirrors (glTF flips
    winding then)."""
    out = np.zeros((len(matrices), 3, 3))
    moved = [k for k, m in enumerate(matrices) if m is not None]
    if moved:
        a = np.stack([matrices[k][:3, :3] for k in moved])
        out[moved] = cofactors(a) * np.where(np.linalg.det(a) < 0, -1.0, 1.0)[:, None, None]
    return out


def transformed_columns(m, v):
    """The columns of ``v @ m[k, :3, :3].T (+ m[k, :3, 3])`` for every matrix of a stack:
    m (k, 3, 3) or (k, 3|4, 4), v (n, 3) -> [x, y, z], each (k, n) float64, with the
    element-wise operations of :func:`apply_matrix` in its order (the same bits)."""
    cols = [np.ascontiguousarray(v[:, c]) for c in range(3)]
    out = []
    for c in range(3):
        col = m[:, c, 0, None] * cols[0]
        col += m[:, c, 1, None] * cols[1]
        col += m[:, c, 2, None] * cols[2]
        if m.shape[2] > 3:
            col += m[:, c, 3, None]
        out.append(col)
    return out


def _cross(x, y):
    return [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]
