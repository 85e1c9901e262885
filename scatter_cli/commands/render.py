"""Draw a point set as a small picture on the CPU with NumPy: no display, no GPU.

Orthographic projection along one of four views, each point splatted as a small disc,
a depth buffer so that front points hide back points (and the pinholes between a
surface's discs closed), and depth shading (nearer is brighter) so that shapes read as
shapes. A volume can be cut open: the near half of its box left out.

Views are taken in the points' frame, whose up axis is +Z or +Y (``up``):

- ``front`` looks horizontally along +Y (Z up) or -Z (Y up), +X to the right;
- ``side`` looks along -X, so +Y (Z up) or -Z (Y up) is to the right;
- ``top`` looks down the up axis, +X to the right;
- ``iso`` looks from above the front right corner of the bounding box (the ``front``
  camera turned 45 degrees about the up axis and raised 35.26 degrees: along the box
  diagonal (-1, +1, -1) in Z-up coordinates).

A thumbnail is framed on the bounding box of the points, not on the points, so that
one shape seen from several views keeps its scale.
"""

from __future__ import annotations

import numpy as np

VIEWS = ("iso", "front", "side", "top")
BACKGROUND = 255
MARGIN = 0.06  # of the side, left empty around the box
NEAR_SHADE, FAR_SHADE = 1.0, 0.45  # brightness of the nearest and the farthest point
MAX_SPLAT = 6.0  # largest disc radius in pixels (sparse sets are dots, not blobs)
SPLAT_FILL = 1.2  # disc radius as a fraction of size / sqrt(n): about the spacing of the visible points of a surface
# Colours of inside and outside points: vermillion and blue of the Okabe-Ito palette,
# told apart with every common form of colour blindness.
INSIDE_RGB, OUTSIDE_RGB = (213, 94, 0), (0, 114, 178)
# Points on sharp edges (the column ``sharp``), over the normal or height colours: black,
# which neither of those ramps comes near.
SHARP_RGB = (0, 0, 0)
EMPTY = np.uint64(np.iinfo(np.uint64).max)  # a depth-buffer pixel no disc covers
DEPTH_STEPS = (1 << 24) - 1  # depth is quantised to this many steps over the bounding box
HOLE_DEPTH, HOLE_NEIGHBOURS, HOLE_PASSES = 0.05, 5, 2  # see fill_holes
HOLE_STEP = np.uint64(HOLE_DEPTH * DEPTH_STEPS)
# Height colour ramp (low to high): viridis at five stops.
HEIGHT_RAMP = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], dtype=np.float64)

# Camera rows (right, screen up, toward the viewer) for Z-up points.
_Z_UP = {
    "front": [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
    "side": [[0, 1, 0], [0, 0, 1], [1, 0, 0]],
    "top": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
}
# A Z-up direction (x, y, z) is (x, z, -y) in Y-up coordinates.
_Z_TO_Y = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=np.float64)


def camera(view, up="Z"):
    """(3, 3) float64 orthonormal rows: screen right, screen up, toward the viewer."""
    if view == "iso":
        toward = np.array([1.0, -1.0, 1.0]) / np.sqrt(3.0)
        screen_up = np.array([0.0, 0.0, 1.0]) - toward[2] * toward
        screen_up /= np.linalg.norm(screen_up)
        rows = np.stack([np.cross(screen_up, toward), screen_up, toward])
    else:
        rows = np.array(_Z_UP[view], dtype=np.float64)
    return rows if up == "Z" else rows @ _Z_TO_Y.T


def splat_offsets(radius):
    """(k, 2) int pixel offsets (dx, dy) of a disc of ``radius`` pixels, centre first."""
    r = int(np.floor(radius))
    dy, dx = np.mgrid[-r : r + 1, -r : r + 1]
    keep = dx * dx + dy * dy <= radius * radius
    offsets = np.stack([dx[keep], dy[keep]], axis=1)
    return offsets[np.argsort(np.abs(offsets).sum(axis=1), kind="stable")]


