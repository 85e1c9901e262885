"""Stable placement (``--stable``): points keyed to the faces themselves.

Each usable face is a Poisson process in time with rate ``area`` (times its mean weight
under ``--weight``), drawn from its own counter-based stream: a key hashed from the seed
and the face's world-space corners (rotated to start at the smallest corner, so a
renumbered or rotated face keeps its key; a mirrored winding is another face). Nothing
about a face's stream depends on its index or on any other face.

A face's time axis is cut into blocks of length ``BLOCK_MEAN / rate`` (the face's own
scale, so a block holds BLOCK_MEAN arrivals on average whatever the mesh's units). Block
``b`` of the face with key ``k`` has state ``s = mix(k + (b + 1) G)``; lane ``l`` of
the block is ``mix(s + l G)``: lane 0 gives the block's Poisson count ``c``, arrival
``j < c`` uses lanes ``1 + 4 j .. 4 + 4 j`` (its time within the block, then the in-face
warp's inputs). ``mix`` is SplitMix64's finaliser and ``G`` its golden-ratio increment.

A run keeps the arrivals before a threshold time: the N earliest over the whole surface
(count mode), every one before D (``--density D``), or every one before a time fixed by
R and then dart-thrown in arrival order (``--radius R``). Output is in arrival order,
ties in time broken by (face key, counter): a total order that depends on no index. The
work is O(N + F): per face a key and the blocks up to the threshold, per arrival a time.
"""

from __future__ import annotations

import math
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import native
from .errors import ScatterError, ScatterUsageError
from .sampling import DEFAULT_CHUNK, LARGE_MESH_CHUNK, SORT_FACES, RawChunk, in_blocks, interpolate_corners
from .surface import apply_matrix
from .warps import square_to_triangle

MASK = (1 << 64) - 1
GOLDEN = 0x9E3779B97F4A7C15
_G = np.uint64(GOLDEN)
_M1, _M2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
# Expected arrivals per block. The work is about F + N / m block counts plus N + F m / 2
# arrival times: 2 balances the 1.31M-face icosphere at 10^6 points against the skull
# (0.1M faces) at 10^7.
BLOCK_MEAN = 2.0
COUNT_BITS = 5  # a block's arrival number j fits in 5 bits: counts are capped at 31
LANES = 4  # per arrival: time, then up to three warp inputs
FACE_BLOCK = 1 << 16  # faces keyed at a time
_kernel = native.kernel("_cstable")
ARRIVAL_BLOCK = 1 << 20  # time blocks expanded at a time
ROOM_SDS = 6.0  # a face range's share of a time bucket holds its mean count plus this many standard deviations
PIECES = 2  # face ranges a worker thread
FINE_BITS = 12  # a coarse bucket of the kernel's arrival sort holds 2^12 to 2^15 time keys
RAY_LANE = 1 << 32  # lanes RAY_LANE + 4 j + k of a block: arrival j's ray rotation (--exterior)


def _poisson_cdf():
    """(31,) float64 P(count <= k) for a Poisson(BLOCK_MEAN) count, k = 0 .. 30.

    Built from a literal e^-2 by plain multiplications and additions, so the table is
    the same on every machine.
    """
    p = 0.1353352832366127  # exp(-2.0)
    cdf = []
    total = 0.0
    for k in range((1 << COUNT_BITS) - 1):
        if k:
            p = p * BLOCK_MEAN / k
        total += p
        cdf.append(total)
    return np.array(cdf)


POISSON_CDF = _poisson_cdf()


def mix(z):
    """SplitMix64's finaliser on (n,) uint64 ``z``, in place; returns ``z``."""
    z ^= z >> np.uint64(30)
    z *= _M1
    z ^= z >> np.uint64(27)
    z *= _M2
    z ^= z >> np.uint64(31)
    return z


def lane(state, offset):
    """(n,) uint64 ``mix(state + offset G)``; offset a scalar or (n,) uint64."""
    z = np.asarray(offset, dtype=np.uint64) * _G
    z += state
    return mix(z)


def to_unit(z):
    """(n,) uint64 -> (n,) float64 in [0, 1): the top 53 bits."""
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


def seed_word(seed: int) -> int:
    """The seed (any non-negative int) folded into one 64-bit word."""
    h = 0
    seed = int(seed)
    while True:
        h = _mix_int((h ^ (seed & MASK)) + GOLDEN)
        seed >>= 64
        if not seed:
            return h


def _mix_int(z):
    z &= MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return z ^ (z >> 31)


def canonical(cols):
    """Rotate faces to start at their smallest corner (x, then y, then z).

    cols: 9 (n,) float64 columns of world corners (corner 0 x y z, corner 1, corner 2)
    -> (rotation (n,) int64 in 0..2, 9 canonical columns starting at corner ``rotation``,
    -0.0 written as 0.0).
    """
    c = [[cols[3 * k + a] + 0.0 for a in range(3)] for k in range(3)]
    rot = np.zeros(len(cols[0]), dtype=np.int64)
    best = c[0]
    for k in (1, 2):
        x = c[k]
        less = (x[0] < best[0]) | ((x[0] == best[0]) & ((x[1] < best[1]) | ((x[1] == best[1]) & (x[2] < best[2]))))
        rot[less] = k
        best = [np.where(less, x[a], best[a]) for a in range(3)]
    one, two = rot == 1, rot == 2
    out = list(best)
    for k in (1, 2):
        for a in range(3):
            out.append(np.where(one, c[(1 + k) % 3][a], np.where(two, c[(2 + k) % 3][a], c[k][a])))
    return rot, out


