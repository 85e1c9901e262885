"""The exterior source: the points of another source that can be seen from outside.

Candidates come from the underlying source's stream in fixed blocks of ``BLOCK`` (a
constant: not the chunk size, not the thread count). Each candidate is classified by
rays (:mod:`.visibility`) with a rotation drawn from its own index, so a block's verdicts
are a pure function of the seed and the block. A first pass classifies blocks in order
until N exterior candidates are found and keeps one bit a candidate; point ``j`` of the
output is then the ``j``-th exterior candidate in stream order, and ``draw(start, stop)``
redraws only the blocks holding that range.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...core import native
from ...errors import ScatterError
from ..plan import RawChunk

BLOCK = 1 << 14
_TAG = 0x4558_5452  # key of the rotation stream: independent of the sampling streams
# When this many candidates in a row are all hidden, the surface has no exterior part
# that sampling can find.
GIVE_UP = 1 << 20
# Look for enclosed faces (:mod:`.enclosure`: their candidates then cast no ray) when
# the hidden candidates the first block predicts for the run number at least the faces
# over this: finding them costs about as much, a face, as 66 rays over this (measured).
ENCLOSE_FACES_PER_HIDDEN = 80
# The pass keeps the exterior candidates it finds, for the output, while they number at
# most this many (64 MB of chunks); past it the output draws them again (flat memory).
KEEP_POINTS = 1 << 20


class ShortStream(ScatterError):
    """A bounded underlying source (``candidates`` given with ``count``) held fewer than
    ``count`` exterior points: ask again with more candidates."""


def rotation_uniforms(seed: int, start: int, stop: int):
    """(n, 3) uniforms in [0, 1) for candidates ``start .. stop - 1``: their ray rotations."""
    bits = np.random.PCG64DXSM(np.random.SeedSequence([_TAG, seed]))
    bits.advance(3 * int(start))
    return np.random.Generator(bits).random((stop - start, 3))


def classify(occluder, chunk: RawChunk, seed: int, u=None, escaped=None, rows=None):
    """((n,) bool exterior, rays cast) for the candidates of ``chunk``; ``u`` (n, 3): their
    ray rotations' uniforms, when the source draws them (else from the candidate's index);
    ``escaped``: their normal rays' verdicts, when already cast (for every candidate not
    enclosed); ``rows`` (n,): their faces' rows in the occluder, when known."""
    rows = occluder.rows(chunk.face, chunk.instance) if rows is None else rows
    enclosed = None if occluder.enclosed is None else occluder.enclosed[rows]
    if u is None:
        u = lambda: rotation_uniforms(seed, chunk.start, chunk.start + len(chunk.points))  # noqa: E731
    if escaped is None or not occluder.normal_rays:
        return occluder.exterior(chunk.points, np.take(occluder.normals, rows, axis=0), u, enclosed)
    cast = np.ones(len(rows), bool) if enclosed is None else ~enclosed
    out = escaped & cast
    rays = int(np.count_nonzero(cast))
    rest = np.flatnonzero(cast & ~escaped)  # only these go on, from the opposite normal
    if len(rest):
        points, normals = np.take(chunk.points, rest, axis=0), np.take(occluder.normals, rows[rest], axis=0)
        more, extra = occluder.exterior(points, normals, lambda: (u() if callable(u) else u)[rest], normal_blocked=True)
        out[rest] = more
        rays += extra
    return out, rays


