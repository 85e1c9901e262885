"""Points on sharp edges (``--edges F``), interleaved with the face points of a run.

Point ``i`` of a run is an edge point exactly when ``floor((i + 1) F) > floor(i F)``,
computed in integers with ``F`` the exact decimal given (0.29 is 29/100): the first ``K``
points of the run hold ``floor(K F)`` edge points. Edge point ``j`` (the ``j``-th edge
point of the run) comes from draws ``2 j`` and ``2 j + 1`` of a stream of its own: the
edge, chosen with probability proportional to its world-space length, then the point,
uniform along it. Face point ``j`` is point ``j`` of the run's face source. So each part
is a fair sample of its own, any prefix of the run is a fair mix of both, and a chunk
``start .. stop - 1`` costs only its share of each.
"""

from __future__ import annotations

import fractions
from dataclasses import dataclass

import numpy as np

from ..surface.model import apply_matrix, normal_transforms
from .normals import face_normals
from .plan import RawChunk, _guide_table, select
from .sharp import SHARP_ANGLE, SharpEdges, is_similarity, sharp_edges

EDGE_DRAWS = 2  # the edge, then the point along it
STREAM_KEY = 0x65646765  # "edge": keys the edge stream apart from the others


@dataclass(frozen=True)
class Interleaving:
    """Which points of a run are edge points, for a share ``fraction`` in [0, 1]."""

    fraction: fractions.Fraction

    def before(self, i: int) -> int:
        """Edge points among points ``0 .. i - 1``: floor(i F)."""
        return i * self.fraction.numerator // self.fraction.denominator

    def mask(self, start: int, stop: int):
        """(stop - start,) bool: which of points ``start .. stop - 1`` are edge points."""
        p, q = self.fraction.numerator, self.fraction.denominator
        n = stop - start
        rest = start * p % q  # floor((start + j) F) - floor(start F) = floor((rest + j p) / q)
        if rest + n * p < 2**62:  # exact in int64
            counts = (rest + np.arange(n + 1, dtype=np.int64) * p) // q
        else:  # a long decimal: Python integers
            counts = np.array([(rest + j * p) // q for j in range(n + 1)], dtype=object)
        return np.diff(counts).astype(bool)


class EdgeTable:
    """The sharp edges of a surface in world space, to draw points on.

    Per instance, in instance order, the sharp edges of its geometry
    (:mod:`scatter_cli.sampling.sharp`) in slot order: found once per geometry in its own
    frame for instances that keep angles (rotations, mirrors, uniform scales), and in
    world space for any other instance. a, b: (E, 3) float64 world positions each edge runs
    from and to; face, instance: (E,) int64; corner: (E,) int64 the corner of ``face``
    at ``a`` (``b`` is the next corner); normal: (E, 3) float64 world-space unit normals;
    length: (E,) float64.
    """

    def __init__(self, surface, angle: float = SHARP_ANGLE):
        self.surface, self.angle = surface, float(angle)
        found = {}  # geometry -> (local unit normals, local SharpEdges)
        parts = []
        transforms = normal_transforms([inst.matrix for inst in surface.instances])
        for k, inst in enumerate(surface.instances):
            g = surface.geometries[inst.geometry]
            if inst.geometry not in found:
                normals = face_normals(g.vertices, g.faces)
                found[inst.geometry] = normals, sharp_edges(g.vertices, g.faces, normals, self.angle)
            normals, edges = found[inst.geometry]
            if inst.matrix is None:
                world_normals = edges.normal
            elif is_similarity(inst.matrix):  # angles kept: the geometry's edges, turned
                world_normals = _unit(edges.normal @ transforms[k].T)
            else:  # the angles of this instance are not those of its geometry
                edges = sharp_edges(g.vertices, g.faces, _unit(normals @ transforms[k].T), self.angle)
                world_normals = edges.normal
            parts.append(self._placed(k, inst, g, edges, world_normals))
        self.a, self.b, self.face, self.corner, self.instance, self.normal = (
            np.concatenate([p[i] for p in parts]) if parts else np.empty(0) for i in range(6))
        d = self.b - self.a
        self.length = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]) if len(d) else np.empty(0)
        self.cdf = np.cumsum(self.length)
        self.guide = _guide_table(self.cdf) if len(self) and self.cdf[-1] > 0 else None

    def __len__(self):
        return len(self.face)

    @property
    def total_length(self) -> float:
        return float(self.cdf[-1]) if len(self.cdf) else 0.0

    @staticmethod
    def _placed(k, inst, g, edges: SharpEdges, normal):
        """(a, b, face, corner, instance, normal) of one instance's edges in world space."""
        a, b = edges.ends(g.vertices, g.faces)
        if inst.matrix is not None:
            a, b = apply_matrix(inst.matrix, a), apply_matrix(inst.matrix, b)
        return a, b, edges.face, edges.corner, np.full(len(edges), k, dtype=np.int64), normal

    def draw(self, start: int, stop: int, seed: int, want_bary: bool = False) -> RawChunk:
        """Edge points ``start .. stop - 1`` of the edge stream of ``seed``."""
        u = edge_uniforms(seed, start, stop)
        e = select(self.cdf, self.guide, u[:, 0])
        t = u[:, 1]
        a, b = np.take(self.a, e, axis=0), np.take(self.b, e, axis=0)
        points = np.empty((len(e), 3))
        for c in range(3):
            col = (b[:, c] - a[:, c]) * t
            col += a[:, c]
            points[:, c] = col
        bary = None
        if want_bary:
            corner = self.corner[e]
            rows = np.arange(len(e))
            bary = np.zeros((len(e), 3))
            bary[rows, corner] = 1.0 - t
            bary[rows, (corner + 1) % 3] = t
        return RawChunk(start, points, self.face[e], self.instance[e], bary, np.ones(len(e), dtype=bool),
                        np.take(self.normal, e, axis=0))


