"""Faces certainly hidden: enclosed by a closed shell of the surface, clear of it.

Every ray from such a face hits the shell, so its candidates need no ray: the verdict
is the one the rays would give (docs/exterior.md, "Enclosed faces"). The reasoning:

- A *shell* is a connected set of faces (vertices of equal coordinates welded) whose
  every edge is used an even number of times: a closed surface, counted mod 2.
- A point off a shell has a *parity*: the number of times any path from it to infinity
  crosses the shell, mod 2 (the same for every path in general position). A point of odd
  parity is enclosed: every ray from it meets the shell.
- A grid of cells covers the scene. A cell that no face of shell S can touch (the
  bounding boxes of S's faces miss it) has one parity with respect to S; it is found by
  counting, in float64, the crossings of S with a line through the cell along x, from
  outside the grid. A line that passes within rounding of an edge of S says nothing.
- A face is enclosed when every cell its bounding box, grown by twice the rays' offset,
  touches is a cell of odd parity for some shell that does not touch the cell: then the
  face and the start of every ray cast from it lie inside that shell.

Faces of shells that cross, touch or come closer to another than a cell are not
enclosed (their candidates are cast as before); so are faces inside surfaces that are
not closed; so are faces with a coordinate beyond ``LIMIT`` in magnitude, and every face
when the grid's cells are no wider than the rays' offset. Nothing here calls Embree.

The compiled kernel ``_cenclosure`` does the same integer and float64 operations in the
same order (tests/test_enclosure_native.py holds the two to the same faces).
"""

from __future__ import annotations

import numpy as np

from ...core import native
from ...core.hashing import mix

_kernel = native.kernel("_cenclosure")

# Cells along the longest side of the scene's box: about 4 (cube root of the faces),
# within these bounds.
GRID = (16, 128)
# Shells considered (one bit each in a uint64 mask): the largest boxes first.
MAX_SHELLS = 63
# Line probes sit at these fractions of a cell (irrational: off the round coordinates of
# axis-aligned models).
PROBE = (0.41421356237309503, 0.7320508075688772, 0.2360679774997898)
# Faces with a coordinate beyond this (or not finite) belong to no shell and are not
# enclosed: every product below then stays finite.
LIMIT = 1e100


def components(count: int, a, b) -> np.ndarray:
    """(count,) int64 label of the connected component of each node (one of its nodes);
    ``a``, ``b`` (m,) the links."""
    label = np.arange(count)
    while True:
        la, lb = label[a], label[b]
        split = la != lb
        if not split.any():
            return label
        la, lb = la[split], lb[split]
        np.minimum.at(label, np.maximum(la, lb), np.minimum(la, lb))  # roots hook to their smallest neighbour
        a, b = a[split], b[split]
        while True:
            up = label[label]
            if np.array_equal(up, label):
                break
            label = up


def weld(vertices) -> np.ndarray:
    """(V,) int64: one id per distinct row of ``vertices`` (V, 3) float64 (bitwise equal)."""
    bits = np.ascontiguousarray(vertices).view(np.uint64)
    with np.errstate(over="ignore"):
        h = mix(mix(mix(bits[:, 0].copy()) ^ bits[:, 1]) ^ bits[:, 2])
    order = np.argsort(h)
    rows = bits[order]
    same_row = (rows[1:] == rows[:-1]).all(axis=1)
    hs = h[order]
    if np.any((hs[1:] == hs[:-1]) & ~same_row):  # a hash collision: sort the rows themselves
        order = np.lexsort(bits.T[::-1])
        rows = bits[order]
        same_row = (rows[1:] == rows[:-1]).all(axis=1)
    ids = np.empty(len(vertices), np.int64)
    ids[order] = np.cumsum(np.r_[True, ~same_row]) - 1
    return ids


def closed_parts(vertices, faces):
    """Connected parts of one geometry and which of them are closed.

    vertices (V, 3) float64, faces (F, 3) int64 -> (part (F,) int64 ids 0..P-1,
    closed (P,) bool: each of its edges used an even number of times, every vertex
    finite). Vertices of equal coordinates are one (welded, unless the faces' own
    indices already close every part)."""
    if not len(faces):
        return np.zeros(0, np.int64), np.zeros(0, bool)
    shared = len(vertices) < 2 * len(faces)  # an indexed mesh, not a triangle soup
    part, closed = _parts(len(vertices) if shared else weld(vertices), faces)
    if shared and not closed.all():
        part, closed = _parts(weld(vertices), faces)
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        closed[part[~finite[faces].all(axis=1)]] = False
    return part, closed


