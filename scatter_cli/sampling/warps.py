"""Warps from the unit square to a triangle, each beside its PDF and its inverse.

A warp takes ``u`` of shape ``(n, 2)`` in [0, 1)^2 and returns barycentric weights
``(b1, b2)`` of shape ``(n, 2)``: the point is ``v0 + b1 (v1 - v0) + b2 (v2 - v0)``
and ``b0 = 1 - b1 - b2``. PDFs are densities over the reference triangle
``{b1, b2 >= 0, b1 + b2 <= 1}`` (area 1/2), so a uniform warp has PDF 2 everywhere.
"""

import numpy as np


def square_to_triangle(u):
    """Square-root warp: b1 = 1 - sqrt(u1), b2 = (1 - b1) u2 = sqrt(u1) u2.

    Uniform over the triangle. ``u``: (n, 2) float64 -> (n, 2) float64.
    Every output lies in the closed triangle for every input in [0, 1]^2, in floating
    point too: b2 is computed from the rounded b1 as (1 - b1) u2, and 1 - b1 is exact
    for every b1 = fl(1 - s) in [0, 1] (Sterbenz when b1 >= 1/2; when b1 < 1/2, b1 was
    itself exact and 1 - b1 = s). So b2 <= 1 - b1 holds exactly and b0 = (1 - b1) - b2
    is >= 0 with no clamping. (b2 = s u2 instead can exceed 1 - fl(1 - s) for small s.)
    """
    u = np.asarray(u, dtype=np.float64)
    s = np.sqrt(u[:, 0])
    out = np.empty_like(u)
    np.subtract(1.0, s, out=out[:, 0])
    np.subtract(1.0, out[:, 0], out=s)
    np.multiply(s, u[:, 1], out=out[:, 1])
    return out


def square_to_triangle_pdf(b):
    """PDF of :func:`square_to_triangle` at ``b`` (n, 2): 2 inside the triangle, else 0."""
    b = np.asarray(b, dtype=np.float64)
    inside = (b[:, 0] >= 0) & (b[:, 1] >= 0) & (b[:, 0] + b[:, 1] <= 1)
    return np.where(inside, 2.0, 0.0)


def triangle_to_square(b):
    """Inverse of :func:`square_to_triangle`: (n, 2) weights -> (n, 2) points of [0, 1]^2.

    u1 = (1 - b1)^2, u2 = b2 / (1 - b1); at the vertex b1 = 1 any u2 maps there, 0 is returned.
    """
    b = np.asarray(b, dtype=np.float64)
    s = 1.0 - b[:, 0]
    out = np.empty_like(b)
    np.multiply(s, s, out=out[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        out[:, 1] = np.where(s > 0, b[:, 1] / s, 0.0)
    return np.clip(out, 0.0, 1.0)


def naive_square_to_triangle(u):
    """The biased counter-example: b1 = u1, b2 = (1 - u1) u2.

    Not uniform: its density grows toward the vertex b1 = 1, so points pile up near v1
    and thin out along the b1 = 0 edge. Kept only to show that the tests catch it.
    """
    u = np.asarray(u, dtype=np.float64)
    out = np.empty_like(u)
    out[:, 0] = u[:, 0]
    np.multiply(1.0 - u[:, 0], u[:, 1], out=out[:, 1])
    return out


def naive_square_to_triangle_pdf(b):
    """PDF of :func:`naive_square_to_triangle`: 1 / (1 - b1) inside the triangle."""
    b = np.asarray(b, dtype=np.float64)
    inside = (b[:, 0] >= 0) & (b[:, 1] >= 0) & (b[:, 0] + b[:, 1] <= 1) & (b[:, 0] < 1)
    with np.errstate(divide="ignore"):
        return np.where(inside, 1.0 / (1.0 - np.where(inside, b[:, 0], 0.0)), 0.0)


def naive_triangle_to_square(b):
    """Inverse of :func:`naive_square_to_triangle`."""
    b = np.asarray(b, dtype=np.float64)
    s = 1.0 - b[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        u2 = np.where(s > 0, b[:, 1] / s, 0.0)
    return np.clip(np.column_stack([b[:, 0], u2]), 0.0, 1.0)


def fold_square_to_triangle(u):
    """Parallelogram fold (trimesh's ``sample_surface``): b = u, reflected when b1 + b2 > 1.

    Uniform (PDF 2) and cheap, but two-to-one: the square's upper half is folded onto
    the lower one, so a stratified pattern in the square lands twice on the triangle.
    ``u``: (n, 2) float64 -> (n, 2) float64.
    """
    u = np.asarray(u, dtype=np.float64)
    fold = (u[:, 0] + u[:, 1]) > 1.0
    return np.where(fold[:, None], 1.0 - u, u)


def fold_triangle_to_square(b):
    """A right inverse of :func:`fold_square_to_triangle`: the preimage in the lower half.

    The fold is two-to-one, so ``warp(inverse(b)) == b`` but ``inverse(warp(u)) == u``
    only for ``u1 + u2 <= 1``; the other preimage is ``1 - u``.
    """
    return np.clip(np.asarray(b, dtype=np.float64), 0.0, 1.0)


def lowdist_square_to_triangle(u):
    """Low-distortion square-to-triangle map (Heitz 2019, "A Low-Distortion Map Between
    Triangle and Square"; pbrt-v4's ``SampleUniformTriangle``).

    The square is cut along its diagonal u1 = u2 and each half is sheared onto the
    triangle: below the diagonal b2 = u2 / 2, b1 = u1 - b2; above it b1 = u1 / 2,
    b2 = u2 - b1. Linear on each half (Jacobian 1/2, PDF 2) and one-to-one, so it keeps
    the shape of strata better than the square-root warp. (n, 2) -> (n, 2) float64.
    """
    u = np.asarray(u, dtype=np.float64)
    above = u[:, 1] > u[:, 0]
    half = 0.5 * np.where(above, u[:, 0], u[:, 1])
    out = np.empty_like(u)
    out[:, 0] = np.where(above, half, u[:, 0] - half)
    out[:, 1] = np.where(above, u[:, 1] - half, half)
    return out


def lowdist_triangle_to_square(b):
    """Inverse of :func:`lowdist_square_to_triangle`: b2 > b1 came from above the diagonal."""
    b = np.asarray(b, dtype=np.float64)
    above = b[:, 1] > b[:, 0]
    s = b[:, 0] + b[:, 1]
    out = np.empty_like(b)
    out[:, 0] = np.where(above, 2.0 * b[:, 0], s)
    out[:, 1] = np.where(above, s, 2.0 * b[:, 1])
    return np.clip(out, 0.0, 1.0)


WARPS = {
    "sqrt": (square_to_triangle, square_to_triangle_pdf, triangle_to_square),
    "fold": (fold_square_to_triangle, square_to_triangle_pdf, fold_triangle_to_square),
    "lowdist": (lowdist_square_to_triangle, square_to_triangle_pdf, lowdist_triangle_to_square),
    "naive": (naive_square_to_triangle, naive_square_to_triangle_pdf, naive_triangle_to_square),
}
"""name -> (warp, pdf, inverse). Only ``sqrt`` is used by ``scatter sample``; the others
are compared by ``scatter bench``. ``naive`` is biased on purpose."""