def edge_uniforms(seed: int, start: int, stop: int):
    """Draws of edge points ``start .. stop - 1``: (n, 2) float64 in [0, 1)."""
    bits = np.random.PCG64DXSM([STREAM_KEY, int(seed)])
    bits.advance(EDGE_DRAWS * int(start))
    return np.random.Generator(bits).random((stop - start, EDGE_DRAWS))


class EdgeMixSource:
    """A run's points, its edge points interleaved with its face points (see the module
    docstring). faces: the face source, of ``count - interleaving.before(count)`` points."""

    kept = stats = None

    def __init__(self, faces, table: EdgeTable, count: int, interleaving: Interleaving, seed: int,
                 want_bary: bool = False):
        self.faces, self.table, self.count = faces, table, int(count)
        self.interleaving, self.seed, self.want_bary = interleaving, seed, want_bary
        self.area = faces.area

    def draw(self, start: int, stop: int) -> RawChunk:
        first, last = self.interleaving.before(start), self.interleaving.before(stop)
        on_edge = self.interleaving.mask(start, stop)
        edge = self.table.draw(first, last, self.seed, self.want_bary)
        face = self.faces.draw(start - first, stop - last)
        e, f = np.flatnonzero(on_edge), np.flatnonzero(~on_edge)
        bary = None if edge.bary is None else _mixed(e, f, edge.bary, face.bary)
        return RawChunk(start, _mixed(e, f, edge.points, face.points), _mixed(e, f, edge.face, face.face),
                        _mixed(e, f, edge.instance, face.instance), bary, on_edge,
                        _mixed(e, f, edge.normal, np.zeros((len(f), 3))))


def _mixed(e, f, of_edges, of_faces):
    """Rows ``of_edges`` (len(e), ...) at rows ``e`` and ``of_faces`` at rows ``f`` of a new
    array: e and f (k,) int64 split 0 .. len(e) + len(f) - 1 between them."""
    out = np.empty((len(e) + len(f),) + of_edges.shape[1:], dtype=of_edges.dtype)
    row = np.dtype((np.void, out.itemsize * (out.size // max(len(out), 1))))  # a row as one item: put moves it whole
    for index, rows in ((e, of_edges), (f, of_faces)):
        np.put(out.view(row).reshape(-1), index, np.ascontiguousarray(rows, dtype=out.dtype).view(row).reshape(-1))
    return out


def _unit(v):
    """Rows of ``v`` (m, 3) scaled to unit length (zero rows stay zero)."""
    length = np.sqrt(np.einsum("ij,ij->i", v, v))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(length[:, None] > 0, v / length[:, None], 0.0)
