"""Volume samples: points in and around a surface, labelled for implicit-shape learning.

A volume run draws each point from one of its parts, chosen at random with the shares
asked for: uniform in the sampling box (the sampled surface's bounding box grown by
``padding`` times its largest side), or near the surface (a uniform surface point of
the run's surface source plus an isotropic Gaussian offset of standard deviation sigma).
Point ``i`` is a pure function of the seed and ``i``: its part, box coordinates and
Gaussian offset come from draws ``8 i .. 8 i + 7`` of a stream of its own, and its
surface point is point ``i`` of the surface source. So any prefix of the output is a
fair subsample and a run of K points is the first K points of a longer run.

:class:`VolumeLabels` then labels each chunk against the sampled surface (world-space
triangles in float64): the exact closest point and distance (:mod:`scatter_cli.volume.distance`),
and inside or outside by the generalized winding number (:mod:`scatter_cli.volume.winding`) or
by a majority of ray parities (:mod:`scatter_cli.volume.parity`). Only what the asked-for attributes need is computed.
"""

from __future__ import annotations

import math
import numpy as np

from ..core.elementary import cos, log, sincos
from ..errors import ScatterError
from ..sampling.plan import RawChunk, SamplePlan, apply_matrix
from .signs import SignTally

VOLUME_DRAWS = 8  # part, 3 box coordinates, 4 uniforms for 3 Gaussians (Box-Muller)
STREAM_KEY = 0x766F6C756D65  # "volume": keys the volume stream apart from the surface one
LABELS = ("sdf", "inside", "winding", "closest", "face", "object", "sharp")
PARITY_RAYS = 5  # rays a point for --sign parity: the majority outvotes two grazing rays


def sampling_box(triangles, padding: float):
    """(2, 3) float64: the bounding box of the triangles (T, 3, 3) grown on every side by
    ``padding`` times its largest side."""
    corners = triangles.reshape(-1, 3)
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    grow = padding * float((hi - lo).max())
    return np.stack([lo - grow, hi + grow])


def world_triangles(plan: SamplePlan):
    """The faces that get points, in world space: (triangles (T, 3, 3) float64,
    instance (T,) int64, face (T,) int64 the face's index in its geometry)."""
    tris, owners, faces = [], [], []
    for part in plan.parts:
        if not part.count:
            continue
        g = part.geometry
        index = np.arange(len(g.faces), dtype=np.int64) if part.faces is None else part.faces
        corners = g.vertices[g.faces[index]].reshape(-1, 3)
        if part.matrix is not None:
            corners = apply_matrix(part.matrix[:3], corners)
        tris.append(corners.reshape(-1, 3, 3))
        owners.append(np.full(len(index), part.instance, dtype=np.int64))
        faces.append(index)
    return np.concatenate(tris), np.concatenate(owners), np.concatenate(faces)


def volume_uniforms(seed: int, start: int, stop: int):
    """Draws of points ``start .. stop - 1`` of the volume stream: (n, 8) float64 in [0, 1)."""
    bits = np.random.PCG64DXSM([STREAM_KEY, int(seed)])
    bits.advance(VOLUME_DRAWS * int(start))
    return np.random.Generator(bits).random((stop - start, VOLUME_DRAWS))


def gaussians(u):
    """Three independent N(0, 1) values per row from four uniforms ``u`` (n, 4) in [0, 1)
    (Box-Muller; 1 - u, exact, keeps the logarithm finite): (n, 3) float64."""
    r1 = np.sqrt(-2.0 * log(1.0 - u[:, 0]))
    r2 = np.sqrt(-2.0 * log(1.0 - u[:, 2]))
    s1, c1 = sincos(2.0 * math.pi * u[:, 1])
    return np.stack([r1 * c1, r1 * s1, r2 * cos(2.0 * math.pi * u[:, 3])], axis=1)


