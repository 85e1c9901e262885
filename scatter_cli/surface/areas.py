"""Twice the areas of faces, computed one way everywhere (and as the compiled kernels
compute them), so that every module gets the same bits for the same face."""

from __future__ import annotations

import numpy as np


def cross_columns(cols):
    """The three (n,) float64 columns of ``(v1 - v0) x (v2 - v0)`` of faces given as 9
    corner columns (n,): corner 0 x y z, corner 1, corner 2."""
    e1 = [cols[3 + c] - cols[c] for c in range(3)]
    e2 = [cols[6 + c] - cols[c] for c in range(3)]
    return [e1[(c + 1) % 3] * e2[(c + 2) % 3] - e1[(c + 2) % 3] * e2[(c + 1) % 3] for c in range(3)]


def norms(cols):
    """(n,) float64 ``sqrt(x^2 + y^2 + z^2)`` of three (n,) columns, summed in this
    order, as the compiled kernels sum it."""
    s = cols[0] * cols[0]
    s += cols[1] * cols[1]
    s += cols[2] * cols[2]
    return np.sqrt(s, out=s)


def doubled_areas(cols):
    """(n,) float64 twice the areas of faces given as 9 corner columns (n,)."""
    return norms(cross_columns(cols))