def doubled_areas(cols):
    """(n,) float64 twice the areas of faces given as 9 corner columns (n,), computed as
    :func:`scatter_cli.surface.doubled_areas` computes them from (n, 9) rows."""
    e1 = [cols[3 + c] - cols[c] for c in range(3)]
    e2 = [cols[6 + c] - cols[c] for c in range(3)]
    n = [e1[(c + 1) % 3] * e2[(c + 2) % 3] - e1[(c + 2) % 3] * e2[(c + 1) % 3] for c in range(3)]
    s = n[0] * n[0]
    s += n[1] * n[1]
    s += n[2] * n[2]
    return np.sqrt(s, out=s)


def face_keys(cols, seed, extra=None):
    """(n,) uint64 keys of 9 canonical corner columns (n,) float64 (and ``extra`` (n,)
    float64, the weight, when given): one hash over their bytes, seeded."""
    h = np.full(len(cols[0]), seed_word(seed), dtype=np.uint64)
    for w in list(cols) + ([] if extra is None else [extra]):
        h ^= np.ascontiguousarray(w, dtype=np.float64).view(np.uint64)
        h += _G
        mix(h)
    return h


class FaceTable:
    """The usable faces of a surface in world space, keyed.

    Per used face k (instances in order, faces in file order): ``part[k]`` instance,
    ``face[k]`` index in its geometry, ``rot[k]`` (uint8) rotation to its canonical
    corners, ``key[k]`` (uint64), ``rate[k]`` (float64 > 0) arrivals per unit time.
    ``weight``: None, or a weighting with ``corner_weights(instance) -> (F, 3)`` or a
    per-face bound and a rejection test (see :class:`StableSource`).
    """

    def __init__(self, surface, seed, weight=None):
        self.surface = surface
        self._columns = {}
        self.non_finite = 0
        self.corners = None  # (F, 9) float64 placement rows of a small single mesh (kernel path)
        got = []  # per instance: (used faces (None: all), rot, key, rate, area of its usable faces)
        for k, inst in enumerate(surface.instances):
            if _kernel is not None and weight is None:
                got.append(self._kernel_faces(k, seed))
            else:
                got.append(self._numpy_faces(k, seed, weight))
            if inst.matrix is not None and len(surface.instances) > 1:
                self._columns.pop(k, None)  # moved vertices are made again for the few faces drawn
                self._columns.pop(("v", k), None)
        # one instance with every face used: used face k is face k (no part or face table)
        self.identity = len(got) == 1 and got[0][0] is None
        if len(got) == 1:
            self._face, self.rot, self.key, self.rate = got[0][:4]
            self._part = None
        else:
            cat = lambda xs, dt: np.concatenate(xs) if xs else np.empty(0, dtype=dt)  # noqa: E731
            self._face = cat([np.arange(len(g[2])) if g[0] is None else g[0] for g in got], np.int64)
            self._part = cat([np.full(len(g[2]), k, dtype=np.int32) for k, g in enumerate(got)], np.int32)
            self.rot, self.key = cat([g[1] for g in got], np.uint8), cat([g[2] for g in got], np.uint64)
            self.rate = cat([g[3] for g in got], np.float64)
        self.area = float(sum(g[4] for g in got))
        self.total = float(np.sum(self.rate)) if len(self.rate) else 0.0
        if weight is not None and self.area > 0 and self.total == 0:
            raise ScatterError(f"{surface.source}: --weight: the weight is zero over the whole surface")
        if not (self.total > 0 and math.isfinite(self.total)):
            raise ScatterError(f"{surface.source}: the mesh has no faces with a non-zero, finite area")

    def __len__(self):
        return len(self.key)

    @property
    def default_chunk(self):
        """Points a chunk when the caller does not say: as for the random method's plan
        (larger chunks on a large mesh, whose points the kernel places in face order)."""
        return LARGE_MESH_CHUNK if _kernel is not None and len(self) >= SORT_FACES else DEFAULT_CHUNK

    @property
    def face(self):
        """(U,) int64: used face k is face ``face[k]`` of its geometry."""
        if self._face is None:
            self._face = np.arange(len(self.key))
        return self._face

    @property
    def part(self):
        """(U,) int32: the instance of used face k."""
        if self._part is None:
            self._part = np.zeros(len(self.key), dtype=np.int32)
        return self._part

    def _kernel_faces(self, k, seed):
        """(used faces or None, rot, key, area, usable area) of instance ``k`` by the
        kernel, in blocks on the worker threads, unweighted (rate = area)."""
        vertices = self.world_vertices(k)
        faces = self.surface.geometries[self.surface.instances[k].geometry].faces
        n = len(faces)
        rot, key, area = np.empty(n, np.uint8), np.empty(n, np.uint64), np.empty(n)
        if len(self.surface.instances) == 1 and n < SORT_FACES:
            # a point's face row in one read: placement in arrival order reads faces at random
            self.corners = np.empty((n, 9))
        word = seed_word(seed)
        in_blocks(lambda i, j: _kernel.faces(vertices, faces, i, j, word, rot, key, area, self.corners), n, 1 << 15)
        if n and area.min() > 0 and area.max() < np.inf:  # two reductions check most meshes
            return None, rot, key, area, float(np.sum(area))
        finite = np.isfinite(area)
        self.non_finite += int(n - np.count_nonzero(finite))
        ok = np.flatnonzero(finite & (area > 0))
        return ok, rot[ok], key[ok], area[ok], float(np.sum(area[ok]))

    def _numpy_faces(self, k, seed, weight):
        """(used faces, rot, key, rate, usable area) of instance ``k`` (rate: area times
        the face's weight), FACE_BLOCK faces at a time."""
        inst = self.surface.instances[k]
        g = self.surface.geometries[inst.geometry]
        w_faces = None if weight is None else weight.face_weights_of(k, inst)
        world = self.world_columns(k)
        faces, rots, keys, rates, areas = [], [], [], [], []
        for i in range(0, len(g.faces), FACE_BLOCK):
            j = min(i + FACE_BLOCK, len(g.faces))
            rot, cols = canonical([np.take(world[a], g.faces[i:j, c]) for c in range(3) for a in range(3)])
            w = None
            if w_faces is not None:
                w = _rotated_mean(w_faces[i:j], rot) if w_faces.ndim == 2 else w_faces[i:j]
            with np.errstate(invalid="ignore", over="ignore"):
                area = 0.5 * doubled_areas(cols)
                rate = area if w is None else area * w
            areas.append(area[np.isfinite(area) & (area > 0)])
            finite = np.isfinite(rate)
            self.non_finite += int(len(rate) - np.count_nonzero(finite))
            ok = np.flatnonzero(finite & (rate > 0))
            faces.append(ok + i)
            rots.append(rot[ok].astype(np.uint8))
            keys.append(face_keys([x[ok] for x in cols], seed, None if w is None else w[ok]))
            rates.append(rate[ok])
        cat = lambda xs, dt: np.concatenate(xs) if xs else np.empty(0, dtype=dt)  # noqa: E731
        return (cat(faces, np.int64), cat(rots, np.uint8), cat(keys, np.uint64), cat(rates, np.float64),
                float(np.sum(cat(areas, np.float64))))

    @property
    def parts(self):
        """[sampling.Part] of the used faces, instance by instance: what
        api.sampled_bounds reads (so a stable run builds no SamplePlan)."""
        from .sampling import Part

        if self.identity:  # one instance, every face
            inst = self.surface.instances[0]
            return [Part(0, None, None, inst.matrix, self.surface.geometries[inst.geometry])]
        out = []
        bounds = np.searchsorted(self.part, np.arange(len(self.surface.instances) + 1))
        for k, inst in enumerate(self.surface.instances):
            g = self.surface.geometries[inst.geometry]
            faces = self.face[bounds[k] : bounds[k + 1]]
            out.append(Part(k, None if len(faces) == len(g.faces) else faces, None, inst.matrix, g))
        return out

    def world_vertices(self, k):
        """(V, 3) float64 world vertices of instance ``k`` (the rows apply_matrix gives)."""
        inst = self.surface.instances[k]
        v = self.surface.geometries[inst.geometry].vertices
        if inst.matrix is None:
            return v
        key = ("v", k)
        if key not in self._columns:
            self._columns[key] = apply_matrix(inst.matrix[:3], v)
        return self._columns[key]

    def world_columns(self, k):
        """[x, y, z] (V,) float64 world vertex columns of instance ``k``: an unmoved
        geometry's are kept (shared by its instances), a moved one's made when asked."""
        inst = self.surface.instances[k]
        key = ("g", inst.geometry) if inst.matrix is None else k
        if key not in self._columns:
            v = self.surface.geometries[inst.geometry].vertices
            if inst.matrix is not None:
                v = apply_matrix(inst.matrix[:3], v)
            self._columns[key] = [np.ascontiguousarray(v[:, a]) for a in range(3)]
        return self._columns[key]

    def corner_columns(self, used):
        """The canonical world corners of used faces ``used`` (n,): a list of 9 (n,)
        float64 columns, corner 0 x y z, corner 1, corner 2."""
        n = len(used)
        part = self.part[used]
        one = len(self.surface.instances) == 1
        cols = None if one else [np.empty(n) for _ in range(9)]
        for k in (range(1) if one else np.unique(part)):
            rows = None if one else np.flatnonzero(part == k)
            mine = used if one else used[rows]
            inst = self.surface.instances[k]
            g = self.surface.geometries[inst.geometry]
            base = 3 * self.face[mine]
            rot = self.rot[mine].astype(np.int64)
            vi = [np.take(g.faces.reshape(-1), base + (rot + c) % 3) for c in range(3)]
            if inst.matrix is None:
                world = self.world_columns(k)
                got = [np.take(world[a], vi[c]) for c in range(3) for a in range(3)]
            else:  # the rows apply_matrix gives for all vertices, made for these only
                got = []
                for c in range(3):
                    w = apply_matrix(inst.matrix[:3], np.take(g.vertices, vi[c], axis=0))
                    got += [w[:, a] for a in range(3)]
            if one:
                return got
            for c in range(9):
                cols[c][rows] = got[c]
        return cols

    def rekey_duplicates(self, seed):
        """Give faces with equal keys distinct keys (the second copy, third, ...): a face
        listed twice has twice the weight, not one stream read twice. Returns whether any."""
        order = np.argsort(self.key, kind="stable")
        same = self.key[order][1:] == self.key[order][:-1]
        if not same.any():
            return False
        run_start = np.flatnonzero(np.concatenate([[True], ~same]))
        occurrence = np.arange(len(order)) - np.repeat(run_start, np.diff(np.append(run_start, len(order))))
        dup = order[occurrence > 0]
        self.key[dup] = lane(self.key[dup], occurrence[occurrence > 0].astype(np.uint64) + np.uint64(1 << 40))
        return True


