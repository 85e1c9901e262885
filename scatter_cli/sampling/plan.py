"""Face selection and sampling: a surface -> a sample plan -> chunks of points.

Point ``i`` of the ``random`` method is a pure function of the seed and ``i``: it uses
draws ``3 i .. 3 i + 2`` of one PCG64DXSM stream (face choice, then the two warp
inputs). A chunk starting at point ``s`` advances a copy of the stream by ``3 s``,
so chunks can be made in any size, order or thread and the output is the same bytes.
"""

from __future__ import annotations

import collections
import functools
import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..core import native, seeding
from ..core.native import in_blocks
from ..errors import ScatterError
from ..surface.areas import norms
from ..surface.model import (Surface, apply_matrix, cofactor, cofactors, column_bounds as numpy_column_bounds, corners,
                             face_cross, transformed_columns)
from .warps import square_to_triangle

DRAWS_PER_POINT = 3
DEFAULT_CHUNK = 1 << 17  # points a chunk, unless the mesh is large (docs/how-it-samples.md: chunk sizes)
# Faces from which the kernel takes a chunk's points in face order, and the chunk size it
# gets then: larger chunks hold closer faces (docs/how-it-samples.md: chunk sizes).
SORT_FACES, LARGE_MESH_CHUNK = 1 << 18, 1 << 19
_kernel = native.kernel("_csampling")


@dataclass
class Part:
    """One instance's faces that can receive points.

    faces: (k,) int64 face indices into its geometry, None when every face is used;
    tri: (F, 9) float64 local corners of the whole geometry (shared between instances
    of one geometry), or None when the compiled kernel reads them from ``geometry``.
    """

    instance: int
    faces: np.ndarray | None
    tri: np.ndarray | None
    matrix: np.ndarray | None
    geometry: object

    @property
    def count(self) -> int:
        return len(self.geometry.faces) if self.faces is None else len(self.faces)


@dataclass
class RawChunk:
    """What the sampler knows about a run of points, before attributes and precision.

    points: (n, 3) float64 world space; face: (n,) int64 index in the geometry;
    instance: (n,) int64; bary: (n, 3) float64 weights of the face's vertices 0, 1, 2.
    With ``--edges``: sharp (n,) bool, the points drawn on sharp edges, and normal (n, 3)
    float64, their edges' world-space unit normals (rows of face points unused).
    """

    start: int
    points: np.ndarray
    face: np.ndarray
    instance: np.ndarray
    bary: np.ndarray
    sharp: np.ndarray | None = None
    normal: np.ndarray | None = None

    OPTIONAL = ("bary", "sharp", "normal")  # the fields that may be None

    def take(self, index):
        """The rows ``index`` (k,) int as a new chunk starting at 0."""
        rows = (lambda a: None if a is None else np.take(a, index, axis=0))  # noqa: E731 (take copies rows of 3 faster than a[index])
        return RawChunk(0, rows(self.points), self.face[index], self.instance[index],
                        *(rows(getattr(self, f)) for f in self.OPTIONAL))

    @staticmethod
    def join(chunks):
        """One chunk, starting at 0, of ``chunks`` end to end."""
        if len(chunks) == 1:
            return chunks[0]
        return RawChunk(0, *(np.concatenate([getattr(c, f) for c in chunks]) for f in ("points", "face", "instance")),
                        *(None if getattr(chunks[0], f) is None else np.concatenate([getattr(c, f) for c in chunks])
                          for f in RawChunk.OPTIONAL))

    def slice(self, start, stop):
        part = (lambda a: None if a is None else a[start:stop])  # noqa: E731
        return RawChunk(start, self.points[start:stop], self.face[start:stop], self.instance[start:stop],
                        *(part(getattr(self, f)) for f in self.OPTIONAL))