def parts_of(u, box_share: float, sigmas: int):
    """Each point's part from its draw ``u`` (n,): -1 for the box, else the index of its
    sigma; the box takes ``box_share`` of the points, the sigmas share the rest equally."""
    part = np.full(len(u), -1, dtype=np.int64)
    near = u >= box_share
    if sigmas and box_share < 1:
        k = ((u[near] - box_share) / (1.0 - box_share) * sigmas).astype(np.int64)
        part[near] = np.minimum(k, sigmas - 1)
    return part


class VolumeSource:
    """Points in the sampling box and near the surface (see the module docstring).

    surface: the run's surface source (its point ``i`` is the surface point of a near
    point ``i``); box (2, 3) and sigmas in world units; edge_sigmas: the sigmas of the near
    points whose surface point is on a sharp edge (``--near-edges``; default: ``sigmas``),
    shared as ``sigmas`` are."""

    def __init__(self, surface, count: int, seed: int, box, sigmas=(), box_share: float = 1.0, edge_sigmas=None):
        self.surface, self.count, self.seed = surface, int(count), seed
        self.area = surface.area
        self.box = np.asarray(box, dtype=np.float64)
        self.sigmas = np.asarray(sigmas, dtype=np.float64)
        self.edge_sigmas = None if edge_sigmas is None else np.asarray(edge_sigmas, dtype=np.float64)
        self.box_share = float(box_share) if len(self.sigmas) else 1.0
        self.kept = None  # not a thinned source
        self.stats = None

    def draw(self, start: int, stop: int) -> RawChunk:
        u = volume_uniforms(self.seed, start, stop)
        part = parts_of(u[:, 0], self.box_share, len(self.sigmas))
        lo, hi = self.box
        points = lo + u[:, 1:4] * (hi - lo)
        near = np.flatnonzero(part >= 0)
        n = stop - start
        sharp = None
        if len(near):
            surface = self.surface.draw(start, stop)
            sigma = self.sigmas[part[near]]
            if surface.sharp is not None:  # --edges: the near points of edge points are sharp
                sharp = np.zeros(n, dtype=bool)
                sharp[near] = surface.sharp[near]
                if self.edge_sigmas is not None:
                    on_edge = np.flatnonzero(sharp[near])
                    sigma[on_edge] = self.edge_sigmas[parts_of(u[near[on_edge], 0], self.box_share,
                                                               len(self.edge_sigmas))]
            points[near] = surface.points[near] + gaussians(u[near, 4:8]) * sigma[:, None]
        return RawChunk(start, points, np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64), None, sharp)


def label_trees(triangles, distance: bool, winding: bool):
    """(the distance tree, the winding tree) of ``triangles`` (T, 3, 3) float64, each
    None when not wanted. Both wanted and more than one worker thread: they are built at
    the same time, one on another thread (the same trees either way; most of a build
    is NumPy and kernel work that runs without the GIL)."""
    from ..core.native import thread_pool, worker_count

    def distance_tree():
        from .distance import TriangleTree

        tree = TriangleTree.from_triangles(triangles)
        tree.wide()  # the kernel's form, else made at the first query
        return tree

    def winding_tree():
        from .winding import WindingTree

        return WindingTree(triangles)

    if not (distance and winding and worker_count() > 1):
        return distance_tree() if distance else None, winding_tree() if winding else None
    with thread_pool(1, one_level=False) as pool:  # (its kernels keep their threads)
        later = pool.submit(winding_tree)
        return distance_tree(), later.result()


def distances_and_windings(distance_tree, winding_tree, points):
    """(closest_points's (distance, closest point, face) or None, the winding numbers (n,)
    float64 or None) of ``points`` (n, 3) float64, each None when its tree is. Both wanted
    and more than one worker thread: at the same time, the winding numbers on another
    thread, so that one's serial steps (visit orders, gathers) run while the other's
    kernel threads do (the same values either way)."""
    from ..core.native import thread_pool, worker_count
    from .distance import closest_points
    from .winding import winding_numbers

    if distance_tree is None or winding_tree is None or worker_count() <= 1:
        return (None if distance_tree is None else closest_points(distance_tree, points),
                None if winding_tree is None else winding_numbers(winding_tree, points))
    with thread_pool(1, one_level=False) as pool:  # (its kernels keep their threads)
        later = pool.submit(winding_numbers, winding_tree, points)
        return closest_points(distance_tree, points), later.result()