def _rotated_mean(w, rot):
    """(n,) mean of corner weights ``w`` (n, 3), summed from corner ``rot`` on (so that a
    rotated face gets the same bits)."""
    r = _rotated_rows(w, rot, width=1)
    return (r[:, 0] + r[:, 1] + r[:, 2]) / 3.0


def _rotated_rows(tri, rot, width=3):
    """Rows of ``tri`` (n, 3 width) with their corners rotated to start at ``rot`` (n,)."""
    rot = rot.astype(np.int64)
    rows = np.arange(len(tri))[:, None]
    cols = ((rot[:, None] + np.arange(3)) % 3)[:, :, None] * width + np.arange(width)
    return tri[rows, cols.reshape(len(tri), 3 * width)]


def _interpolate(cols, b):
    """(n, 3) float64 points ``v0 + b1 (v1 - v0) + b2 (v2 - v0)`` from 9 corner columns
    (n,), rounded as the random method's (sampling.interpolate_corners)."""
    points = np.empty((len(b), 3))
    interpolate_corners(cols, np.ascontiguousarray(b[:, 0]), np.ascontiguousarray(b[:, 1]), points)
    return points


def _blocks_before(tau, length):
    """(n,) int64 blocks of lengths ``length`` (n,) that cover time [0, tau): every
    arrival of a later block has time >= tau, in floating point too."""
    with np.errstate(over="ignore", invalid="ignore"):
        nb = np.floor(tau / length) + 1
    nb = nb.astype(np.int64)
    nb += nb * length < tau
    return nb


