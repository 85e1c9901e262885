"""Instancing orientations: a unit quaternion per point that turns +Z onto its normal,
then spins it about the normal by a uniform angle.

The angle of point ``i`` is a pure function of the run's seed and ``i`` (its absolute
position in the output), drawn from a stream of its own: asking for ``orient`` moves no
point, and the bytes are the same whatever the chunk size or thread count.
"""

from __future__ import annotations

import numpy as np

from ..core.elementary import sincos
from ..core.hashing import lane, to_unit

# Keeps the spin stream apart from every placement stream of the same seed.
SPIN_STREAM = 0x6F7269656E74  # "orient"


def spin_key(seed: int) -> np.uint64:
    """The 64-bit key of the spin stream for ``seed``."""
    return np.random.SeedSequence([int(seed), SPIN_STREAM]).generate_state(1, np.uint64)[0]


def spin_uniforms(seed: int, start: int, n: int) -> np.ndarray:
    """(n,) float64 in [0, 1): the spin stream's values for points ``start`` .. ``start + n - 1``.

    Counter-based SplitMix64: value ``i`` is the SplitMix64 finaliser of ``key + (i + 1) * gamma``.
    """
    return to_unit(lane(spin_key(seed), np.arange(start + 1, start + n + 1, dtype=np.uint64)))


def align_z(n: np.ndarray) -> np.ndarray:
    """(m, 4) float64 quaternions ``qx qy qz qw``: the shortest rotation of +Z onto unit ``n`` (m, 3).

    q = (z x n, 1 + z . n), normalised; 1 + n_z is taken as (n_x^2 + n_y^2) / (1 - n_z) where
    n_z < 0, so normals near -Z keep their precision. Exactly -Z turns about +X.
    """
    nx, ny, nz = n[:, 0], n[:, 1], n[:, 2]
    q = np.zeros((len(n), 4))
    q[:, 0] = -ny
    q[:, 1] = nx
    side = nx * nx + ny * ny
    with np.errstate(invalid="ignore", divide="ignore"):
        q[:, 3] = np.where(nz >= 0, 1.0 + nz, side / (1.0 - nz))
    norm = np.sqrt(side + q[:, 3] ** 2)
    flip = ~(norm > 0)
    q[flip] = (1.0, 0.0, 0.0, 0.0)
    norm[flip] = 1.0
    q /= norm[:, None]
    return q


def orientations(normals: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(m, 4) float64 unit quaternions: +Z onto ``normals`` (m, 3), then ``angles`` (m,) radians about it.

    A turn about the normal after the alignment is the alignment after the same turn
    about +Z: q = a * (0, 0, sin t/2, cos t/2), written out for a_z = 0.
    """
    a = align_z(np.asarray(normals, dtype=np.float64))
    s, c = sincos(0.5 * angles)
    q = np.empty_like(a)
    q[:, 0] = a[:, 0] * c + a[:, 1] * s
    q[:, 1] = a[:, 1] * c - a[:, 0] * s
    q[:, 2] = a[:, 3] * s
    q[:, 3] = a[:, 3] * c
    return q


def point_orientations(normals: np.ndarray, seed: int, start: int) -> np.ndarray:
    """(m, 4) float64 orientations of points ``start`` .. ``start + m - 1`` with unit ``normals`` (m, 3)."""
    return orientations(normals, 2.0 * np.pi * spin_uniforms(seed, start, len(normals)))