class ExteriorSource:
    """The exterior candidates of ``base`` (anything with ``draw(start, stop) -> RawChunk``
    over an unbounded stream of candidates), in stream order.

    ``count``: exactly this many points; ``candidates``: look no further than the first
    ``candidates`` (alone: keep every exterior one among them, a ``--density`` run; with
    ``count``, over a bounded source: :class:`ShortStream` when they hold fewer).
    ``area`` is the estimated exterior area, ``stats`` what the pass found.
    """

    kept = None  # (the Source protocol: filtered, not thinned)

    def __init__(self, base, occluder, seed, total_area, count=None, candidates=None, threads=None):
        self.base, self.occluder, self.seed = base, occluder, seed
        t = time.perf_counter()
        self.enclosure_seconds = 0.0
        self._bits, self._sizes, kept, rays = [], [], [0], 0
        self._found = []  # the exterior candidates of each block, while they fit KEEP_POINTS
        self._round = None  # (faces, points, escaped) of a round's candidates
        limit = math.inf if candidates is None else candidates
        threads = threads or native.worker_count()
        faces_total = len(occluder.normals)
        hit_faces = np.zeros(faces_total, dtype=bool)
        tried_faces = np.zeros(faces_total, dtype=bool)
        with native.thread_pool(threads) as pool:
            if occluder.enclosed is None:
                rays += self._enclose_if_worth_it(pool, threads, count, limit)
            block = 0
            while (count is None or kept[-1] < count) and block * BLOCK < limit:
                group = [b for b in range(block, block + self._blocks_to_go(count, kept[-1], block, threads))
                         if b * BLOCK < limit]
                for bits, size, found, chunk_rays, faces, hit in self._classify_round(pool, group, limit, threads):
                    if count is not None and kept[-1] >= count:
                        break  # blocks past the N-th exterior candidate: the thread count's, not the run's
                    self._bits.append(bits)
                    self._sizes.append(size)
                    kept.append(kept[-1] + len(found.face))
                    if self._found is not None and kept[-1] > KEEP_POINTS:
                        self._found = None
                    elif self._found is not None:
                        self._found.append(found)
                    rays += chunk_rays
                    tried_faces[faces] = True
                    hit_faces[hit] = True
                block += len(group)
                if kept[-1] == 0 and block * BLOCK >= GIVE_UP:
                    raise ScatterError(f"no exterior surface found: the first {block * BLOCK:,} candidates are all hidden")
        self._kept = np.asarray(kept, dtype=np.int64)
        self._round = None
        if count is not None and kept[-1] < count:
            raise ShortStream(f"{kept[-1]:,} exterior points among {limit:,} candidates, not {count:,}")
        tried = sum(self._sizes)
        self.count = int(self._kept[-1]) if count is None else count
        p = self._kept[-1] / tried if tried else 0.0
        self.area = float(total_area * p)
        self.stats = {
            "exterior_area": self.area,
            "exterior_area_se": total_area * math.sqrt(p * (1 - p) / tried) if tried else 0.0,
            "exterior_fraction": float(p),
            "candidates": int(tried),
            "exterior_candidates": int(self._kept[-1]),
            "rays": int(rays),
            "rays_per_candidate": rays / tried if tried else 0.0,
            "faces_seen_exterior": int(np.count_nonzero(hit_faces)),
            "faces_seen_hidden_only": int(np.count_nonzero(tried_faces & ~hit_faces)),
            "faces_enclosed": 0 if occluder.enclosed is None else int(np.count_nonzero(occluder.enclosed)),
            "seconds": time.perf_counter() - t,
        }

    def _enclose_if_worth_it(self, pool, threads, count, limit):
        """Find the enclosed faces when the hidden candidates that the first block
        predicts for the run justify it; the prediction counts the block's candidates
        whose two normal rays are both blocked (a few of those may yet get out; cast in
        face order on the pool, as the pass casts them). Returns the rays cast."""
        stop = int(min(BLOCK, limit))
        if stop <= 0:
            return 0
        chunk = self.base.draw(0, stop)
        rows = self.occluder.rows(chunk.face, chunk.instance)
        order = np.argsort(_face_buckets(rows, len(self.occluder.normals)), kind="stable")
        points = np.take(chunk.points, order, axis=0)
        normals = np.take(self.occluder.normals, rows[order], axis=0)
        parts = list(pool.map(lambda i: self.occluder.normals_blocked(points[i], normals[i]),
                              np.array_split(np.arange(stop), native.PIECES_PER_THREAD * threads)))
        hidden = sum(int(np.count_nonzero(blocked)) for blocked, _ in parts)
        rays = sum(r for _, r in parts)
        total = limit if count is None else min(limit, count * stop / max(stop - hidden, 1))
        if hidden and hidden / stop * total * ENCLOSE_FACES_PER_HIDDEN >= len(self.occluder.normals):
            t = time.perf_counter()
            self.occluder.enclose()
            self.enclosure_seconds = time.perf_counter() - t
        return rays

    @staticmethod
    def _blocks_to_go(count, kept, done, threads):
        """Blocks for the next round of the pass: about what the rate so far says is left
        (a few more), at most 16 a thread; in the first, no more than the count would fill
        if every candidate were exterior (the rays of a round are cut among the threads
        whatever its blocks: many threads must not draw blocks a small count never uses)."""
        if count is None or (done and not kept):
            return threads
        if not done:
            return max(1, min(threads, math.ceil(count / BLOCK)))
        need = (count - kept) * done / kept * 1.05 + 1
        return max(1, min(16 * threads, math.ceil(need)))

    def _classify_round(self, pool, group, limit, threads):
        """What :meth:`_finish_block` gives for each block of ``group``, classified on the pool. The
        normal rays of all the round's candidates go first, together and in face order:
        nearby rays then share Embree's caches (docs/exterior.md, "Speed"); the order
        changes no verdict."""
        drawn = list(pool.map(lambda b: self._draw_block(b, limit), group))
        occluder = self.occluder
        if not occluder.normal_rays or not drawn:
            return pool.map(lambda d: self._finish_block(*d), drawn)
        count = sum(len(d[2]) for d in drawn)
        if self._round is None or len(self._round[0]) < count:  # kept for the next rounds: fresh memory is dear
            self._round = np.empty(count, np.int64), np.empty((count, 3)), np.empty(count, bool)
        faces, points, escaped = (a[:count] for a in self._round)
        np.concatenate([d[2] for d in drawn], out=faces)
        np.concatenate([d[0].points for d in drawn], out=points)
        todo = np.arange(count) if occluder.enclosed is None else np.flatnonzero(~occluder.enclosed[faces])
        order = todo[np.argsort(_face_buckets(faces[todo], len(occluder.normals)), kind="stable")]
        escaped[:] = False

        def cast(idx):  # in batches of one block: small temporaries, reused
            for k in range(0, len(idx), BLOCK):
                i = idx[k:k + BLOCK]
                escaped[i] = occluder.normal_escapes(np.take(points, i, axis=0),
                                                     np.take(occluder.normals, faces[i], axis=0))

        list(pool.map(cast, np.array_split(order, native.PIECES_PER_THREAD * threads)))
        cuts = np.cumsum([0] + [len(d[2]) for d in drawn])
        return pool.map(lambda k: self._finish_block(*drawn[k], escaped[cuts[k]:cuts[k + 1]]), range(len(drawn)))

    def _draw_block(self, b, limit):
        """(chunk, ray uniforms or None, (n,) faces' rows in the occluder) of block ``b``."""
        start, stop = b * BLOCK, int(min((b + 1) * BLOCK, limit))
        chunk = self.base.draw(start, stop)
        # a source whose candidates carry their own streams (--stable) draws their rotations
        u = self.base.ray_uniforms(start, stop) if hasattr(self.base, "ray_uniforms") else None
        return chunk, u, self.occluder.rows(chunk.face, chunk.instance)

    def _finish_block(self, chunk, u, faces, escaped=None):
        """(packed verdicts, candidates, the exterior ones (a chunk), rays cast, (n,)
        faces' rows, the exterior ones' rows) of one block."""
        mask, rays = classify(self.occluder, chunk, self.seed, u, escaped, faces)
        found = np.flatnonzero(mask)
        return np.packbits(mask), len(mask), chunk.take(found), rays, faces, faces[found]

    def draw(self, start: int, stop: int) -> RawChunk:
        """Exterior points ``start .. stop - 1`` (the ``j``-th exterior candidate is point j)."""
        first = int(np.searchsorted(self._kept, start, side="right")) - 1
        last = max(first, int(np.searchsorted(self._kept, stop - 1, side="right")) - 1)
        parts = []
        for b in range(first, min(last, len(self._bits) - 1) + 1):
            rows = slice(max(start - self._kept[b], 0), stop - self._kept[b])
            if self._found is not None:
                parts.append(self._found[b].slice(rows.start, rows.stop))
                continue
            mask = np.unpackbits(self._bits[b], count=self._sizes[b]).view(bool)
            chunk = self.base.draw(b * BLOCK, b * BLOCK + self._sizes[b])
            parts.append(chunk.take(np.flatnonzero(mask)[rows]))
        out = RawChunk.join(parts) if parts else self.base.draw(0, 0)
        return RawChunk(start, out.points, out.face, out.instance, out.bary)