def _expand(counts):
    """(owner (total,), rank (total,)) int64: entry ``t`` of run ``owner`` counts 0.."""
    owner = np.repeat(np.arange(len(counts)), counts)
    starts = np.cumsum(counts) - counts
    return owner, np.arange(len(owner)) - starts[owner]


def arrivals(table, tau, first=0, last=None):
    """Arrivals before ``tau`` of used faces ``first .. last - 1``.

    Returns (time (m,) float64, used face (m,) int64, counter (m,) uint64 = block << 5 | j).
    """
    last = len(table) if last is None else last
    rate = table.rate[first:last]
    length = BLOCK_MEAN / rate
    nb = _blocks_before(tau, length)
    cum = np.cumsum(nb)
    out = []
    total = int(cum[-1]) if len(cum) else 0
    for lo in range(0, total, ARRIVAL_BLOCK):
        hi = min(lo + ARRIVAL_BLOCK, total)
        f0 = int(np.searchsorted(cum, lo, side="right"))
        f1 = int(np.searchsorted(cum, hi - 1, side="right")) + 1
        counts = nb[f0:f1].copy()
        skip = lo - (int(cum[f0]) - int(nb[f0]))
        counts[0] -= skip
        counts[-1] -= int(cum[f1 - 1]) - hi
        owner, b = _expand(counts)
        b[: counts[0]] += skip
        face = owner + f0
        state = lane(table.key[first + face], (b + 1).astype(np.uint64))
        c = np.searchsorted(POISSON_CDF, to_unit(lane(state, 0)), side="right")
        blk, j = _expand(c)
        u = to_unit(lane(state[blk], (1 + LANES * j).astype(np.uint64)))
        t = (b[blk] + u) * length[face[blk]]
        keep = np.flatnonzero(t < tau)
        ctr = (b[blk[keep]].astype(np.uint64) << np.uint64(COUNT_BITS)) | j[keep].astype(np.uint64)
        out.append((t[keep], face[blk[keep]] + first, ctr))
    if not out:
        return np.empty(0), np.empty(0, np.int64), np.empty(0, np.uint64)
    return tuple(np.concatenate(x) for x in zip(*out))


def all_arrivals(table, tau):
    """:func:`arrivals` of every used face, in face ranges on the worker threads (the
    NumPy path)."""
    n = len(table)
    threads = native.worker_count()
    pieces = 1 if threads == 1 or n < 2 * FACE_BLOCK else 4 * threads
    cuts = np.linspace(0, n, pieces + 1).astype(np.int64).tolist()
    with ThreadPoolExecutor(max_workers=threads) as pool:
        parts = list(pool.map(lambda a, b: arrivals(table, tau, a, b), cuts[:-1], cuts[1:]))
    return tuple(np.concatenate(x) for x in zip(*parts)) if len(parts) > 1 else parts[0]


