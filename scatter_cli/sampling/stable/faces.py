"""The faces of a ``--stable`` run, keyed: each usable face in world space, its key
hashed from the seed and its world-space corners (rotated to start at the smallest
corner, so a renumbered or rotated face keeps its key; a mirrored winding is another
face), and its rate (area, times its mean weight under ``--weight``).
"""

from __future__ import annotations

import math

import numpy as np

from ...core import native
from ...surface.areas import doubled_areas
from ...errors import ScatterError
from ...core.hashing import GOLDEN, lane, mix, seed_word
from ...core.native import in_blocks
from ..plan import DEFAULT_CHUNK, LARGE_MESH_CHUNK, SORT_FACES
from ...surface.model import apply_matrix

_G = np.uint64(GOLDEN)
FACE_BLOCK = 1 << 16  # faces keyed at a time
_kernel = native.kernel("_cstable")


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
        from ..plan import Part

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
    r = rotated_rows(w, rot, width=1)
    return (r[:, 0] + r[:, 1] + r[:, 2]) / 3.0


def rotated_rows(tri, rot, width=3):
    """Rows of ``tri`` (n, 3 width) with their corners rotated to start at ``rot`` (n,)."""
    rot = rot.astype(np.int64)
    rows = np.arange(len(tri))[:, None]
    cols = ((rot[:, None] + np.arange(3)) % 3)[:, :, None] * width + np.arange(width)
    return tri[rows, cols.reshape(len(tri), 3 * width)]