def _parts(ids, faces):
    """closed_parts for vertex ids ``ids`` (V,) int64 (equal ids: one vertex), or for
    ``ids`` V vertices, each its own."""
    faces = np.ascontiguousarray(faces, np.int64)
    count = ids if isinstance(ids, int) else len(ids)
    if _kernel is not None and count < 2**32:  # (the kernel numbers vertices in 32 bits)
        return _kernel.parts(ids if isinstance(ids, int) else np.ascontiguousarray(ids, np.int64), faces,
                             native.worker_count())
    if isinstance(ids, int):
        ids = np.arange(ids)
    w = ids[faces]
    size = int(ids.max()) + 1
    key = np.concatenate([np.minimum(w[:, i], w[:, j]) * size + np.maximum(w[:, i], w[:, j])
                          for i, j in ((0, 1), (1, 2), (2, 0))])
    key.sort()
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    edges = key[starts]
    label = components(size, edges // size, edges % size)
    roots, vertex_part = np.unique(label, return_inverse=True)
    closed = np.ones(len(roots), bool)
    odd = np.diff(np.r_[starts, len(key)]) % 2 == 1
    closed[vertex_part[edges[odd] // size]] = False
    return vertex_part[w[:, 0]], closed


class Grid:
    """Cells of side ``step`` from ``origin`` (3,), ``shape`` (3,) of them, one spare
    cell round the box lo..hi."""

    def __init__(self, lo, hi, cells):
        self.step = float(max(np.max(hi - lo), 1e-300)) / cells
        self.origin = lo - self.step
        self.shape = tuple(int(v) for v in np.ceil((hi - lo) / self.step) + 3)

    def ranges(self, lo, hi, grow=0.0):
        """(n, 3) first and (n, 3) last cell touched by the boxes lo..hi (n, 3) grown by ``grow``."""
        top = np.array(self.shape) - 1
        first = np.floor((lo - grow - self.origin) / self.step).astype(np.int64)
        last = np.floor((hi + grow - self.origin) / self.step).astype(np.int64)
        return np.clip(first, 0, top), np.clip(last, 0, top)


def corner_sum(first, last):
    """The 8 corners of boxes of cells first .. last (n, 3) for a summed-area table:
    ((8, 3, n) indices, (8,) signs)."""
    at, sign = [], []
    for corner in range(8):
        pick = [(corner >> k) & 1 for k in range(3)]
        at.append([np.where(pick[k], last[:, k] + 1, first[:, k]) for k in range(3)])
        sign.append((-1) ** (3 - sum(pick)))
    return at, sign


def box_cover(shape, first, last):
    """(shape) bool: cells covered by any of the boxes of cells first .. last (n, 3)."""
    ext = tuple(v + 1 for v in shape)
    at, sign = corner_sum(first, last)
    flat = np.concatenate([np.ravel_multi_index(c, ext) for c in at])
    weight = np.repeat(-np.array(sign, np.float64), len(first))  # a difference array: +1 at first
    diff = np.bincount(flat, weights=weight, minlength=int(np.prod(ext))).reshape(ext)
    for k in range(3):
        np.cumsum(diff, axis=k, out=diff)
    return diff[: shape[0], : shape[1], : shape[2]] > 0.5


def point_cover(shape, cells):
    """(shape) bool: the cells ``cells`` (n, 3) and their 26 neighbours."""
    hit = np.zeros(int(np.prod(shape)), bool)
    hit[np.ravel_multi_index(cells.T, shape)] = True
    hit = hit.reshape(shape)
    for k in range(3):
        grown = hit.copy()
        lead = [slice(None)] * 3
        lag = [slice(None)] * 3
        lead[k], lag[k] = slice(1, None), slice(None, -1)
        grown[tuple(lead)] |= hit[tuple(lag)]
        grown[tuple(lag)] |= hit[tuple(lead)]
        hit = grown
    return hit


def shell_cover(grid, vertex_cells, faces, lo, hi, box_lo, box_hi, grow):
    """(slices, (shape) bool): the cells that faces (F, 3) of boxes lo..hi (F, 3), grown
    by ``grow``, may touch, within the box of cells ``slices`` (that of box_lo..box_hi).
    A face no wider than a cell less ``grow`` touches only its corners' cells and their
    neighbours; ``vertex_cells`` (V, 3) is each vertex's cell."""
    first, last = grid.ranges(box_lo[None], box_hi[None], grow)
    base, top = first[0], last[0] + 1
    shape = tuple(int(v) for v in top - base)
    small = (hi - lo).max(axis=1) <= grid.step - grow
    used = np.zeros(len(vertex_cells), bool)
    used[faces[small].reshape(-1)] = True
    cover = point_cover(shape, np.clip(vertex_cells[used] - base, 0, np.array(shape) - 1))
    if not small.all():
        a, b = grid.ranges(lo[~small], hi[~small], grow)
        cover |= box_cover(shape, a - base, b - base)
    return tuple(slice(p, q) for p, q in zip(base, top)), cover


def bounds(vertices, faces):
    """(F, 3) lower and (F, 3) upper corners of the boxes of faces (F, 3) of ``vertices`` (V, 3)."""
    lo = np.take(vertices, faces[:, 0], axis=0)
    hi = lo.copy()
    corner = np.empty_like(lo)
    for k in (1, 2):
        np.take(vertices, faces[:, k], axis=0, out=corner)
        np.minimum(lo, corner, out=lo)
        np.maximum(hi, corner, out=hi)
    return lo, hi


def crossings(grid, vertices, faces, lo, hi):
    """Where lines along x cross faces (F, 3) of ``vertices`` (V, 3), of boxes lo..hi (F, 3): (line (m,)
    int64 = j * shape[2] + k, x (m,) float64 from the grid's origin, unsure lines (L,)
    int64: lines that pass within rounding of an edge, or along a face)."""
    s, o = grid.step, grid.origin
    nz = grid.shape[2]
    j0 = np.ceil((lo[:, 1] - o[1]) / s - PROBE[1]).astype(np.int64)
    j1 = np.floor((hi[:, 1] - o[1]) / s - PROBE[1]).astype(np.int64)
    k0 = np.ceil((lo[:, 2] - o[2]) / s - PROBE[2]).astype(np.int64)
    k1 = np.floor((hi[:, 2] - o[2]) / s - PROBE[2]).astype(np.int64)
    cj, ck = np.maximum(j1 - j0 + 1, 0), np.maximum(k1 - k0 + 1, 0)
    per = cj * ck
    t = np.repeat(np.arange(len(faces)), per)
    rank = np.arange(len(t)) - np.repeat(np.cumsum(per) - per, per)
    j = j0[t] + rank // ck[t]
    k = k0[t] + rank % ck[t]
    y, z = (j + PROBE[1]) * s, (k + PROBE[2]) * s
    near = vertices[faces[t]] - o  # small coordinates: the orientation tests' rounding stays far below tol
    a, b, c = near[:, 0], near[:, 1], near[:, 2]

    def orient(p, q):  # twice the signed area of (p, q, (y, z)) in the yz plane
        return (q[:, 1] - p[:, 1]) * (z - p[:, 2]) - (q[:, 2] - p[:, 2]) * (y - p[:, 1])

    d = np.stack([orient(b, c), orient(c, a), orient(a, b)], axis=1)
    edge = np.abs(near[:, :, 1:] - near[:, [1, 2, 0], 1:]).max(axis=(1, 2))
    tol = (np.maximum(edge, 1e-300) * s * 1e-9)[:, None]
    inside = (d > tol).all(axis=1) | (d < -tol).all(axis=1)
    touch = ((d >= -tol).all(axis=1) | (d <= tol).all(axis=1)) & ~inside
    line = j * nz + k
    d, nx_ = d[inside], near[inside][:, :, 0]
    x = (d[:, 0] * nx_[:, 0] + d[:, 1] * nx_[:, 1] + d[:, 2] * nx_[:, 2]) / (d[:, 0] + d[:, 1] + d[:, 2])
    return line[inside], x, np.unique(line[touch])


def line_parity(grid, line, x, bits):
    """(shape) uint64: for each cell, the XOR of the bits of the crossings on its line
    (along x) before its probe point."""
    nx, ny, nz = grid.shape
    width = nx + 2.0
    key = line + x / grid.step / width
    order = np.argsort(key)
    key = key[order]
    prefix = np.zeros(len(key) + 1, np.uint64)
    np.bitwise_xor.accumulate(bits[order], out=prefix[1:])
    cells = np.arange(ny * nz)[:, None] + (np.arange(nx)[None, :] + PROBE[0]) / width
    before = np.searchsorted(key, cells)
    start = np.searchsorted(key, np.arange(ny * nz, dtype=np.float64))[:, None]
    return (prefix[before] ^ prefix[start]).reshape(ny, nz, nx).transpose(2, 0, 1)


def enclosed_faces(vertices, faces, part, closed, offset):
    """(F,) bool: faces certainly hidden (see the module's docstring).

    vertices (V, 3) float64 in world space, faces (F, 3) int64; part (F,) int64 their
    part (a shell when ``closed[part]``); offset: how far off its face a ray starts."""
    cells = int(np.clip(4 * round(len(faces) ** (1 / 3)), *GRID))
    if _kernel is not None:
        out = np.zeros(len(faces), np.uint8)
        _kernel.enclosed(np.ascontiguousarray(vertices, np.float64), np.ascontiguousarray(faces, np.int64),
                         np.ascontiguousarray(part, np.int64), np.ascontiguousarray(closed, np.uint8),
                         float(offset), cells, MAX_SHELLS, *PROBE, LIMIT, native.worker_count(), out)
        return out.view(bool)
    out = np.zeros(len(faces), bool)
    order = None
    if np.any(part[1:] < part[:-1]):  # each part's faces in one run
        order = np.argsort(part, kind="stable")
        faces, part = faces[order], part[order]
    lo, hi = bounds(vertices, faces)
    usable = (np.abs(vertices) <= LIMIT).all(axis=1)  # NaN: False
    finite = np.ones(len(faces), bool) if usable.all() else usable[faces].all(axis=1)
    starts = np.flatnonzero(np.r_[True, part[1:] != part[:-1]])
    ends = np.r_[starts[1:], len(part)]
    shell = closed[part[starts]] & np.logical_and.reduceat(finite, starts)
    if not shell.any():
        return out
    slo = np.minimum.reduceat(lo, starts)
    shi = np.maximum.reduceat(hi, starts)
    shells = np.flatnonzero(shell)
    shells = shells[np.lexsort((shells, -np.prod(shi[shells] - slo[shells], axis=1)))[:MAX_SHELLS]]
    # a face can be enclosed only by a shell other than its own whose box holds its box
    maybe = np.zeros(len(faces), bool)
    for i in shells:
        inside = (lo > slo[i]).all(axis=1) & (hi < shi[i]).all(axis=1)
        inside[starts[i]:ends[i]] = False
        maybe |= inside
    maybe &= finite
    if not maybe.any():
        return out
    grid = Grid(slo[shell].min(axis=0), shi[shell].max(axis=0), cells)
    grow = 2.0 * offset + 1e-9 * grid.step
    if not grow < grid.step:  # cells finer than the rays' offset resolve nothing
        return out
    cover = np.zeros(grid.shape, np.uint64)
    with np.errstate(invalid="ignore", over="ignore"):
        vertex_cells = np.floor((np.where(usable[:, None], vertices, 0.0) - grid.origin) / grid.step).astype(np.int64)
    lines, xs, bits, unsure = [], [], [], []
    for bit, i in enumerate(shells):
        mine = slice(starts[i], ends[i])
        box, mask = shell_cover(grid, vertex_cells, faces[mine], lo[mine], hi[mine], slo[i], shi[i], grow)
        cover[box] |= np.where(mask, np.uint64(1 << bit), np.uint64(0))
        line, x, bad = crossings(grid, vertices, faces[mine], lo[mine], hi[mine])
        lines.append(line)
        xs.append(x)
        bits.append(np.full(len(line), 1 << bit, np.uint64))
        unsure.append(bad)
    parity = line_parity(grid, np.concatenate(lines), np.concatenate(xs), np.concatenate(bits))
    hidden = np.ascontiguousarray((parity & ~cover) != 0)
    hidden.reshape(grid.shape[0], -1)[:, np.unique(np.concatenate(unsure))] = False
    table = np.zeros(tuple(v + 1 for v in grid.shape), np.int64)
    table[1:, 1:, 1:] = hidden.cumsum(axis=0).cumsum(axis=1).cumsum(axis=2)
    idx = np.flatnonzero(maybe)
    a, b = grid.ranges(lo[idx], hi[idx], grow)
    at, sign = corner_sum(a, b)
    total = sum(table[tuple(c)] * sg for c, sg in zip(at, sign))
    out[idx if order is None else order[idx]] = total == np.prod(b - a + 1, axis=1)
    return out