def counter_bits(table, tau):
    """Bits of the counter (block << COUNT_BITS | j) in an arrival id ``used face << bits |
    counter``, for the arrivals before ``tau``: room for the most blocks any face has."""
    expected = tau * table.total
    if not expected < 2.0**40:  # about 2^40 arrivals: past any memory
        raise ScatterError(f"{table.surface.source}: --stable would keep {expected:.3g} arrivals: too many")
    most = int(_blocks_before(tau, BLOCK_MEAN / np.max(table.rate)))
    bits = COUNT_BITS + (2 * most + 1).bit_length()
    if bits + max(1, (len(table) - 1).bit_length()) > 63:
        raise ScatterError(f"{table.surface.source}: too many points for --stable on {len(table):,} faces")
    return bits


def kernel_arrivals(table, tau, bits):
    """The kernel's arrivals before ``tau`` of every used face, in arrival order: (time (m,)
    float64, id (m,) uint64, duplicates), sorted by (time, face key, counter) as
    :func:`arrival_order` sorts them; duplicates as :func:`_duplicates`.

    A counting sort on the time key ``floor(t * K / tau)`` (K a power of two, about the
    expected count), in two levels on the worker threads. Face ranges write their arrivals
    straight into coarse buckets of the key, range by range within each bucket (each with
    room for its mean count plus ROOM_SDS standard deviations; in the rare case that one
    holds more, the pass runs again with room for the counts it returned). Then each
    coarse bucket, small enough for the cache, is sorted on the rest of its key and exactly
    within equal keys, and written back from the start of the same arrays.
    """
    n = len(table)
    threads = native.worker_count()
    expected = tau * table.total
    pieces = 1 if threads == 1 or n + expected < 1 << 16 or n < 4 * threads else PIECES * threads
    cuts = _balanced_cuts(table.rate, tau, pieces)
    key_bits = max(1, int(expected).bit_length())  # about 1 to 2 arrivals a key
    fine_bits = min(key_bits, max(FINE_BITS, key_bits - 8), FINE_BITS + 3)
    coarse = 1 << (key_bits - fine_bits)
    total = coarse << fine_bits
    scale = total / float(tau)
    mean = np.array([tau * float(np.sum(table.rate[a:b])) / coarse for a, b in zip(cuts[:-1], cuts[1:])])
    room = np.tile(np.maximum(0, mean + ROOM_SDS * np.sqrt(mean) + 16).astype(np.int64), (coarse, 1))
    args = (table.key, table.rate, float(tau), BLOCK_MEAN, POISSON_CDF)
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for _ in range(2):
            start = (np.cumsum(room) - room.ravel()).reshape(coarse, pieces)
            size = int(room.sum())
            t, ids = np.empty(size), np.empty(size, np.uint64)
            nexts = [start[:, k].copy() for k in range(pieces)]  # advanced by the kernel
            ends = [np.ascontiguousarray(start[:, k] + room[:, k]) for k in range(pieces)]
            list(pool.map(lambda k: _kernel.arrivals(*args, cuts[k], cuts[k + 1], bits, scale, fine_bits, total,
                                                     nexts[k], ends[k], t, ids), range(pieces)))
            counts = np.stack(nexts, axis=1) - start
            if (counts <= room).all():
                return _kernel_order(pool, t, ids, start.ravel(), counts.ravel(), (pieces, scale, fine_bits, total),
                                     table.key, bits)
            room = counts
    raise AssertionError("arrivals: the counts changed between two passes")


def _balanced_cuts(rate, tau, pieces):
    """[pieces + 1] face indices cutting ``rate`` (F,) into ranges of about equal work (a
    face plus its arrivals before ``tau``)."""
    if pieces == 1:
        return [0, len(rate)]
    work = np.cumsum(rate * tau + 1.0)
    return [0] + np.searchsorted(work, work[-1] * np.arange(1, pieces) / pieces).tolist() + [len(rate)]


def _kernel_order(pool, t, ids, start, counts, buckets, key, bits):
    """Sort the bucketed arrivals (segments ``start``, ``counts`` (C P,), see
    :func:`kernel_arrivals`) in place, bucket ranges of about equal counts on the threads:
    (time (m,), id (m,), duplicates). A thread writes the positions below its first
    segment to side arrays (a thread below may still read them), copied in afterwards."""
    parts, coarse = buckets[0], len(start) // buckets[0]
    bounds = np.zeros(coarse + 1, np.int64)
    np.cumsum(counts.reshape(coarse, parts).sum(axis=1), out=bounds[1:])
    m = int(bounds[-1])
    sorters = native.worker_count() if m >= 1 << 16 else 1
    qcuts = np.searchsorted(bounds, np.linspace(0, m, sorters + 1)).tolist()
    qcuts[0], qcuts[-1] = 0, coarse
    sides = []
    for q0, q1 in zip(qcuts[:-1], qcuts[1:]):
        direct = int(start[q0 * parts]) if q0 < coarse else len(t)
        k = max(0, min(direct, int(bounds[q1])) - int(bounds[q0]))
        sides.append((int(bounds[q0]), np.empty(k), np.empty(k, np.uint64)))
    dups = pool.map(lambda k: _kernel.order(t, ids, start, counts, parts, qcuts[k], qcuts[k + 1], *buckets[1:], key,
                                            bits, *sides[k][1:]), range(sorters))
    dup = any(list(dups))
    for lo, t_side, id_side in sides:
        t[lo : lo + len(t_side)] = t_side
        ids[lo : lo + len(id_side)] = id_side
    return t[:m], ids[:m], dup


