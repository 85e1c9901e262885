"""The sampled surface's extent: its bounding box, and the coordinate precision it allows.

The box is that of the vertices the used faces reference, in world space (``--precision
auto``, LAS scale and offset, ``--normalize``), not of stray vertices.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ScatterError
from ..sampling.plan import column_bounds
from ..surface.model import transformed_columns

# --precision auto keeps float32 while its rounding moves no point by more than this
# fraction of the bounding-box diagonal.
AUTO_PRECISION_TOLERANCE = 1e-6


def sampled_bounds(plan):
    """(2, 3) float64 min and max over the world-space vertices of the faces that get points.

    The instances of a geometry that use all its faces are bounded together: its
    referenced vertices under all their matrices at once, (k, V) values at a time."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    whole = {}  # geometry -> matrices of the parts that use every face (None: identity)
    for part in plan.parts:
        if not part.count:  # an instance none of whose faces can get points
            continue
        gi = plan.surface.instances[part.instance].geometry
        if part.faces is None:
            whole.setdefault(gi, []).append(part.matrix)
            continue
        g = plan.surface.geometries[gi]
        box = _box(_referenced(g.vertices, g.faces[part.faces]), [part.matrix])
        lo, hi = np.minimum(lo, box[0]), np.maximum(hi, box[1])
    for gi, matrices in whole.items():
        g = plan.surface.geometries[gi]
        box = _box(_referenced(g.vertices, g.faces), matrices)
        lo, hi = np.minimum(lo, box[0]), np.maximum(hi, box[1])
    return np.stack([lo, hi])


def _referenced(vertices, faces):
    """The rows of ``vertices`` (V, 3) that ``faces`` (F, 3) use."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    return vertices if used.all() else vertices[used]


def _box(v, matrices):
    """(2, 3) min and max of points ``v`` (n, 3) under each of ``matrices`` ((4, 4) or
    None for identity), as :func:`surface.apply_matrix` places them, bit for bit."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    if any(m is None for m in matrices):
        lo, hi = column_bounds(v)
    moved = [m[:3] for m in matrices if m is not None]
    step = max(1, (1 << 20) // max(len(v), 1))
    for s in range(0, len(moved), step):
        cols = transformed_columns(np.stack(moved[s : s + step]), v)
        lo = np.minimum(lo, [c.min() for c in cols])
        hi = np.maximum(hi, [c.max() for c in cols])
    return lo, hi


FLOAT32_MAX = float(np.finfo(np.float32).max)


def float32_error_bound(bounds) -> float:
    """Largest distance rounding to float32 can move a point inside ``bounds`` (2, 3)."""
    biggest = np.abs(bounds).max(axis=0)
    if not (biggest <= FLOAT32_MAX).all():  # would round to inf (spacing: NaN)
        return math.inf
    half_ulp = np.spacing(biggest.astype(np.float32)).astype(np.float64) / 2
    return float(np.sqrt(np.sum(half_ulp**2)))


def choose_precision(bounds, precision, source, warn=None):
    """The output's coordinate dtype for ``--precision precision`` over ``bounds`` (2, 3),
    the output's box (of the mesh ``source``)."""
    if precision == "float32" and math.isinf(float32_error_bound(bounds)):
        raise ScatterError(f"{source}: coordinates beyond the float32 range; use --precision float64 or auto")
    if precision != "auto":
        return np.dtype(precision)
    extent = bounds[1] - bounds[0]
    with np.errstate(over="ignore"):
        diag = math.sqrt(float(extent.dot(extent)))  # np.linalg.norm's own arithmetic, without its overhead
    err = float32_error_bound(bounds)
    if math.isinf(err) or err > AUTO_PRECISION_TOLERANCE * diag:
        if warn:
            warn(f"writing float64 coordinates: float32 would move points by up to {err:.3g}, "
                 f"more than 1e-6 of the bounding-box diagonal ({diag:.6g})")
        return np.dtype(np.float64)
    return np.dtype(np.float32)


NORMAL_FRAMES = ("unit-cube", "unit-sphere")


def normal_frame(plan, mode):
    """(offset (3,) float64, scale float) of ``--normalize mode``: output points are
    ``(p - offset) * scale``, with offset the centre of the sampled box and the scale
    that makes its largest side 2 (``unit-cube``) or puts the farthest used vertex at
    distance 1 (``unit-sphere``). None for ``none``."""
    if mode not in NORMAL_FRAMES:
        return None
    lo, hi = sampled_bounds(plan)
    centre = (lo + hi) / 2
    size = float(np.max(hi - lo)) / 2 if mode == "unit-cube" else farthest_distance(plan, centre)
    if not (math.isfinite(size) and size > 0):
        raise ScatterError(f"{plan.surface.source}: cannot --normalize {mode}: the sampled surface has no extent")
    return centre, 1.0 / size


def in_frame(box, frame=None):
    """(2, 3) float64 world-space ``box`` in the output's frame (``frame``: (offset,
    scale) of :func:`normal_frame`, or None for world space)."""
    return box if frame is None else (box - frame[0]) * frame[1]


def farthest_distance(plan, centre) -> float:
    """Largest distance from ``centre`` (3,) to a world-space vertex the used faces reference."""
    far = 0.0
    for part in plan.parts:
        if not part.count:
            continue
        g = plan.surface.geometries[plan.surface.instances[part.instance].geometry]
        v = _referenced(g.vertices, g.faces if part.faces is None else g.faces[part.faces])
        if part.matrix is not None:
            v = v @ part.matrix[:3, :3].T + part.matrix[:3, 3]
        far = max(far, float(np.sqrt(np.einsum("ij,ij->i", v - centre, v - centre)).max(initial=0.0)))
    return far
