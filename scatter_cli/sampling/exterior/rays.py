"""Visibility from outside: rays from surface points, against the surface, in Embree.

A point is exterior when one of its rays leaves the surface's bounding sphere without
hitting a face. Each point tries, in turn and until one gets out: its face's normal,
the opposite direction, then the K directions of a fixed spherical design (a Fibonacci
lattice) turned by a uniformly random rotation of its own. A ray starts a few float32
roundings off the face, on the side it goes to, so that it does not hit its own face.
Embree works in float32: the scene is centred on its bounding box first.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...core.elementary import sincos
from ..normals import face_normals
from ..plan import column_bounds


# Design directions after the two normal rays (docs/exterior.md: false drops against K).
DESIGN_SIZE = 64
# Ray origins sit this many float32 roundings (at the scene's radius) off the face.
OFFSET_ROUNDINGS = 16


def fibonacci_sphere(k: int) -> np.ndarray:
    """(k, 3) float64 unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    i = np.arange(k, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / k
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    s, c = sincos(i * (math.pi * (3.0 - math.sqrt(5.0))))
    return np.stack([r * c, r * s, z], axis=1)


def random_rotations(u) -> np.ndarray:
    """(n, 4) unit quaternions (x, y, z, w), uniform over rotations, from ``u`` (n, 3) in [0, 1)."""
    a, b = np.sqrt(1.0 - u[:, 0]), np.sqrt(u[:, 0])
    s1, c1 = sincos(2 * math.pi * u[:, 1])
    s2, c2 = sincos(2 * math.pi * u[:, 2])
    return np.stack([a * s1, a * c1, b * s2, b * c2], axis=1)


def rotate(q, v) -> np.ndarray:
    """(n, 3): the unit vector ``v`` (3,) turned by each quaternion ``q`` (n, 4)."""
    xyz, w = q[:, :3], q[:, 3:]
    t = 2.0 * np.cross(xyz, v)
    return v + w * t + np.cross(xyz, t)


def finite_bounds(v):
    """(lo (3,), hi (3,), finite): the bounds of the finite rows of ``v`` (n, 3) (inf and
    -inf when there are none) and their (n,) bool mask, or None when every row is finite."""
    if len(v):
        lo, hi = column_bounds(v)
        if np.isfinite(lo).all() and np.isfinite(hi).all():
            return lo, hi, None
    finite = np.isfinite(v).all(axis=1)
    ok = v[finite]
    if not len(ok):
        return np.full(3, np.inf), np.full(3, -np.inf), finite
    return ok.min(axis=0), ok.max(axis=0), finite


class Occluder:
    """Every finite face of a surface, in world space, in one Embree scene.

    ``normals`` (F, 3) float64 unit world-space normals, row ``offsets[instance] + face``.
    """

    def __init__(self, surface, design_size: int | None = None, normal_rays: bool = True,
                 offset_roundings: float | None = None):
        from .rayscene import RayScene

        self.design = fibonacci_sphere(DESIGN_SIZE if design_size is None else design_size)
        self.normal_rays = normal_rays
        world = [surface.world_vertices(inst) for inst in surface.instances]
        faces = [surface.geometries[inst.geometry].faces for inst in surface.instances]
        boxes = [finite_bounds(v) for v in world]
        lo = np.min([b[0] for b in boxes], axis=0) if boxes else np.full(3, np.inf)
        hi = np.max([b[1] for b in boxes], axis=0) if boxes else np.full(3, -np.inf)
        self.center = (lo + hi) / 2 if np.isfinite(lo).all() else np.zeros(3)
        self.scene = RayScene()
        self.offsets = np.cumsum([0] + [len(f) for f in faces])
        self.normals = np.zeros((int(self.offsets[-1]), 3))
        radius = 0.0
        for k, (v, f, (vlo, vhi, finite)) in enumerate(zip(world, faces, boxes)):
            self.normals[self.offsets[k]:self.offsets[k + 1]] = face_normals(v, f, self.center)
            if finite is None:  # every vertex finite: the box's corners bound |v - center| (rounding is monotonic)
                if len(f):
                    radius = max(radius, float(np.abs([vlo - self.center, vhi - self.center]).max()))
                    self.scene.add(v, f, self.center)
                continue
            good = finite[f].all(axis=1)
            if good.any():
                radius = max(radius, float(np.abs(v[finite] - self.center).max()))
                self.scene.add(np.where(finite[:, None], v, self.center), f[good], self.center)  # (others at 0)
        self.radius = radius
        self._world = [(v, f, inst.geometry, surface.geometries[inst.geometry].vertices)
                       for v, f, inst in zip(world, faces, surface.instances)]
        self.enclosed = None
        t = time.perf_counter()
        self.scene.commit()
        self.build_seconds = time.perf_counter() - t
        # float32 spacing at the largest coordinate, times the roundings
        roundings = OFFSET_ROUNDINGS if offset_roundings is None else offset_roundings
        self.offset = float(np.spacing(np.float32(radius or 1.0))) * roundings

    def enclose(self):
        """Find the faces certainly hidden (:mod:`.enclosure`): their candidates then cast
        no ray (the verdict the rays would give). Returns how many."""
        from .enclosure import closed_parts, enclosed_faces

        if self.enclosed is None:
            parts, vertices, faces, part, closed = {}, [], [], [], []
            for v, f, geometry, own in self._world:
                if geometry not in parts:  # welded in the geometry's own frame
                    parts[geometry] = closed_parts(own, f)
                p, c = parts[geometry]
                part.append(p + sum(len(x) for x in closed) if closed else p)
                closed.append(c)
                faces.append(f + sum(len(x) for x in vertices) if vertices else f)
                vertices.append(v)
            self.enclosed = enclosed_faces(*(x[0] if len(x) == 1 else np.concatenate(x)
                                             for x in (vertices, faces, part, closed)), self.offset)
        return int(np.count_nonzero(self.enclosed))

    def rows(self, face, instance):
        """(n,) int64: the rows of faces ``face`` (n,) of instances ``instance`` (n,)."""
        return self.offsets[instance] + face

    def face_normals(self, face, instance):
        """(n, 3) unit normals of faces ``face`` (n,) of instances ``instance`` (n,)."""
        return np.take(self.normals, self.rows(face, instance), axis=0)

    def exterior(self, points, normals, u, enclosed=None, normal_blocked=False):
        """Whether each point (n, 3) on a face of unit normal ``normals`` (n, 3) sees out:
        ((n,) bool, rays cast). ``u`` (n, 3) uniforms in [0, 1) (or a function that
        draws them, called only when a point needs the design) choose each point's
        rotation of the design; points where ``enclosed`` (n,) bool is set are hidden
        without a ray. ``normal_blocked``: every point's normal ray has been cast (by
        :meth:`normal_escapes`) and is blocked: the rays go on from the opposite normal."""
        out = np.zeros(len(points), dtype=bool)
        todo = np.arange(len(points)) if enclosed is None else np.flatnonzero(~enclosed)
        rays = 0
        origin = points - self.center
        if self.normal_rays:
            todo, rays = self._normal_rays(origin, normals, todo, out, signs=(-1.0,) if normal_blocked else (1.0, -1.0))
        if not len(todo) or not len(self.design):
            return out, rays
        u = u() if callable(u) else u
        spin = np.empty((len(points), 4))
        spin[todo] = random_rotations(u[todo])  # (elementwise: the rows of the whole block's rotations)
        for d in self.design:
            if not len(todo):
                break
            rays += len(todo)
            todo = self._cast(origin, normals, rotate(spin[todo], d), todo, out)
        return out, rays

    def normals_blocked(self, points, normals):
        """((n,) bool: both normal rays of each point (n, 3) on a face of unit normal
        ``normals`` (n, 3) are blocked, rays cast)."""
        out = np.zeros(len(points), dtype=bool)
        _, rays = self._normal_rays(points - self.center, normals, np.arange(len(points)), out)
        return ~out, rays

    def normal_escapes(self, points, normals):
        """(m,) bool: the normal ray of each point (m, 3) on a face of unit normal
        ``normals`` (m, 3) gets out (the origin and direction :meth:`_cast` gives it: the
        normal's side of the face, as n . n is never negative)."""
        start = points - self.center
        start += self.offset * normals
        return ~self.scene.occluded(start, normals)

    def _normal_rays(self, origin, normals, todo, out, signs=(1.0, -1.0)):
        """Cast the normal, then the opposite direction (``signs``), from points
        ``todo``; mark those that get out in ``out``: (the others, rays cast)."""
        rays = 0
        for sign in signs:
            rays += len(todo)
            todo = self._cast(origin, normals, sign * normals[todo], todo, out)
        return todo, rays

    def _cast(self, origin, normals, d, todo, out):
        """Cast rays ``d`` (m, 3) from points ``todo`` (m,); mark those that get out in
        ``out``, return the others."""
        if not len(todo):
            return todo
        n = np.take(normals, todo, axis=0)
        side = np.where(np.einsum("ij,ij->i", d, n) < 0, -self.offset, self.offset)
        start = np.take(origin, todo, axis=0) + side[:, None] * n
        free = ~self.scene.occluded(start, d)
        out[todo[free]] = True
        return todo[~free]