def arrival_order(t, face, ctr, key):
    """(m,) int64 permutation sorting arrivals by (time, face key, counter).

    t (m,) float64, face (m,) used-face index, ctr (m,) uint64, key (F,) uint64 face keys.
    One value sort of packed words (time quantised in the high bits, position in the low
    ones), then the rare runs of equal quantised time ordered exactly.
    """
    m = len(t)
    if m == 0:
        return np.empty(0, np.int64)
    bits = max(1, (m - 1).bit_length())
    qbits = min(52, 64 - bits)
    top = float(t.max())
    scale = 2.0 ** (qbits - 1) / top if top > 0 else 0.0  # q < 2^qbits even when rounded up
    packed = (t * scale).astype(np.uint64)
    packed <<= np.uint64(bits)
    packed |= np.arange(m, dtype=np.uint64)
    packed.sort()
    order = (packed & np.uint64((1 << bits) - 1)).astype(np.int64)
    packed >>= np.uint64(bits)
    tie = np.flatnonzero(packed[1:] == packed[:-1])
    if len(tie):
        member = np.zeros(m, dtype=bool)
        member[tie] = True
        member[tie + 1] = True
        pos = np.flatnonzero(member)
        run = np.cumsum(np.concatenate([[1], np.diff(pos) > 1]))
        idx = order[pos]
        order[pos] = idx[np.lexsort((ctr[idx], key[face[idx]], t[idx], run))]
    return order


def _duplicates(t, face, ctr, key):
    """Whether two consecutive arrivals (sorted arrays) are the same arrival of two faces
    with one key."""
    same = np.flatnonzero(t[1:] == t[:-1])
    if not len(same):
        return False
    return bool(np.any((key[face[same]] == key[face[same + 1]]) & (ctr[same] == ctr[same + 1])))