def _face_buckets(faces, count):
    """(n,) uint16 keys of faces (n,) int64 in 0 .. count - 1: the face over 2**k, the
    smallest k that fits 16 bits (NumPy sorts them stably by radix: neighbouring rays
    stay together, which is all the sort is for)."""
    shift = max(0, int(count - 1).bit_length() - 16)
    return (faces >> shift).astype(np.uint16)


_SUBSET_TAG = 0x4558_5355  # key of the subset choice: independent of the other streams


class ExteriorSubset:
    """Exactly ``count`` exterior points from a source whose points depend on its count
    (``--method stratified``): the exterior candidates of the run of M that
    ``source_of(M)`` gives (M = ``count``, then, while they are fewer than ``count``, M
    grown by the fraction found, plus 2 %), then ``count`` of them chosen uniformly at
    random without replacement (keyed by the seed), kept in stream order.
    """

    kept = None

    def __init__(self, source_of, occluder, seed, total_area, count, threads=None):
        m, passes = max(count, 1), 0
        while True:
            self.inner = ExteriorSource(source_of(m), occluder, seed, total_area, candidates=m, threads=threads)
            passes += 1
            found = self.inner.count
            if found >= count:
                break
            if found == 0 and m >= GIVE_UP:
                raise ScatterError(f"no exterior surface found: the {m:,} candidates are all hidden")
            m = math.ceil(m * count / max(found, 1) * 1.02) + 64
        bits = np.random.PCG64DXSM(np.random.SeedSequence([_SUBSET_TAG, seed]))
        self.chosen = np.sort(np.random.Generator(bits).choice(found, count, replace=False))
        self.count, self.area = count, self.inner.area
        self.enclosure_seconds = self.inner.enclosure_seconds
        self.stats = dict(self.inner.stats, candidate_runs=passes)

    def draw(self, start: int, stop: int) -> RawChunk:
        """Output points ``start .. stop - 1``."""
        pick = self.chosen[start:stop]
        if not len(pick):
            out = self.inner.draw(0, 0)
        else:
            out = self.inner.draw(int(pick[0]), int(pick[-1]) + 1).take(pick - pick[0])
        return RawChunk(start, out.points, out.face, out.instance, out.bary)
