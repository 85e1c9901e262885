"""Exact quantities of a surface that only the tests use: the area below a height,
equal-area slabs of exactly 1/k each and their probabilities, the second moment about
the origin. Built on the closed forms per triangle of :mod:`scatter_cli.stats.measures`
and :mod:`scatter_cli.stats.slabs`."""

import numpy as np

from scatter_cli.stats.slabs import below_fraction as _below_fraction
from scatter_cli.stats.measures import (
    _chunks,
    _edges,
    _kept,
    _split,
    _unit,
    centred_moments,
)


def _heights(tri, ref, d):
    """Sorted vertex heights (F, 3) about ref, and the offset ref.d removed."""
    d = _unit(d)
    return np.sort((tri - ref) @ d, axis=1), float(ref @ d)


def face_heights(tri, areas, d):
    """Sorted heights (F', 3) and areas (F',) of the faces with positive
    area, and the height offset removed from the heights."""
    tri, areas, ref = _kept(tri, areas)
    h, off = _heights(tri, ref, d)
    return h, areas, off


def cdf_from_heights(h, areas, s):
    """Area with height <= s for each s in (m,), from sorted heights (F, 3)."""
    s = np.asarray(s, dtype=float).ravel()
    out = np.zeros(s.size)
    for sl in _chunks(len(h), s.size):
        frac = _below_fraction(h[sl, 0, None], h[sl, 1, None], h[sl, 2, None], s[None, :])
        out += areas[sl] @ frac
    return out



def height_cdf(tri, areas, d, t):
    """Area of the surface whose height x.d is <= t.

    tri (F, 3, 3), areas (F,), d (3,) direction (normalised here), t any
    shape; returns an array of t's shape (float for scalar t).  Divide by
    ``areas.sum()`` for the CDF of the height of a uniform surface point.
    """
    h, a, off = face_heights(tri, areas, d)
    t = np.asarray(t, dtype=float)
    out = cdf_from_heights(h, a, t.ravel() - off).reshape(t.shape)
    return float(out) if out.ndim == 0 else out


def equal_area_slabs(tri, areas, d, k, iterations=48):
    """Edges (k+1,) of k slabs along d that each hold 1/k of the area.

    edges[0] and edges[k] are the lowest and highest surface heights; the
    k-1 interior edges are found together by bisection on the exact area
    function.  Where the area jumps (faces flat in d) an exact split may not
    exist; the edge then sits just above the jump, so use
    ``slab_probabilities`` for the exact share of each slab.  Interior edges
    are nudged up by ~1e-11 of the extent so points lying on a flat face at an
    edge's height fall below it whatever their rounding.
    """
    k = int(k)
    if k < 1:
        raise ValueError("equal_area_slabs: k must be >= 1")
    tri, areas, ref = _kept(tri, areas)
    h, off = _heights(tri, ref, d)
    inner, _ = _split(h, areas, k, iterations)
    return _edges(h, inner) + off


def slab_probabilities(tri, areas, d, edges):
    """Exact probability (k,) that a uniform surface point falls in each slab
    of ``edges`` (k+1,): slab 0 is (-inf, e1], slab j is (e_j, e_j+1], the last
    is (e_k-1, inf) — the same convention as ``slab_counts``."""
    h, a, off = face_heights(tri, areas, d)
    inner = cdf_from_heights(h, a, np.asarray(edges, dtype=float)[1:-1] - off) / a.sum()
    # Rounding in the per-face sums can make the CDF step back by an ulp: keep it monotone.
    inner = np.maximum.accumulate(np.clip(inner, 0.0, 1.0))
    return np.diff(np.concatenate(([0.0], inner, [1.0])))


def surface_moments(tri, areas):
    """Exact mean (3,) and second moment E[x x^T] (3, 3) of a uniform point
    on the surface.  Computed about the bounding-box centre; for large
    coordinates prefer ``surface_covariance``, which never forms E[x x^T]."""
    ref, mean, cov, _, _ = centred_moments(tri, areas)
    mu = ref + mean
    return mu, cov + np.outer(mu, mu)



def with_direct_areas(solve):
    """A twin of the slab solver ``solve`` (``surface_measures._solve_heights``): the
    heights it finds, with the area below any height summed over every face's closed
    form (no bracket, no narrowing, no quadratic)."""

    def solver(h, areas, targets, iterations, pad=0.0):
        hi, _ = solve(h, areas, targets, iterations, pad)
        return hi, lambda t: cdf_from_heights(h, areas, t)

    return solver