class SamplePlan:
    """Everything needed to draw points from a surface, built once per run."""

    def __init__(self, surface: Surface, weights=None):
        self.surface = surface
        self.parts, doubled, self.non_finite = _parts(surface, weights)
        self.cdf = np.cumsum(doubled, out=doubled)  # in place: the areas are not kept
        self.cdf *= 0.5
        self.offsets = np.cumsum([0] + [p.count for p in self.parts])
        if len(self.parts) > 1:
            self._scene_tables()
        if not len(self.cdf) or not self.cdf[-1] > 0 or not math.isfinite(self.cdf[-1]):
            raise ScatterError(f"{surface.source}: the mesh has no faces with a non-zero, finite area")
        self.guide = _guide_table(self.cdf)
        # every point's instance when there is one: one value, no memory (sliced per chunk)
        self._one_instance = np.broadcast_to(np.int64(self.parts[0].instance), (1 << 59,))
        # how the kernel goes (the output is the same); the NumPy path has no such order
        self.in_face_order = _kernel is not None and self.faces_used >= SORT_FACES

    @property
    def area(self) -> float:
        """Total sampled area (weighted area when a weight is given)."""
        return float(self.cdf[-1])

    @property
    def faces_used(self) -> int:
        return len(self.cdf)

    @property
    def default_chunk(self) -> int:
        """Points a chunk when the caller does not say."""
        return LARGE_MESH_CHUNK if self.in_face_order else DEFAULT_CHUNK

    def select(self, u):
        """Index into the used-face list for each ``u`` (n,) in [0, 1): P(k) = area_k / total
        (:func:`select`)."""
        return select(self.cdf, self.guide, u)

    def draw(self, start: int, stop: int, seed: int, want_bary: bool = False) -> RawChunk:
        """Points ``start`` to ``stop`` of the random sequence for ``seed`` (the random
        method's stream; :class:`scatter_cli.sampling.sources.RandomSource` is its source)."""
        if _kernel is None:
            u = uniforms(seed, start, stop)
            return self.place(start, self.select(u[:, 0]), square_to_triangle(u[:, 1:3]), want_bary)
        n = stop - start
        used, points = np.empty(n, dtype=np.int64), np.empty((n, 3))
        b = np.empty((n, 2)) if want_bary else None
        _kernel.draw(self.cdf, self.guide, generator_state(seed, start), *self._corner_table(), used, points, b,
                     self.in_face_order)
        return self._finish(start, used, b, points, want_bary)

    def _scene_tables(self):
        """Gather tables for several instances: for every used face of every instance, its
        row in the shared corner array and its face number (indices only: the corners of an
        instanced geometry are stored once), and the (P, 3, 4) placement of each part."""
        base = self.parts[0].tri.base
        self._corners = base if base is not None else self.parts[0].tri
        origin = self._corners.__array_interface__["data"][0]
        first = {}  # a geometry's row in the shared corner array, by its view
        for p in self.parts:
            if id(p.tri) not in first:
                first[id(p.tri)] = (p.tri.__array_interface__["data"][0] - origin) // (9 * 8)
        counts = np.diff(self.offsets)
        local = np.arange(self.offsets[-1], dtype=np.int64) - np.repeat(self.offsets[:-1], counts)
        for k, p in enumerate(self.parts):
            if p.faces is not None:
                local[self.offsets[k] : self.offsets[k + 1]] = p.faces
        self._rows = local + np.repeat(np.array([first[id(p.tri)] for p in self.parts], dtype=np.int64), counts)
        self._faces = local
        self._instance = np.asarray([p.instance for p in self.parts], dtype=np.int64)
        eye = np.eye(4)
        self._matrix = np.stack([(eye if p.matrix is None else p.matrix)[:3] for p in self.parts])
        self._moved = any(p.matrix is not None for p in self.parts)

    def _corner_table(self):
        """(coords, faces, rows) for the kernels: used face k has corners
        ``coords[rows[k]]`` of a (R, 9) corner table when faces is None, else the vertices
        ``coords[faces[rows[k]]]``; rows None means k itself."""
        if len(self.parts) == 1:
            part = self.parts[0]
            if part.tri is None:
                return part.geometry.vertices, part.geometry.faces, part.faces
            return part.tri, None, part.faces
        return self._corners, None, self._rows

    def place(self, start, used, b, want_bary=False) -> RawChunk:
        """Points at barycentric ``b`` (n, 2) on used faces ``used`` (n,)."""
        points = np.empty((len(used), 3))
        tri, faces, rows = self._corner_table()
        if _kernel is not None:
            used = used.astype(np.int64, copy=False)
            _kernel.place(tri, faces, rows, used, np.ascontiguousarray(b, dtype=np.float64), points)
        else:
            _corner_points(tri, used if rows is None else rows[used], b, points)
        return self._finish(start, used, b, points, want_bary)

    def _finish(self, start, used, b, points, want_bary):
        """The chunk for local corner points (n, 3) of used faces (n,): face and instance
        numbers, instance matrices applied in place, barycentrics if wanted."""
        n = len(used)
        if len(self.parts) == 1:
            part = self.parts[0]
            face = used.astype(np.int64, copy=False) if part.faces is None else np.take(part.faces, used)
            instance = self._one_instance[:n]  # one value, no memory
            if part.matrix is not None:
                apply_matrix(part.matrix, points, out=points)
        else:
            part = np.searchsorted(self.offsets, used, side="right") - 1
            instance = self._instance[part]
            face = self._faces[used]
            if self._moved:
                m = self._matrix[part]
                x, y, z = (points[:, c].copy() for c in range(3))
                for c in range(3):
                    col = m[:, c, 0] * x
                    col += m[:, c, 1] * y
                    col += m[:, c, 2] * z
                    col += m[:, c, 3]
                    points[:, c] = col
        bary = None
        if want_bary:
            bary = np.empty((n, 3))
            bary[:, 1:] = b
            bary[:, 0] = 1.0 - b[:, 0] - b[:, 1]  # >= 0 exactly: the warp keeps b1 + b2 <= 1
        return RawChunk(start, points, face, instance, bary)


