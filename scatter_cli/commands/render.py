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
MAX_SPLAT = 8.0  # largest disc radius in pixels (sparse sets are dots, not blobs)
SPLAT_FILL = 1.7  # disc radius over the spacing of the visible points about it (random points: 0.01 % of pixels uncovered)
DENSITY_CELL = 8  # pixels a side of the cells in which the visible points are counted
SURFACE_DEPTH = 4.0  # pixels of depth behind a cell's nearest point that count as its surface
# Colours of inside and outside points: vermillion and blue of the Okabe-Ito palette,
# told apart with every common form of colour blindness.
INSIDE_RGB, OUTSIDE_RGB = (213, 94, 0), (0, 114, 178)
# Points on sharp edges (the column ``sharp``), over the normal or height colours: black,
# which neither of those ramps comes near.
SHARP_RGB = (0, 0, 0)
EMPTY = np.uint64(np.iinfo(np.uint64).max)  # a depth-buffer pixel no disc covers
DEPTH_STEPS = (1 << 24) - 1  # depth is quantised to this many steps over the bounding box
HOLE_DEPTH, HOLE_NEIGHBOURS, HOLE_PASSES = 0.05, 5, 3  # see fill_holes
HOLE_STEP = np.uint64(HOLE_DEPTH * DEPTH_STEPS)
# Height colour ramp (low to high): viridis at five stops.
HEIGHT_RAMP = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], dtype=np.float64)
# A height field (a terrain: nearly every normal on one side of the up axis) is coloured
# by height and lit as a relief map is: from the north-west, 45 degrees up (Z up).
HEIGHT_FIELD = 0.99
LIGHT = np.array([-1.0, 1.0, np.sqrt(2.0)]) / 2.0
AMBIENT = 0.35  # the brightness of a slope turned away from the light

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


def splat_radii(x, y, depth, depth_pixels, size):
    """(n,) float64 disc radius of each point at pixel ``x``, ``y`` (n,) and ``depth``
    (n,) in a ``size`` square (``depth_pixels``: the depth range in pixels): SPLAT_FILL
    times the spacing of the visible points about it, 1 to MAX_SPLAT. So the discs of a
    surface close up wherever it is, seen face on or at a slant, sparse or dense.

    Visible points are counted in cells of DENSITY_CELL pixels: those within
    SURFACE_DEPTH pixels of the nearest point of their cell (a surface's front, not its
    back). A point's spacing is from the mean count of the cells about it (its own and
    the eight around, those with points), so that a cell a surface only partly covers,
    at its edges, takes about the density of the surface, and its discs spill little
    over the edge."""
    cols = size // DENSITY_CELL + 1
    row, col = ((np.clip(v, 0, size - 1) // DENSITY_CELL).astype(np.int64) for v in (y, x))
    cell = row * cols + col
    nearest = np.full(cols * cols, np.inf)
    np.minimum.at(nearest, cell, depth)
    band = SURFACE_DEPTH / depth_pixels if depth_pixels > 0 else np.inf
    front = depth <= nearest[cell] + band
    visible = np.pad(np.bincount(cell[front], minlength=cols * cols).reshape(cols, cols), 1)
    around = np.stack([visible[1 + dy : 1 + dy + cols, 1 + dx : 1 + dx + cols]
                       for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    mean = (around.sum(axis=0) / np.maximum((around > 0).sum(axis=0), 1)).reshape(-1)
    spacing = DENSITY_CELL / np.sqrt(mean[cell])
    return np.clip(SPLAT_FILL * spacing, 1.0, MAX_SPLAT)


def point_colors(points, attributes, up="Z"):
    """(n, 3) uint8 colours from the first the set has: ``color``, ``inside``/``sdf``
    (inside points INSIDE_RGB, outside OUTSIDE_RGB), ``sharp`` (points on sharp edges
    SHARP_RGB, the others by the next rule), ``normal`` (x, y, z to r, g, b; for a height
    field, a relief map: :func:`relief_colors`), else the height along the up axis
    (HEIGHT_RAMP)."""
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
        upward = normal[:, 2 if up == "Z" else 1]
        if n and max(np.mean(upward > 0), np.mean(upward < 0)) >= HEIGHT_FIELD:
            return relief_colors(points, normal * np.sign(upward.sum()), up)
        return np.clip(np.rint((normal + 1.0) * 127.5), 0, 255).astype(np.uint8)
    return height_colors(points, up)


def legend(attributes):
    """[(label, rgb)] of the colours :func:`point_colors` gives a set with ``attributes``
    that a reader needs told: inside and outside; [] for the others."""
    if "color" not in attributes and ("inside" in attributes or "sdf" in attributes):
        return [("inside", INSIDE_RGB), ("outside", OUTSIDE_RGB)]
    return []


def relief_colors(points, normal, up="Z"):
    """(n, 3) uint8: a height field's colours, HEIGHT_RAMP by height, lit by LIGHT on its
    ``normal`` (n, 3) turned up (a relief map)."""
    light = LIGHT if up == "Z" else _Z_TO_Y @ LIGHT
    lit = AMBIENT + (1.0 - AMBIENT) * np.clip(normal @ light, 0.0, 1.0)
    return np.rint(height_colors(points, up) * lit[:, None]).astype(np.uint8)


def height_colors(points, up="Z"):
    """(n, 3) uint8: HEIGHT_RAMP by the height of ``points`` (n, 3) along the up axis."""
    n = len(points)
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
    """(x, y, depth, depth range in pixels) of ``points`` (n, 3) seen from ``view`` in a
    ``size`` square: pixel coordinates (y down) and depth in [0, 1] (0 nearest), framed
    on the bounding box."""
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
    return x, y, depth, depth_span * scale


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
    x, y, depth, depth_pixels = project(points, view, up, size)
    if cut:
        far = depth >= 0.5
        x, y, depth, colors = x[far], y[far], 2 * depth[far] - 1, colors[far]  # shaded over the far half
        depth_pixels /= 2
    n = len(x)
    if n == 0:
        return np.full((size, size, 3), BACKGROUND, dtype=np.uint8)
    radius = splat_radii(x, y, depth, depth_pixels, size)
    pad = int(np.floor(radius.max())) + 1
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
    # A pass per disc pixel, nearest the centre first (n keys stay in the cache): the
    # points whose disc reaches it, a prefix of the points by decreasing radius.
    order = np.argsort(-radius, kind="stable")
    base, key, reach = base[order], key[order], -radius[order]
    offsets = splat_offsets(radius.max())
    for offset, distance in zip((offsets @ [1, width]).tolist(), np.hypot(*offsets.T).tolist()):
        m = np.searchsorted(reach, -distance, side="right")
        np.minimum.at(nearest, base[:m] + offset, key[:m])
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
