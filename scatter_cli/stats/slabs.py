"""The heights along a direction where the area of a surface below reaches given values:
the edges of ``scatter check``'s exact equal-area slabs, and the exact area below them.

Faces come as sorted vertex heights ``h`` ``(F, 3) float64`` (h0 <= h1 <= h2 per row) and
``areas`` ``(F,) float64``. The area of a face below height t is a closed form
(:func:`below_fraction`), so the area function A(t) of the surface is piecewise
quadratic. :func:`solve_heights` starts from a guess (each face's area spread evenly over
its heights, on a grid: one pass), brackets each target between two exact values,
and refines by Newton steps on the exact A and its derivative, halving where a step
leaves the bracket; the faces of each bracket are gathered once and narrowed as it
shrinks (:class:`_Pairs`).
"""

import numpy as np

# Upper bound on the entries of one work array of (target, face) pairs.
CHUNK_ENTRIES = 1 << 21
# Grid of the first guess, the half-width of the first brackets in its steps, and the
# faces it looks at (every j-th face, so that about GUESS_FACES remain).
GUESS_BINS = 1024
GUESS_HALF_WIDTH = 3
GUESS_FACES = 1 << 15


def below_fraction(h0, h1, h2, t):
    """Fraction of a triangle with sorted vertex heights h0 <= h1 <= h2 lying
    at height <= t (all arguments broadcast)."""
    # Each branch is used only where its denominator is positive (h0 <= t < h1
    # needs h1 > h0; h1 <= t < h2 needs h2 > h1), so the substituted 1.0 never
    # reaches the result; a face flat in the direction becomes a step.
    den_lo = (h1 - h0) * (h2 - h0)
    den_hi = (h2 - h0) * (h2 - h1)
    lower = (t - h0) ** 2 / np.where(den_lo > 0, den_lo, 1.0)
    upper = 1.0 - (h2 - t) ** 2 / np.where(den_hi > 0, den_hi, 1.0)
    return np.where(t >= h2, 1.0, np.where(t >= h1, upper, np.where(t >= h0, lower, 0.0)))


def below_density(h0, h1, h2, t):
    """The derivative in t of :func:`below_fraction` (0 at a step)."""
    den_lo = (h1 - h0) * (h2 - h0)
    den_hi = (h2 - h0) * (h2 - h1)
    lower = 2.0 * (t - h0) / np.where(den_lo > 0, den_lo, 1.0)
    upper = 2.0 * (h2 - t) / np.where(den_hi > 0, den_hi, 1.0)
    return np.where(t >= h2, 0.0, np.where(t >= h1, upper, np.where(t >= h0, lower, 0.0)))


def solve_heights(h, areas, targets, iterations, pad=0.0):
    """Heights hi (m,) where the area function reaches targets (m,, ascending, each
    strictly between 0 and the total area) — A(hi) >= target, within 2^-iterations of
    the mean slab area (total / (m + 1)) above it, or, where A jumps past the target (a
    face flat in the direction), within 2^-iterations of the first bracket above the
    jump — and the exact area function (face by face) for heights (m,) each between its
    bracket's low end and ``pad`` above hi. At least every second step halves a
    bracket, so 2 ``iterations`` steps at most."""
    targets = np.asarray(targets, dtype=float)
    if np.any(np.diff(targets) < 0):
        raise ValueError("targets must be ascending")
    lo0, hi0 = float(h[:, 0].min()), float(h[:, 2].max())
    tol = 2.0**-iterations * float(areas.sum()) / (len(targets) + 1)
    guess, step = _guess(h, areas, targets, lo0, hi0)
    lo, hi, a_lo, a_hi, pairs = _bracket(h, areas, targets, guess - step, guess + step, lo0, hi0, pad)
    aim = targets + 0.5 * tol  # land just above: hi is where A >= target
    t = lo + (aim - a_lo) / np.maximum(a_hi - a_lo, 1e-300) * (hi - lo)  # the secant
    halved = np.ones(len(targets), dtype=bool)
    for _ in range(2 * iterations):
        done = a_hi - targets <= tol
        if done.all():
            break
        # A Newton step where it lands inside and the last step at least halved the
        # bracket; else the middle: a jump or a flat stretch of A cannot stall it.
        t = np.where(halved & (t > lo) & (t < hi), t, 0.5 * (lo + hi))
        t = np.where(done, hi, t)
        got, slope = pairs.area_at(t), pairs.density_at(t)
        below = got < targets
        width = hi - lo
        lo, a_lo = np.where(below, t, lo), np.where(below, got, a_lo)
        hi, a_hi = np.where(below, hi, t), np.where(below, a_hi, got)
        halved = hi - lo <= 0.5 * width
        with np.errstate(divide="ignore", invalid="ignore"):
            t = t + (aim - got) / slope
        t = np.where(np.isfinite(t), t, lo)
        # A target found needs the area at hi + pad only: its faces below hi join the base.
        pairs.narrow(np.where(a_hi - targets <= tol, hi, lo), hi + pad)
    hi = _onto_jumps(pairs, targets, lo, hi, a_hi - targets > tol)
    pairs.narrow(hi, hi + pad)
    return hi, pairs.exact_area_at