class StableSource:
    """The ``--stable`` point source: ``draw(start, stop)`` gives arrivals start..stop-1 in
    arrival order (a pure function of the range).

    At most one of ``count`` (the N earliest arrivals), ``density`` (every arrival before
    time D), ``radius`` (every arrival before the candidate horizon of ``--radius R``:
    :func:`scatter_cli.thinning.dart_thrown` keeps the set) and ``stream=True`` (every arrival, without end:
    ``count`` is None and the arrivals are found as far as ``draw`` asks; what the
    exterior filter reads). ``weight``: an object with ``face_weights_of(k, inst)`` and
    ``barycentric(w, u)`` (vertex colours) or with ``accept(raw, u)`` (textures: arrivals
    at rate area times bound, kept with probability weight over bound).

    An arrival is held as one word, ``id = used face << bits | counter`` (``bits`` from
    :func:`counter_bits`): 8 bytes a point.
    """

    kept = stats = None  # (the Source protocol: neither thinned nor filtered)

    def __init__(self, surface, seed, *, count=None, density=None, radius=None, stream=False, want_bary=False,
                 weight=None, max_candidates=None):
        self.surface, self.seed, self.want_bary, self.weight = surface, seed, want_bary, weight
        self.table = FaceTable(surface, seed, weight)
        self.area = self.table.area
        self.rate = self.table.total
        self._epochs = []  # [(first arrival, end time, ids (k,) uint64, bits)]: arrivals in time order
        if stream:
            # every later stretch of the stream must read the keys the first one read
            self.table.rekey_duplicates(seed)
            self._lock = threading.Lock()
            self.count = None
            return
        if radius is not None:
            self._select_radius(radius, max_candidates)
        elif density is not None:
            self._select_before(float(density))
        else:
            self._select_count(int(count))
        self.count = len(self._epochs[0][2])

    # -- selection ---------------------------------------------------------------------

    def _candidates(self, tau):
        """Arrivals before ``tau`` in arrival order: (time (m,) float64, id (m,) uint64,
        bits); faces with one key get distinct keys first."""
        for _ in range(4):
            t, ids, bits, dup = self._sorted_arrivals(tau)
            if not (dup and self.table.rekey_duplicates(self.seed)):
                return t, ids, bits
        raise ScatterError(f"{self.surface.source}: --stable could not tell duplicate faces apart")

    def _sorted_arrivals(self, tau):
        """(time, id, bits, whether two faces with one key gave the same arrival) of the
        arrivals before ``tau``, in arrival order."""
        bits = counter_bits(self.table, tau)
        key = self.table.key
        if _kernel is not None:
            t, ids, dup = kernel_arrivals(self.table, tau, bits)
            if self._accepts:  # the accepted ones, still in order (the order is total)
                keep = np.flatnonzero(self._accept(ids, bits))
                t, ids = t[keep], ids[keep]
                dup = _duplicates(t, *unpack(ids, bits), key)
            return t, ids, bits, dup
        t, face, ctr = all_arrivals(self.table, tau)
        if self._accepts:
            keep = self._accept(pack(face, ctr, bits), bits)
            t, face, ctr = t[keep], face[keep], ctr[keep]
        order = arrival_order(t, face, ctr, key)
        t, face, ctr = t[order], face[order], ctr[order]
        return t, pack(face, ctr, bits), bits, _duplicates(t, face, ctr, key)

    @property
    def _accepts(self):
        return self.weight is not None and hasattr(self.weight, "accept")

    def _select_before(self, tau):
        t, ids, bits = self._candidates(tau)
        self._epochs = [(0, tau, ids, bits)]

    def _select_count(self, n):
        if n == 0:
            self._epochs = [(0, 0.0, np.empty(0, np.uint64), COUNT_BITS + 1)]
            return
        # a time that n arrivals beat with overwhelming odds: mean count n + 6 sd + 16
        tau = (n + 6.0 * math.sqrt(n) + 16.0) / self.rate
        for _ in range(64):
            t, ids, bits = self._candidates(tau)
            if len(t) >= n:
                self._epochs = [(0, tau, ids[:n], bits)]  # a view: the few past n stay
                self.threshold = float(t[n - 1])
                return
            tau *= max(1.25, 1.1 * n / max(len(t), 1))
        raise ScatterError(f"{self.surface.source}: --stable found fewer than {n:,} arrivals")

    def _select_radius(self, radius, max_candidates):
        from .thinning import RADIUS_OVERSAMPLING

        # candidates at RADIUS_OVERSAMPLING times the hexagonal density of spacing R: a
        # time per unit area, the same for every face, so an edit moves only nearby points
        tau = RADIUS_OVERSAMPLING / (math.sqrt(3) / 2 * radius * radius)
        expected = tau * self.rate
        if max_candidates is not None and expected > max_candidates:
            raise ScatterUsageError(f"--radius {radius:g} is too small for {self.surface.source} (area "
                                    f"{self.area:.6g}): thinning would need {expected:,.0f} candidates, more than "
                                    f"{max_candidates:,}")
        self.horizon = tau
        self._select_before(tau)

    def _extend(self, stop):
        """Stream mode: find arrivals until there are at least ``stop``. Each stretch holds
        the arrivals between the last one's end time and a later time (all arrivals before
        that time, in order, less those before the end), so stretches only append."""
        with self._lock:
            while self._found < stop:
                first, end = (self._found, self._epochs[-1][1]) if self._epochs else (0, 0.0)
                want = max(2 * stop, 1 << 14)
                tau = max((want + 6.0 * math.sqrt(want) + 16.0) / self.rate, 2 * end)
                t, ids, bits, dup = self._sorted_arrivals(tau)
                if dup:
                    raise ScatterError(f"{self.surface.source}: --stable could not tell duplicate faces apart")
                later = int(np.searchsorted(t, end, side="left"))
                self._epochs.append((first, tau, ids[later:].copy() if later else ids, bits))

    @property
    def _found(self):
        return self._epochs[-1][0] + len(self._epochs[-1][2]) if self._epochs else 0

    def _stretches(self, start, stop):
        """[(ids, bits)] of arrivals ``start .. stop - 1``, stretch by stretch."""
        if self.count is None and self._found < stop:
            self._extend(stop)
        out = []
        for first, _, ids, bits in self._epochs:
            lo, hi = max(start, first), min(stop, first + len(ids))
            if lo < hi:
                out.append((ids[lo - first : hi - first], bits))
        return out or [(np.empty(0, np.uint64), COUNT_BITS + 1)]

    def _accept(self, ids, bits):
        """(m,) bool: texture-weighted arrivals that pass their rejection test."""
        raw = self._place(ids, bits, bary=True)
        used, ctr = unpack(ids, bits)
        u = to_unit(lane(self._state(used, ctr), (LANES * (ctr & np.uint64(31)) + np.uint64(4)).astype(np.uint64)))
        return self.weight.accept(raw, u)

    # -- points ------------------------------------------------------------------------

    def _state(self, used, ctr):
        return lane(self.table.key[used], (ctr >> np.uint64(COUNT_BITS)) + np.uint64(1))

    def ray_uniforms(self, start, stop):
        """(n, 3) uniforms in [0, 1) for arrivals ``start .. stop - 1`` from their own
        streams (lanes RAY_LANE + 4 j + k): the exterior filter's ray rotations, so an
        arrival's verdict does not depend on its place in the stream."""
        parts = []
        for ids, bits in self._stretches(start, stop):
            used, ctr = unpack(ids, bits)
            state = self._state(used, ctr)
            j = (ctr & np.uint64((1 << COUNT_BITS) - 1)) * np.uint64(LANES) + np.uint64(RAY_LANE)
            parts.append(np.stack([to_unit(lane(state, j + np.uint64(k))) for k in range(3)], axis=1))
        return np.concatenate(parts) if len(parts) > 1 else parts[0]

    def _place(self, ids, bits, start=0, bary=None):
        """The RawChunk of arrivals ``ids`` (n,) uint64."""
        want_bary = self.want_bary if bary is None else bary
        t = self.table
        if _kernel is not None and not self._barycentric and len(self.surface.instances) == 1:
            n = len(ids)
            points = np.empty((n, 3))
            b = np.empty((n, 2)) if want_bary else None
            face = np.empty(n, np.int64)
            g = self.surface.geometries[self.surface.instances[0].geometry]
            # in face order on a large mesh: arrival order reads the tables at random
            _kernel.place(np.ascontiguousarray(ids), bits, t.key, None if t.identity else t.face, g.faces,
                          t.world_vertices(0), t.corners, points, b, face, len(t) >= SORT_FACES)
            return self._finish(start, ids, bits, face, b, points, want_bary)
        used, ctr = unpack(ids, bits)
        state = self._state(used, ctr)
        j = (ctr & np.uint64((1 << COUNT_BITS) - 1)) * np.uint64(LANES)
        u = np.empty((len(used), 3 if self._barycentric else 2))
        for k in range(u.shape[1]):
            u[:, k] = to_unit(lane(state, j + np.uint64(2 + k)))
        if self._barycentric:
            w = _rotated_rows(self.weight.corner_weights(t.part[used], t.face[used]), t.rot[used], width=1)
            b = self.weight.barycentric(w, u)
        else:
            b = square_to_triangle(u)
        points = _interpolate(t.corner_columns(used), b)
        return self._finish(start, ids, bits, t.face[used], b, points, want_bary)

    def _finish(self, start, ids, bits, face, b, points, want_bary):
        t = self.table
        one = len(self.surface.instances) == 1
        used = None if one and not want_bary else (ids >> np.uint64(bits)).astype(np.int64)
        out_bary = None
        if want_bary:
            canon = np.empty((len(face), 3))
            canon[:, 1:] = b
            canon[:, 0] = 1.0 - b[:, 0] - b[:, 1]
            rot = t.rot[used].astype(np.int64)
            out_bary = np.empty_like(canon)
            rows = np.arange(len(face))
            for k in range(3):  # canonical corner k is the face's corner (k + rot) % 3
                out_bary[rows, (k + rot) % 3] = canon[:, k]
        if one:
            instance = np.broadcast_to(np.int64(0), (len(face),))  # one value, no memory
        else:
            instance = t.part[used].astype(np.int64)
        return RawChunk(start, points, face, instance, out_bary)

    @property
    def _barycentric(self):
        return self.weight is not None and hasattr(self.weight, "barycentric")

    def draw(self, start: int, stop: int) -> RawChunk:
        """Points ``start .. stop - 1`` in arrival order."""
        parts = [self._place(ids, bits) for ids, bits in self._stretches(start, stop)]
        out = RawChunk.join(parts)
        return RawChunk(start, out.points, out.face, out.instance, out.bary)


