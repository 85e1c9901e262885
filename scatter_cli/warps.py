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


WARPS = {
    "sqrt": (square_to_triangle, square_to_triangle_pdf, triangle_to_square),
    "naive": (naive_square_to_triangle, naive_square_to_triangle_pdf, naive_triangle_to_square),
}