def splat_radius(n, size):
    """Disc radius in pixels for ``n`` points in a ``size`` thumbnail: about the
    spacing of the visible points of a surface (so the discs close up), 1 to MAX_SPLAT."""
    return float(np.clip(SPLAT_FILL * size / np.sqrt(max(n, 1)), 1.0, MAX_SPLAT))


def point_colors(points, attributes, up="Z"):
    """(n, 3) uint8 colours from the first the set has: ``color``, ``inside``/``sdf``
    (inside points INSIDE_RGB, outside OUTSIDE_RGB), ``sharp`` (points on sharp edges
    SHARP_RGB, the others by the next rule), ``normal`` (x, y, z to r, g, b), else the
    height along the up axis (HEIGHT_RAMP)."""
    n = len(points)
    if "color" in attributes:
        return np.asarray(attributes["color"])[:, :3].astype(np.uint8)
    for name in ("inside", "sdf"):
        if name in attributes:
            values = np.asarray(attributes[name]).reshape(n)
            inside = values > 0.5 if name == "inside" else values < 0
            return np.where(inside[:, None], np.array(INSIDE_RGB, np.uint8), np.array(OUTSIDE_RGB, np.uint8))
    if "sharp" in attributes:
        colors = point_colors(points, {k: v for k, v in attributes.items() if k != "sharp"}, up)
        colors[np.asarray(attributes["sharp"]).reshape(n) > 0] = SHARP_RGB
        return colors
    if "normal" in attributes:
        normal = np.nan_to_num(np.asarray(attributes["normal"], dtype=np.float64))
        return np.clip(np.rint((normal + 1.0) * 127.5), 0, 255).astype(np.uint8)
    height = points[:, 2 if up == "Z" else 1] if n else np.empty(0)
    lo, hi = (height.min(), height.max()) if n else (0.0, 0.0)
    t = (height - lo) / (hi - lo) if hi > lo else np.full(n, 0.5)
    at = t * (len(HEIGHT_RAMP) - 1)
    i = np.minimum(at.astype(np.int64), len(HEIGHT_RAMP) - 2)
    f = (at - i)[:, None]
    return np.rint(HEIGHT_RAMP[i] * (1 - f) + HEIGHT_RAMP[i + 1] * f).astype(np.uint8)