class VolumeLabels:
    """Turns chunks of volume points into the asked-for label arrays (``make``)."""

    needs_bary = False

    def __init__(self, triangles, instance, face, names, sign="winding", frame=None):
        self.triangles, self.instance, self.face = triangles, instance, face
        self.names = tuple(names)
        self.sign = sign
        self.frame = frame  # (offset (3,), scale) of the output's frame, or None
        wanted = set(self.names)
        self.needs_distance = bool(wanted & {"sdf", "closest", "face", "object"})
        self.needs_winding = "winding" in wanted or ("inside" in wanted or "sdf" in wanted) and sign == "winding"
        self.needs_parity = sign == "parity" and bool(wanted & {"inside", "sdf"})
        # how many signs rest on a winding number near 1/2 (the run warns when many do)
        self.tally = SignTally() if sign == "winding" and wanted & {"inside", "sdf"} else None
        self._distance_tree, self._winding_tree = label_trees(triangles, self.needs_distance or self.needs_parity,
                                                              self.needs_winding)

    def stored_points(self, points, real_dtype):
        """The world points (n, 3) float64 that the labels of ``points`` (n, 3), world
        points, belong to: the points as written. In float32, those the run writes,
        ``((points - offset) * scale).astype(float32)``, mapped back to world space."""
        if np.dtype(real_dtype) != np.float32:
            return points
        if self.frame is None:
            return points.astype(np.float32).astype(np.float64)
        offset, scale = self.frame
        return ((points - offset) * scale).astype(np.float32).astype(np.float64) / scale + offset

    @property
    def split_chunks(self):
        """Whether chunks may be cut into pieces on the threads: not when the label
        kernels split each chunk among them themselves (sampling.plan.run_chunks)."""
        return not (self.needs_distance or self.needs_winding or self.needs_parity)

    def make(self, raw: RawChunk, real_dtype) -> dict:
        """dict key -> array for the asked-for names; ``raw.points`` are world points,
        labelled as written (:meth:`stored_points`)."""
        p = self.stored_points(raw.points, real_dtype)
        out = {}
        distance = closest = face = inside = None
        found, winding = distances_and_windings(self._distance_tree if self.needs_distance else None,
                                                self._winding_tree, p)
        if found is not None:
            distance, closest, face = found
        if winding is not None and self.tally is not None:
            self.tally.add(winding)
        if self.needs_parity:
            from .parity import parity_inside

            inside = parity_inside(self._distance_tree, p, rays=PARITY_RAYS)
        elif winding is not None:
            inside = winding >= 0.5
        scale = 1.0 if self.frame is None else self.frame[1]
        for name in self.names:
            if name == "sdf":
                sdf = np.where(inside, -distance, distance)
                out["sdf"] = sdf if self.frame is None else sdf * scale
            elif name == "inside":
                out["inside"] = inside.astype(np.uint8)
            elif name == "winding":
                out["winding"] = winding
            elif name == "closest":
                moved = closest if self.frame is None else (closest - self.frame[0]) * scale
                out["closest"] = moved.astype(real_dtype, copy=False)
            elif name == "face":
                out["face"] = self.face[face].astype(np.int32)
            elif name == "object":
                out["object"] = self.instance[face].astype(np.int32)
            elif name == "sharp":
                out["sharp"] = np.zeros(len(p), np.uint8) if raw.sharp is None else raw.sharp.astype(np.uint8)
            else:
                raise ScatterError(f"attribute '{name}' is not a volume attribute")
        return out