def select(cdf, guide, u):
    """Index into ``cdf`` (m,) float64 for each ``u`` (n,) in [0, 1), by its
    :func:`_guide_table` ``guide``: P(k) = (cdf[k] - cdf[k - 1]) / cdf[-1].

    Same result as ``searchsorted(cdf, u * total, 'right')`` clipped to the last entry,
    so a draw that rounds up to the total never indexes past the end and an entry whose
    CDF step is zero is never chosen. The guide table answers most draws outright; the
    others start their search at the right entry and end in a step or two.
    """
    if _kernel is not None:
        index = np.empty(len(u), dtype=np.int64)
        _kernel.select(cdf, guide, np.ascontiguousarray(u, dtype=np.float64), 1, 0, index)
        return index
    last = len(cdf) - 1
    index = guide[(u * len(guide)).astype(np.int64)]
    todo = np.flatnonzero(index < 0)
    i = -1 - index[todo]
    x = u[todo] * cdf[-1]
    for _ in range(4):
        step = (cdf[i] <= x) & (i < last)
        if not step.any():
            break
        i += step
    else:
        more = (cdf[i] <= x) & (i < last)
        i[more] = np.minimum(np.searchsorted(cdf, x[more], side="right"), last)
    index[todo] = i
    return index


def _corner_points(tri, rows, b, points):
    """points (n, 3) = v0 + b1 (v1 - v0) + b2 (v2 - v0) for corner rows ``tri[rows]``.

    Column by column on 1-D arrays: several times faster than (n, 3) broadcasting.
    Adding v0 last keeps the rounding at the scale of the triangle, not of v0.
    """
    b1, b2 = np.ascontiguousarray(b[:, 0]), np.ascontiguousarray(b[:, 1])
    interpolate_corners(np.take(tri, rows, axis=0).T, b1, b2, points)


def interpolate_corners(cols, b1, b2, points):
    """points (n, 3) = v0 + b1 (v1 - v0) + b2 (v2 - v0) from 9 corner columns ``cols``
    (9, n) and weights b1, b2 (n,), in the arithmetic of their dtype; v0 added last."""
    for c in range(3):
        col = (cols[3 + c] - cols[c]) * b1
        col += (cols[6 + c] - cols[c]) * b2
        col += cols[c]
        points[:, c] = col


def uniforms(seed: int, start: int, stop: int):
    """Draws for points ``start .. stop - 1``: (n, 3) float64 in [0, 1)."""
    return np.random.Generator(_stream(seed, start)).random((stop - start, DRAWS_PER_POINT))


@functools.lru_cache(maxsize=64)  # a batch asks for the same seed and start for every mesh
def generator_state(seed: int, start: int):
    """(state high, state low, inc high, inc low): the 128-bit PCG64DXSM state, as four
    uint64, from which the kernel draws point ``start`` onwards: ``_stream(seed, start)``'s,
    computed without importing numpy.random (:mod:`scatter_cli.core.seeding`)."""
    state, inc = _seeded(int(seed))
    state = seeding.advance(state, inc, DRAWS_PER_POINT * int(start))
    mask = (1 << 64) - 1
    return state >> 64, state & mask, inc >> 64, inc & mask


@functools.lru_cache(maxsize=16)  # every chunk of a run starts from its seed's state
def _seeded(seed: int):
    return seeding.pcg64_state(seed)


def _stream(seed, start):
    bits = np.random.PCG64DXSM(seed)
    bits.advance(DRAWS_PER_POINT * int(start))
    return bits