def _onto_jumps(pairs, targets, lo, hi, stuck, steps=8):
    """hi (m,), where A jumps past a ``stuck`` target inside its bracket (lo, hi], moved
    down onto the jump's height: the lowest top height h2 of a face inside the bracket
    where A reaches the target (a face flat in the direction is its own top), so the
    targets inside one jump share one edge."""
    for _ in range(steps):
        if not stuck.any():
            break
        o = pairs.owner
        v = np.full(len(targets), np.inf)
        np.minimum.at(v, o, np.where(pairs.h2 > lo[o], pairs.h2, np.inf))
        stuck = stuck & (v < hi)
        v = np.where(stuck, v, hi)
        reached = pairs.area_at(v) >= targets
        hi = np.where(stuck & reached, v, hi)
        lo = np.where(stuck & ~reached, v, lo)
        stuck = stuck & ~reached
    return hi


def _guess(h, areas, targets, lo0, hi0):
    """First guesses (m,) of the heights where A reaches targets, and a bracket half-width:
    A with each face's area spread evenly from h0 to h2 (a step where h2 - h0 is under a
    grid step), on a grid of GUESS_BINS steps (a few bincount passes), over every j-th
    face of a large surface (their shares of its area)."""
    nb = GUESS_BINS
    width = (hi0 - lo0) / nb
    every = max(1, len(h) // GUESS_FACES)
    if every > 1:
        total = float(areas.sum())
        h, areas = h[::every], areas[::every]
        targets = targets * (float(areas.sum()) / total)
    p0, p2 = (h[:, 0] - lo0) / width, (h[:, 2] - lo0) / width
    wide = p2 - p0 >= 1.0
    # A ramp max(0, x - p) on the grid rises by 1 - frac(p) over step floor(p), then by 1.
    rate = np.where(wide, areas / np.where(wide, p2 - p0, 1.0), 0.0)
    i0, i2 = np.minimum(p0.astype(np.int64), nb), np.minimum(p2.astype(np.int64), nb)
    mid = np.minimum(((p0 + p2) * 0.5).astype(np.int64), nb)
    rise = (np.bincount(i0, rate * (1.0 - (p0 - i0)), minlength=nb + 2)
            - np.bincount(i2, rate * (1.0 - (p2 - i2)), minlength=nb + 2)
            + np.bincount(mid, np.where(wide, 0.0, areas), minlength=nb + 2))
    slope = np.bincount(i0 + 1, rate, minlength=nb + 2) - np.bincount(i2 + 1, rate, minlength=nb + 2)
    grid = np.concatenate(([0.0], np.cumsum(rise + np.cumsum(slope))))[: nb + 2]
    j = np.clip(np.searchsorted(grid, targets, side="left"), 1, nb + 1)
    gap = grid[j] - grid[j - 1]
    part = np.where(gap > 0, (targets - grid[j - 1]) / np.where(gap > 0, gap, 1.0), 1.0)
    guess = np.minimum(lo0 + width * (j - 1 + np.clip(part, 0.0, 1.0)), hi0)
    return np.maximum.accumulate(guess), GUESS_HALF_WIDTH * width


def _bracket(h, areas, targets, lo, hi, lo0, hi0, pad, tries=4):
    """Brackets lo < hi (m,, ascending) with A(lo) < target <= A(hi), from the given ones
    (lo < hi): an end that misses moves out by twice the bracket's width, at the last
    try to the end of the range; the exact A at their ends and their :class:`_Pairs`."""
    floor = lo0 - (hi0 - lo0)  # A is 0 there and total at hi0
    for attempt in range(tries + 1):
        lo = np.minimum.accumulate(np.maximum(lo, floor)[::-1])[::-1]
        hi = np.maximum.accumulate(np.minimum(hi, hi0))
        pairs = _Pairs(h, areas, lo, hi + pad)
        pairs.narrow(lo, hi + pad)
        a_lo, a_hi = pairs.area_at(lo), pairs.area_at(hi)
        low, high = a_lo >= targets, a_hi < targets
        if not (low.any() or high.any()) or attempt == tries:
            break
        span = hi - lo
        wide = attempt + 1 == tries
        lo = np.where(low, floor if wide else lo - 2.0 * span, lo)
        hi = np.where(high, hi0 if wide else hi + 2.0 * span, hi)
    return lo, hi, a_lo, a_hi, pairs


class _Pairs:
    """The (target, face) pairs of the faces that reach into each bracket lo (m,) ..
    hi (m,) (highest vertex above lo, lowest at or below hi; both ascending), with
    what the area function needs of each face gathered once. Per bracket, ``base``
    (m,): the area of the faces wholly below it, and ``quad`` (3, m): the summed
    quadratic a + b u + c u^2 (u = t - lo) of the faces whose area below t is one
    closed form over the whole bracket; ``kept``: those faces, for the exact sum."""

    FIELDS = ("owner", "h0", "h1", "h2", "area")

    def __init__(self, h, areas, lo, hi):
        # A face reaches into the brackets k with hi_k >= h0 and lo_k < h2: a run of k,
        # as lo and hi ascend; it lies wholly below lo_k for k from the run's end on.
        first = np.searchsorted(hi, h[:, 0], side="left")
        last = np.searchsorted(lo, h[:, 2], side="left")
        n = np.maximum(last - first, 0)
        faces = np.repeat(np.arange(len(h)), n)
        starts = np.cumsum(n) - n
        self.owner = np.repeat(first - starts, n) + np.arange(len(faces))
        self.h0, self.h1, self.h2 = (np.ascontiguousarray(h[faces, c]) for c in range(3))
        self.area = areas[faces]
        self.base = np.cumsum(np.bincount(last, areas, minlength=len(lo) + 1))[: len(lo)]
        self.lo = np.asarray(lo, dtype=float).copy()
        self.quad = np.zeros((3, len(lo)))
        self.kept = []

    def narrow(self, lo, hi):
        """Keep the pairs of the brackets lo .. hi inside the old ones that still have a
        vertex height inside: the faces now wholly below lo join the base, those whose
        area below is one closed form from lo to hi join the quadratic."""
        a, b, c = self.quad
        du = lo - self.lo
        self.quad = np.array([a + du * (b + du * c), b + 2.0 * c * du, c])
        self.lo = lo
        o = self.owner
        lo_o, hi_o = lo[o], hi[o]
        below = self.h2 <= lo_o
        lower = (self.h0 <= lo_o) & (hi_o < self.h1)
        upper = (self.h1 <= lo_o) & (hi_o < self.h2)
        m = len(lo)
        self.base = self.base + np.bincount(o[below], self.area[below], minlength=m)
        self._absorb(lower, self.h0 - lo_o, (self.h1 - self.h0) * (self.h2 - self.h0), 1.0, m)
        self._absorb(upper, self.h2 - lo_o, (self.h2 - self.h0) * (self.h2 - self.h1), -1.0, m)
        keep = ~(below | lower | upper) & (self.h0 <= hi_o)
        for name in self.FIELDS:
            setattr(self, name, getattr(self, name)[keep])

    def _absorb(self, which, e, den, sign, m):
        """Add to the quadratics the faces ``which`` whose area below t is area (t - h0)^2
        / den (sign 1, e = h0 - lo) or area (1 - (h2 - t)^2 / den) (sign -1, e = h2 - lo):
        sign area / den (u - e)^2 (+ area for sign -1)."""
        idx = np.flatnonzero(which)
        if not len(idx):
            return
        o, area = self.owner[idx], self.area[idx]
        w, e = sign * area / den[idx], e[idx]
        const = w * e * e + (area if sign < 0 else 0.0)
        self.quad += np.stack([np.bincount(o, v, minlength=m) for v in (const, -2.0 * w * e, w)])
        self.kept.append(tuple(getattr(self, name)[idx] for name in self.FIELDS))

    def __len__(self):
        return len(self.owner)

    def area_at(self, t):
        """The area below heights t (m,), each inside its bracket."""
        u = t - self.lo
        a, b, c = self.quad
        return self.base + (a + u * (b + u * c)) + self._sum(below_fraction, self._fields(), t)

    def density_at(self, t):
        """The derivative of the area below at heights t (m,), each inside its bracket."""
        u = t - self.lo
        _, b, c = self.quad
        return b + 2.0 * c * u + self._sum(below_density, self._fields(), t)

    def exact_area_at(self, t):
        """The area below heights t (m,), each inside its bracket, summed face by face."""
        cols = [np.concatenate(c) for c in zip(self._fields(), *self.kept)]
        return self.base + self._sum(below_fraction, cols, t)

    def _fields(self):
        return tuple(getattr(self, name) for name in self.FIELDS)

    @staticmethod
    def _sum(fraction, cols, t):
        owner, h0, h1, h2, area = cols
        out = np.zeros(len(t))
        for s in range(0, len(owner), CHUNK_ENTRIES):
            cut = slice(s, s + CHUNK_ENTRIES)
            o = owner[cut]
            out += np.bincount(o, area[cut] * fraction(h0[cut], h1[cut], h2[cut], t[o]), minlength=len(t))
        return out