def box_corners(points):
    """(8, 3) corners of the bounding box of ``points`` (n, 3)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    pick = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], dtype=bool)
    return np.where(pick, hi, lo)


def project(points, view, up, size):
    """(x, y, depth) of ``points`` (n, 3) seen from ``view`` in a ``size`` square: pixel
    coordinates (y down) and depth in [0, 1] (0 nearest), framed on the bounding box."""
    rows = camera(view, up)
    corners = box_corners(points) @ rows.T
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    centre = 0.5 * (lo + hi)
    extent = max(hi[0] - lo[0], hi[1] - lo[1])
    scale = (1 - 2 * MARGIN) * size / extent if extent > 0 else 1.0
    screen = points @ rows.T - centre
    x = size / 2 + screen[:, 0] * scale
    y = size / 2 - screen[:, 1] * scale
    depth_span = hi[2] - lo[2]
    depth = (hi[2] - centre[2] - screen[:, 2]) / depth_span if depth_span > 0 else np.zeros(len(points))
    return x, y, depth


def fill_holes(keys):
    """Close the pinholes of a surface in the depth buffer ``keys`` (h, w) uint64, in place.

    A pixel of which at least HOLE_NEIGHBOURS of its 8 neighbours are nearer by more than
    HOLE_DEPTH of the depth range (or empty, and its neighbours drawn) sees through a gap
    between the discs of a surface: it takes its nearest neighbour's point. Silhouettes
    stay (a pixel at an edge has fewer nearer neighbours)."""
    h, w = keys.shape
    # depth as int32 (empty: beyond every drawn depth), compared once per neighbour
    depth = np.minimum(keys >> np.uint64(32), np.uint64(2 * DEPTH_STEPS)).astype(np.int32)
    limit = depth[1:-1, 1:-1] - np.int32(HOLE_STEP)
    windows = [(slice(1 + dy, h - 1 + dy), slice(1 + dx, w - 1 + dx))
               for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]
    nearer = np.zeros(limit.shape, dtype=np.uint8)
    for window in windows:
        nearer += depth[window] < limit
    rows, cols = np.nonzero(nearer >= HOLE_NEIGHBOURS)
    if len(rows) == 0:
        return
    best = np.full(len(rows), EMPTY, dtype=np.uint64)
    for window in windows:
        np.minimum(best, keys[rows + window[0].start, cols + window[1].start], out=best)
    keys[rows + 1, cols + 1] = best


def thumbnail(points, colors, view="iso", up="Z", size=256, depth_test=True, cut=False):
    """(size, size, 3) uint8 picture of ``points`` (n, 3) float64 coloured ``colors``
    (n, 3) uint8, seen from ``view``. ``cut``: leave out the points in the near half of
    the bounding box, so that the section through its middle shows (for volumes of
    inside and outside points). Without ``depth_test`` the discs are painted in the
    points' order, later over earlier (only for tests: front points no longer hide back
    ones)."""
    finite = np.isfinite(points).all(axis=1)
    points, colors = points[finite], colors[finite]
    if len(points) == 0:
        return np.full((size, size, 3), BACKGROUND, dtype=np.uint8)
    x, y, depth = project(points, view, up, size)
    if cut:
        far = depth >= 0.5
        x, y, depth, colors = x[far], y[far], 2 * depth[far] - 1, colors[far]  # shaded over the far half
    n = len(x)
    if n == 0:
        return np.full((size, size, 3), BACKGROUND, dtype=np.uint8)
    radius = splat_radius(n, size)
    pad = int(np.floor(radius)) + 1
    width = size + 2 * pad  # a padded buffer: discs need no bounds check (points are in the square)
    ix = np.clip(np.floor(x).astype(np.int64), 0, size - 1) + pad
    iy = np.clip(np.floor(y).astype(np.int64), 0, size - 1) + pad
    base = iy * width + ix
    # One key per point: quantised depth above the point's index, so the smallest key
    # a pixel gets is its nearest point's (ties: the earlier point).
    if depth_test:
        near = np.rint(np.clip(depth, 0, 1) * DEPTH_STEPS).astype(np.uint64) << np.uint64(32)
        key = near | np.arange(n, dtype=np.uint64)
    else:
        key = np.arange(n - 1, -1, -1, dtype=np.uint64)  # the last point drawn wins
    nearest = np.full(width * width, EMPTY, dtype=np.uint64)
    for offset in (splat_offsets(radius) @ [1, width]).tolist():  # a pass per disc pixel: n keys stay in the cache
        np.minimum.at(nearest, base + offset, key)
    if depth_test:
        for _ in range(HOLE_PASSES):
            fill_holes(nearest.reshape(width, width))
    nearest = nearest.reshape(width, width)[pad : pad + size, pad : pad + size]
    # The low 32 bits of a pixel's key: its point's rank in ``palette`` (n: the background).
    rank = np.minimum(nearest & np.uint64(0xFFFFFFFF), np.uint64(n)).astype(np.intp)
    shade = NEAR_SHADE + (FAR_SHADE - NEAR_SHADE) * np.clip(depth, 0, 1)
    palette = np.empty((n + 1, 3), dtype=np.uint8)
    palette[:n] = np.rint(colors * shade[:, None])
    palette[n] = BACKGROUND
    if not depth_test:
        palette[:n] = palette[n - 1 :: -1].copy()
    return palette[rank]