def _parts(surface: Surface, weights):
    """Per-instance usable faces and twice their (world-space, weighted) areas."""
    if _kernel is not None and len(surface.instances) == 1:
        # One mesh and the kernel: areas and points straight from vertices and faces, with
        # no (F, 9) corner table (72 bytes a face to build and to keep).
        inst = surface.instances[0]
        tris, doubled, clean = None, [_doubled_areas(surface.geometries[inst.geometry], inst.matrix)], [False]
    else:
        tris = _geometry_corners(surface)
        doubled, clean = _instance_areas(surface, tris)
    parts, areas = [], []
    skipped = 0
    for k, inst in enumerate(surface.instances):
        g = surface.geometries[inst.geometry]
        a, ok_all = doubled[k], clean[k]
        if weights is not None:
            a, ok_all = a * weights(k, inst), False
        faces = None
        if not ok_all and not (len(a) and a.min() > 0 and a.max() < np.inf):  # two reductions check most meshes
            finite = np.isfinite(a)
            skipped += int(len(a) - np.count_nonzero(finite))
            ok = finite & (a > 0)
            faces = None if ok.all() else np.flatnonzero(ok)
        parts.append(Part(k, faces, None if tris is None else tris[inst.geometry], inst.matrix, g))
        areas.append(a if faces is None else a[faces])
    return parts, (areas[0] if len(areas) == 1 else np.concatenate(areas) if areas else np.empty(0)), skipped


def _doubled_areas(g, matrix):
    """(F,) float64 twice the world-space face areas of geometry ``g``, by the kernel from
    its vertices and faces (as :func:`surface.doubled_areas` gives them, bit for bit)."""
    out = np.empty(len(g.faces))
    cof = None if matrix is None else np.ascontiguousarray(cofactor(matrix[:3, :3]))
    in_blocks(lambda i, j: _kernel.areas(g.vertices, g.faces[i:j], cof, out[i:j]), len(out))
    return out


def _instance_areas(surface, tris):
    """([(F,) float64], [bool]): per instance, twice its world-space face areas (as
    :func:`surface.doubled_areas` gives them, bit for bit) and whether all are positive
    and finite. The instances of one geometry are computed together, (k, F) at a time:
    one face-cross table per geometry, the instance cofactors applied in one go."""
    by_geometry = {}
    for k, inst in enumerate(surface.instances):
        by_geometry.setdefault(inst.geometry, []).append(k)
    n = len(surface.instances)
    areas, clean = [None] * n, [False] * n
    with np.errstate(invalid="ignore", over="ignore"):
        for gi, ks in by_geometry.items():
            tri = tris[gi]
            cross = np.concatenate(in_blocks(lambda i, j: face_cross(tri[i:j]), len(tri)))
            still = [k for k in ks if surface.instances[k].matrix is None]
            moved = [k for k in ks if surface.instances[k].matrix is not None]
            if still:
                a = norms(list(cross.T))
                good = bool(len(a) and a.min() > 0 and a.max() < np.inf)
                for k in still:
                    areas[k], clean[k] = a, good
            if moved:
                table = _movednorms(cofactors(np.stack([surface.instances[k].matrix for k in moved])), cross)
                good = ((table.min(axis=1) > 0) & (table.max(axis=1) < np.inf)).tolist() if len(tri) else [False] * len(moved)
                for r, k in enumerate(moved):
                    areas[k], clean[k] = table[r], good[r]
    return areas, clean


