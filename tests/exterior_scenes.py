"""Scenes with known exterior surface, built of axis-aligned unit squares.

Every square is whole inside another closed box (hidden) or not (exterior), so the exact
exterior area of each square is its area or 0. A scene is (trimesh.Scene, cells) where
``cells[part]`` is a list of (centre (3,), exterior bool) per square, square ``s`` being
faces 2 s and 2 s + 1 of part ``part``.
"""

import numpy as np

AXES = [(0, 1, 2), (1, 2, 0), (2, 0, 1)]


def cuboid(lo, hi, step=1.0, drop=None, inward=False):
    """(F, 3, 3) triangles of the box lo..hi cut into step x step squares, normals out
    (in when ``inward``); ``drop(centre)`` -> True removes a square. Square s is
    triangles 2 s, 2 s + 1."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    tris = []
    for a, b, c in AXES:  # the side at x_a = lo or hi, spanned by axes b and c
        for side, sign in ((lo[a], -1.0), (hi[a], 1.0)):
            nb, nc = int(round((hi[b] - lo[b]) / step)), int(round((hi[c] - lo[c]) / step))
            for i in range(nb):
                for j in range(nc):
                    q = np.zeros((4, 3))
                    q[:, a] = side
                    u0, u1 = lo[b] + i * step, lo[b] + (i + 1) * step
                    w0, w1 = lo[c] + j * step, lo[c] + (j + 1) * step
                    q[:, b] = [u0, u1, u1, u0]
                    q[:, c] = [w0, w0, w1, w1]
                    if drop is not None and drop(q.mean(axis=0)):
                        continue
                    # (b, c) order with axes (a, b, c) cyclic gives normal +a
                    t1, t2 = q[[0, 1, 2]], q[[0, 2, 3]]
                    if (sign < 0) != inward:
                        t1, t2 = t1[[0, 2, 1]], t2[[0, 2, 1]]
                    tris += [t1, t2]
    return np.array(tris)


def inside(box, p, margin=1e-9):
    lo, hi = np.asarray(box[0], float), np.asarray(box[1], float)
    return bool(np.all(p > lo + margin) and np.all(p < hi - margin))


def make_scene(parts, solids):
    """parts: {name: triangles (F, 3, 3)}; solids: closed boxes (lo, hi) that hide what is
    strictly inside them (each part's own box is given as its name's entry in ``own``)."""
    import trimesh

    scene = trimesh.Scene()
    cells = {}
    for name, (tri, own) in parts.items():
        mesh = trimesh.Trimesh(tri.reshape(-1, 3), np.arange(len(tri) * 3).reshape(-1, 3), process=False)
        scene.add_geometry(mesh, geom_name=name, node_name=name)
        centres = tri.reshape(-1, 2, 3, 3).mean(axis=(1, 2))
        cells[name] = [(c, not any(inside(s, c) for k, s in enumerate(solids) if k != own)) for c in centres]
    return scene, cells


def box_in_box():
    outer, inner = ([0, 0, 0], [3, 3, 3]), ([1, 1, 1], [2, 2, 2])
    return make_scene({"outer": (cuboid(*outer), 0), "inner": (cuboid(*inner), 1)}, [outer, inner])


def overlapping_boxes():
    a, b = ([0, 0, 0], [2, 2, 2]), ([1, 1, 1], [3, 3, 3])
    return make_scene({"a": (cuboid(*a), 0), "b": (cuboid(*b), 1)}, [a, b])


def double_shell(gap=0.5):
    outer, inner = ([0, 0, 0], [4, 4, 4]), ([gap, gap, gap], [4 - gap, 4 - gap, 4 - gap])
    return make_scene({"outer": (cuboid(*outer, step=0.5), 0), "inner": (cuboid(*inner, step=0.5), 1)},
                      [outer, inner])


def cup():
    """A solid cup: a 4 x 4 x 4 block with a 2 x 2 x 2 well open at the top. All exterior;
    the well is seen only through its opening."""
    hole = lambda c: c[2] > 3.99 and 1 < c[0] < 3 and 1 < c[1] < 3  # noqa: E731
    top = lambda c: c[2] > 3.99  # noqa: E731
    body = cuboid([0, 0, 0], [4, 4, 4], drop=hole)
    well = cuboid([1, 1, 2], [3, 3, 4], drop=top, inward=True)
    return make_scene({"body": (body, 0), "well": (well, 1)}, [])


def car():
    """A closed body with seats and an engine inside, and four wheels half sunk into it."""
    body = ([0, 0, 1], [6, 3, 3])
    parts = {"body": (cuboid(*body, step=0.5), 0)}
    solids = [body]
    for k, (lo, hi) in enumerate([([1, 0.5, 1.5], [2, 2.5, 2.5]), ([3, 0.5, 1.5], [4, 2.5, 2.5]),
                                  ([4.5, 1, 1.5], [5.5, 2, 2.5])]):
        parts[f"inside{k}"] = (cuboid(lo, hi, step=0.5), len(solids))
        solids.append((lo, hi))
    for k, (x, y) in enumerate([(1, -0.5), (4.5, -0.5), (1, 2.5), (4.5, 2.5)]):
        lo, hi = [x, y, 0.5], [x + 1, y + 1, 1.5]
        parts[f"wheel{k}"] = (cuboid(lo, hi, step=0.5), len(solids))
        solids.append((lo, hi))
    return make_scene(parts, solids)


SCENES = {"box_in_box": box_in_box, "overlapping_boxes": overlapping_boxes, "double_shell": double_shell,
          "cup": cup, "car": car}


def _orient(tri, outward):
    """Flip triangles (F, 3, 3) whose normal points against ``outward`` (F, 3)."""
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", n, outward) < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    return tri


def _band(r0, z0, r1, z1, segments):
    """Triangles (2 segments, 3, 3) of the surface of revolution between the rings
    (radius r0 at height z0) and (r1, z1)."""
    a = np.linspace(0, 2 * np.pi, segments + 1)
    ring = lambda r, z: np.stack([r * np.cos(a), r * np.sin(a), np.full_like(a, z)], axis=1)  # noqa: E731
    p, q = ring(r0, z0), ring(r1, z1)
    t1 = np.stack([p[:-1], p[1:], q[1:]], axis=1)
    t2 = np.stack([p[:-1], q[1:], q[:-1]], axis=1)
    return np.concatenate([t1, t2])


def bowl(inner=0.8, rings=12, segments=48):
    """A solid bowl: outer and inner hemispheres (radius 1 and ``inner``, below z = 0)
    joined by a flat rim. Every face is exterior; the inside is seen through the top.
    Returns (scene, bands): bands[part] = (face -> band index (F,), band areas)."""
    import trimesh

    scene, bands = trimesh.Scene(), {}
    t = np.linspace(0, np.pi / 2, rings + 1)  # polar angle from the bottom
    for name, r, sign in (("outside", 1.0, 1.0), ("inside", inner, -1.0)):
        tri = np.concatenate([_band(r * np.sin(t[k]), -r * np.cos(t[k]), r * np.sin(t[k + 1]),
                                    -r * np.cos(t[k + 1]), segments) for k in range(rings)])
        tri = _orient(tri, sign * tri.mean(axis=1))
        bands[name] = np.repeat(np.arange(rings), 2 * segments)
        scene.add_geometry(trimesh.Trimesh(tri.reshape(-1, 3), np.arange(len(tri) * 3).reshape(-1, 3),
                                           process=False), geom_name=name, node_name=name)
    rim = _orient(_band(inner, 0.0, 1.0, 0.0, segments), np.array([[0, 0, 1.0]]).repeat(2 * segments, 0))
    bands["rim"] = np.zeros(2 * segments, dtype=np.int64)
    scene.add_geometry(trimesh.Trimesh(rim.reshape(-1, 3), np.arange(len(rim) * 3).reshape(-1, 3), process=False),
                       geom_name="rim", node_name="rim")
    return scene, bands
