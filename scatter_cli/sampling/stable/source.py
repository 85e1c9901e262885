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

The modules: :mod:`~scatter_cli.sampling.stable.faces` (the keyed faces),
:mod:`~scatter_cli.sampling.stable.arrivals` (the arrival streams), :mod:`~scatter_cli.sampling.stable.order`
(arrival order), :mod:`~scatter_cli.sampling.stable.weights` (``--weight``),
:mod:`~scatter_cli.sampling.stable.thinning` (``--radius``); this one is the source.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from ...core import native
from ...errors import ScatterError
from ...core.hashing import lane, to_unit
from ..plan import SORT_FACES, RawChunk, interpolate_corners
from .arrivals import COUNT_BITS, LANES, RAY_LANE, all_arrivals, counter_bits, pack, unpack
from .faces import FaceTable, rotated_rows
from .order import has_duplicates, arrival_order, kernel_arrivals
from .thinning import radius_horizon
from ..warps import square_to_triangle

_kernel = native.kernel("_cstable")


class StableSource:
    """The ``--stable`` point source: ``draw(start, stop)`` gives arrivals start..stop-1 in
    arrival order (a pure function of the range).

    At most one of ``count`` (the N earliest arrivals), ``density`` (every arrival before
    time D), ``radius`` (every arrival before the candidate horizon of ``--radius R``:
    :func:`scatter_cli.sampling.poisson.thinning.dart_thrown` keeps the set) and ``stream=True`` (every arrival, without end:
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
                dup = has_duplicates(t, *unpack(ids, bits), key)
            return t, ids, bits, dup
        t, face, ctr = all_arrivals(self.table, tau)
        if self._accepts:
            keep = self._accept(pack(face, ctr, bits), bits)
            t, face, ctr = t[keep], face[keep], ctr[keep]
        order = arrival_order(t, face, ctr, key)
        t, face, ctr = t[order], face[order], ctr[order]
        return t, pack(face, ctr, bits), bits, has_duplicates(t, face, ctr, key)

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
        self.horizon = radius_horizon(radius, self.rate, self.area, self.surface.source, max_candidates)
        self._select_before(self.horizon)

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
            w = rotated_rows(self.weight.corner_weights(t.part[used], t.face[used]), t.rot[used], width=1)
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


def _interpolate(cols, b):
    """(n, 3) float64 points ``v0 + b1 (v1 - v0) + b2 (v2 - v0)`` from 9 corner columns
    (n,), rounded as the random method's (sampling.interpolate_corners)."""
    points = np.empty((len(b), 3))
    interpolate_corners(cols, np.ascontiguousarray(b[:, 0]), np.ascontiguousarray(b[:, 1]), points)
    return points