def _movednorms(cof, cross):
    """(k, F) float64 lengths of ``cross`` (F, 3) under each cofactor matrix of ``cof``
    (k, 3, 3), in blocks of instances of about 2^20 values."""
    out = np.empty((len(cof), len(cross)))
    step = max(1, (1 << 20) // max(len(cross), 1))

    def fill(i, j):
        for s in range(i, j, step):
            e = min(s + step, j)
            out[s:e] = norms(transformed_columns(cof[s:e], cross))

    in_blocks(fill, len(cof), min_block=step)
    return out


def _geometry_corners(surface):
    """{geometry: (F, 9) corners} for the geometries the instances use, as views of one array.

    One array lets a chunk of a multi-object scene gather all its triangles at once.
    """
    used = sorted({inst.geometry for inst in surface.instances})
    sizes = [len(surface.geometries[gi].faces) for gi in used]
    whole = np.empty((sum(sizes), 9))
    views, start = {}, 0
    for gi, size in zip(used, sizes):
        g, view = surface.geometries[gi], whole[start : start + size]

        def fill(i, j, g=g, view=view):
            view[i:j] = corners(g.vertices, g.faces[i:j])

        in_blocks(fill, size)
        views[gi] = view
        start += size
    return views


def _guide_table(cdf):
    """For 2^m buckets of u (2 to 4 per face): the face of a bucket, or -1 - first candidate.

    Entry k is the first face whose CDF exceeds the bucket's lower edge ``k / M * total``.
    When the next bucket starts on that same face, every draw in bucket k lands there and
    the entry is stored as is; otherwise it is stored as ``-1 - face`` and the search goes
    on from it. A power-of-two M makes ``u * M`` and ``k / M`` exact, so no draw's face is
    before its bucket's entry.
    """
    last = len(cdf) - 1
    m = 1 << max(4, min(26, int(len(cdf) - 1).bit_length() + 1))
    itype = np.int32 if len(cdf) < 2**31 - 1 else np.int64
    if _kernel is not None:
        table = np.empty(m, dtype=itype)
        in_blocks(lambda i, j: _kernel.guide(cdf, table, i, j), m)
        return table
    first = np.empty(m + 1, dtype=itype)

    def fill(i, j):
        lower = (np.arange(i, j, dtype=np.float64) / m) * cdf[-1]
        first[i:j] = np.minimum(np.searchsorted(cdf, lower, side="right"), last)

    in_blocks(fill, m + 1)
    return np.where(first[1:] == first[:-1], first[:-1], -1 - first[:-1])


def column_bounds(v):
    """(lo, hi): the (3,) minimum and maximum of each column of ``v`` (n, 3) float64, n > 0:
    surface.column_bounds's values bit for bit, in one pass where the kernel is built
    (about twice as fast on the 3.9M vertices of a 1.3M-face binary STL)."""
    if _kernel is None:
        return numpy_column_bounds(v)
    out = np.empty((2, 3))
    _kernel.bounds(np.ascontiguousarray(v, dtype=np.float64), out)
    return out[0], out[1]


def chunk_ranges(stop: int, chunk_size: int, start: int = 0):
    """(start, stop) pairs of at most ``chunk_size`` covering ``range(start, stop)``, made
    as they are taken (a count of 10^13 has millions of chunks)."""
    return ((s, min(s + chunk_size, stop)) for s in range(start, stop, chunk_size))


def run_chunks(job, start, stop, chunk_size, threads=None, split=True):
    """Yield ``job(a, b)`` over consecutive ranges covering ``start .. stop - 1``, in order.

    On one thread the ranges are chunks of ``chunk_size`` points. On T threads a pool
    computes them while the caller takes them in order, with at most IN_FLIGHT chunks'
    worth of points computed or waiting at a time, so that memory stays flat whatever
    the count and whatever T: ``split``, pieces of the chunks (:func:`pieces`), each on one
    thread; else (a job that splits its range among the threads itself, such as the
    volume labels) two half chunks at a time, so that one's Python runs while the
    other's kernels do, in the memory of one chunk. The output's bytes never change: a job's result does not depend
    on where its range was cut.
    """
    threads = threads or native.worker_count()
    piece, depth = pieces(stop - start, chunk_size, threads) if split else (-(-chunk_size // 2), 2)
    if depth <= 1:
        yield from (job(a, b) for a, b in chunk_ranges(stop, piece, start))
        return
    ranges = chunk_ranges(stop, piece, start)
    with native.thread_pool(min(threads, depth), one_level=split) as pool:
        pending = collections.deque(pool.submit(job, *r) for r in itertools.islice(ranges, depth))
        while pending:
            yield pending.popleft().result()
            nxt = next(ranges, None)  # (once the caller is done with the last: it counts)
            if nxt is not None:
                pending.append(pool.submit(job, *nxt))


IN_FLIGHT = 2  # chunks' worth of points a pool holds at most, computed or waiting, whatever its threads
MIN_PIECE = 1 << 13  # points a piece at least: less, and the Python of each piece would be the bound


def pieces(n, chunk_size, threads):
    """(points a piece, pieces in flight at most) for ``n`` points in chunks of
    ``chunk_size`` on ``threads`` threads: two pieces a thread in flight, of IN_FLIGHT
    chunks' worth in all (of MIN_PIECE points at least, then fewer in flight), and pieces
    small enough for a short run to keep the threads busy. (chunk_size, 1): one at a time."""
    if threads <= 1 or n <= min(chunk_size, MIN_PIECE):
        return chunk_size, 1
    piece = min(chunk_size, max(MIN_PIECE, IN_FLIGHT * chunk_size // (2 * threads)), -(-n // (2 * threads)))
    piece = max(piece, min(MIN_PIECE, chunk_size))
    return piece, max(1, min(2 * threads, IN_FLIGHT * chunk_size // piece))