def pack(used, ctr, bits):
    """(n,) uint64 arrival ids ``used << bits | ctr``."""
    return (used.astype(np.uint64) << np.uint64(bits)) | ctr


def unpack(ids, bits):
    """(used face (n,) int64, counter (n,) uint64) of arrival ids."""
    return (ids >> np.uint64(bits)).astype(np.int64), ids & np.uint64((1 << bits) - 1)


class VertexColorRates:
    """``--weight vertex-color:C`` for the stable source: rate area times the face's mean
    weight, positions by the weighting's exact in-face mixture warp."""

    def __init__(self, weight):
        from . import weighting

        # {geometry: (F, 3) corner weights}, and the mixture warp (w (n, 3), u (n, 3)) -> (n, 2)
        self._w = weight.corner_w if hasattr(weight, "corner_w") else weight._corner_w
        self.barycentric = getattr(weighting, "barycentric", None) or weight.barycentric
        self.surface = weight.surface

    def face_weights_of(self, k, inst):
        return self._w[inst.geometry]

    def corner_weights(self, part, face):
        """(n, 3) corner weights of faces ``face`` (n,) of instances ``part`` (n,)."""
        out = np.empty((len(face), 3))
        for k in np.unique(part):
            rows = np.flatnonzero(part == k)
            out[rows] = self._w[self.surface.instances[k].geometry][face[rows]]
        return out


class TextureRates:
    """``--weight texture:C`` for the stable source: arrivals at rate area times the
    weight's bound over the geometry, each kept with probability weight / bound (a
    thinned Poisson process: rate area times weight, face by face)."""

    def __init__(self, weight):
        self._weight = weight
        self._bound = weight._bound
        self._inst_bound = np.array([weight._bound[i.geometry] for i in weight.surface.instances])

    def face_weights_of(self, k, inst):
        return np.full(len(self._weight.surface.geometries[inst.geometry].faces), self._bound[inst.geometry])

    def accept(self, raw, u):
        return u * self._inst_bound[raw.instance] < self._weight.weight(raw)


def stable_weight(surface, spec):
    """The stable source's form of ``--weight spec``."""
    from .weighting import TextureWeight, VertexColorWeight, parse_weight

    source, channel = parse_weight(spec)
    if source == "vertex-color":
        return VertexColorRates(VertexColorWeight(surface, channel, spec))
    return TextureRates(TextureWeight(surface, channel, spec))
