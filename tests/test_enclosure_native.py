"""The compiled enclosure kernel (scatter_cli/sampling/exterior/_cenclosure.c) certifies exactly the faces
that enclosure.py's NumPy path certifies, and finds the same closed parts, on built
scenes, random nested shells (hypothesis) and degenerate input: non-finite and huge
coordinates, zero-area and duplicated faces. The comparison is paired with a kernel fed
a grid one cell finer, which must differ somewhere on the same scenes (so the scenes
exercise the grid arithmetic the two paths must share)."""

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scatter_cli.sampling.exterior import enclosure

from . import exterior_scenes as es
from .test_enclosure import nested_boxes, random_rotation

KERNEL = enclosure._kernel
pytestmark = pytest.mark.skipif(
    KERNEL is None and os.environ.get("SCATTER_REQUIRE_KERNELS", "") in ("", "0"),
    reason="compiled kernels not built (SCATTER_REQUIRE_KERNELS=1 makes this a failure)",
)
OFFSET = float(np.spacing(np.float32(4.0))) * 16


def soup(tri):
    """(vertices (3F, 3), faces (F, 3)) of triangles (F, 3, 3): no index shared."""
    return tri.reshape(-1, 3).astype(np.float64), np.arange(len(tri) * 3, dtype=np.int64).reshape(-1, 3)


def both_paths(vertices, faces, monkeypatch, offset=OFFSET, cells_shift=0):
    """((part, closed, enclosed) by the kernel, the same by NumPy); ``cells_shift``: a
    broken kernel, fed a grid that many cells finer."""
    with monkeypatch.context() as m:
        m.setattr(enclosure, "_kernel", None)
        part, closed = enclosure.closed_parts(vertices, faces)
        numpy_out = (part, closed, enclosure.enclosed_faces(vertices, faces, part, closed, offset))
    return kernel_path(vertices, faces, offset, cells_shift), numpy_out


def kernel_path(vertices, faces, offset=OFFSET, cells_shift=0):
    part, closed = enclosure.closed_parts(vertices, faces)
    if cells_shift:
        out = np.zeros(len(faces), np.uint8)
        cells = int(np.clip(4 * round(len(faces) ** (1 / 3)), *enclosure.GRID)) + cells_shift
        KERNEL.enclosed(vertices, faces, part, closed.astype(np.uint8), offset, cells, enclosure.MAX_SHELLS,
                        *enclosure.PROBE, enclosure.LIMIT, 2, out)
        return part, closed, out.view(bool)
    return part, closed, enclosure.enclosed_faces(vertices, faces, part, closed, offset)


def same(a, b):
    return all(np.array_equal(x, y) for x, y in zip(a, b))


def test_the_kernel_is_built():
    assert KERNEL is not None


def built_scenes():
    """(name, vertices, faces): the exterior test scenes, and spheres in spheres."""
    import trimesh

    out = []
    for name in ("box_in_box", "double_shell", "car", "overlapping_boxes", "cup", "bowl"):
        scene, _ = getattr(es, name)()
        tri = np.concatenate([m.vertices[m.faces] for m in scene.dump()])
        out.append((name, *soup(tri)))
    outer, inner = trimesh.creation.icosphere(4), trimesh.creation.icosphere(3, radius=0.5)
    out.append(("spheres", np.vstack([outer.vertices, inner.vertices]),
                np.vstack([outer.faces, inner.faces + len(outer.vertices)]).astype(np.int64)))
    return out


@pytest.mark.parametrize("name, vertices, faces", built_scenes(), ids=lambda x: x if isinstance(x, str) else "")
def test_same_faces_on_built_scenes(name, vertices, faces, monkeypatch):
    kernel, numpy_out = both_paths(vertices, faces, monkeypatch)
    assert same(kernel, numpy_out)
    if name in ("box_in_box", "double_shell", "car", "spheres"):
        assert kernel[2].any()  # something to compare


@pytest.mark.slow
def test_same_faces_on_random_nested_boxes_and_a_finer_grid_differs(monkeypatch):
    """24 scenes of boxes in a box: the same parts and faces; a kernel fed a grid one cell
    finer certifies other faces on some of them."""
    differs, found = 0, 0
    for seed in range(24):
        v, f = soup(nested_boxes(seed))
        kernel, numpy_out = both_paths(v, f, monkeypatch)
        assert same(kernel, numpy_out), seed
        found += int(kernel[2].sum())
        broken, _ = both_paths(v, f, monkeypatch, cells_shift=1)
        differs += not same(broken, numpy_out)
    assert found > 100 and differs > 0


@pytest.mark.slow
def test_same_faces_whatever_the_thread_count(monkeypatch):
    """Shells large enough to be split between threads (a 327,680-face sphere holding a
    sphere and a box): the same faces as NumPy on 1, 2, 3 and 7 threads."""
    import trimesh

    outer, inner = trimesh.creation.icosphere(7), trimesh.creation.icosphere(4, radius=0.4)
    box = es.cuboid([0.45, -0.1, -0.1], [0.6, 0.1, 0.1], step=0.05)
    v = np.vstack([outer.vertices, inner.vertices, box.reshape(-1, 3)])
    f = np.vstack([outer.faces, inner.faces + len(outer.vertices),
                   np.arange(len(box) * 3).reshape(-1, 3) + len(outer.vertices) + len(inner.vertices)]).astype(np.int64)
    _, expected = both_paths(v, f, monkeypatch)
    for threads in ("1", "2", "3", "7"):
        monkeypatch.setenv("SCATTER_THREADS", threads)
        assert same(kernel_path(v, f), expected), threads
    assert expected[2][len(outer.faces):].all() and not expected[2][:len(outer.faces)].any()


def shells_scene(draw):
    """A random scene of closed shells (boxes, tetrahedra, icospheres; turned, scaled,
    nested, some listed twice or opened) and stray or degenerate triangles."""
    import trimesh

    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    parts = []
    for _ in range(draw(st.integers(1, 5))):
        kind = draw(st.sampled_from(["box", "tetra", "sphere"]))
        if kind == "box":
            tri = es.cuboid([0, 0, 0], [1, 1, 1], step=float(rng.choice([1.0, 0.5])))
        elif kind == "tetra":
            t = trimesh.creation.icosphere(0).convex_hull if rng.random() < 0.3 else trimesh.Trimesh(
                [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
            tri = t.vertices[t.faces]
        else:
            t = trimesh.creation.icosphere(int(rng.integers(0, 3)))
            tri = t.vertices[t.faces]
        tri = (tri - 0.5) @ random_rotation(rng).T * rng.uniform(0.05, 4.0) + rng.uniform(-2, 2, 3)
        if rng.random() < 0.15:
            tri = np.concatenate([tri, tri])
        if rng.random() < 0.15:
            tri = tri[1:]
        parts.append(tri)
    if rng.random() < 0.5:
        parts.append(rng.uniform(-3, 3, (int(rng.integers(1, 4)), 3, 3)))
    if rng.random() < 0.3:  # zero-area faces: a repeated corner
        p = rng.uniform(-3, 3, (2, 3))
        parts.append(np.array([[p[0], p[0], p[1]], [p[1], p[1], p[1]]]))
    return np.concatenate(parts)


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_same_faces_on_random_shells(data, monkeypatch):
    tri = shells_scene(data.draw)
    v, f = soup(tri)
    assert same(*both_paths(v, f, monkeypatch))
    # the same mesh, indexed (welded vertices): the parts come from the faces' own indices
    u, inverse = np.unique(v, axis=0, return_inverse=True)
    assert same(*both_paths(u, inverse.reshape(-1, 3).astype(np.int64), monkeypatch))


def box_in_box_soup():
    return soup(np.concatenate([es.cuboid([-2, -2, -2], [2, 2, 2]), es.cuboid([-1, -1, -1], [1, 1, 1], step=0.5)]))


@pytest.mark.parametrize("damage", ["nan", "inf", "huge", "beyond_limit", "at_limit", "duplicate", "zero_area",
                                    "one_point", "tiny", "offset_too_large"])
def test_same_faces_on_degenerate_input(damage, monkeypatch):
    v, f = box_in_box_soup()
    offset = OFFSET
    rng = np.random.default_rng(1)
    if damage in ("nan", "inf"):  # a vertex of the inner box, then one of the outer
        v[rng.integers(len(v) // 2, len(v), 2)] = np.nan if damage == "nan" else np.inf
        v[5, 1] = -np.inf if damage == "inf" else np.nan
    elif damage == "huge":
        v = v * 1e200
        offset *= 1e200
    elif damage == "beyond_limit":
        v = v * 6e99
    elif damage == "at_limit":
        v = v / 2 * enclosure.LIMIT
    elif damage == "duplicate":  # the inner box listed twice (still closed)
        f = np.concatenate([f, f[192:]])
    elif damage == "zero_area":
        v = np.concatenate([v, np.zeros((3, 3))])
        f = np.concatenate([f, [[len(v) - 3, len(v) - 2, len(v) - 1]], f[-5:, [0, 0, 1]]])
    elif damage == "one_point":
        v = np.zeros_like(v)
    elif damage == "tiny":
        v = v * 1e-300
        offset = 0.0
    elif damage == "offset_too_large":
        offset = 10.0
    kernel, numpy_out = both_paths(v, f, monkeypatch, offset)
    assert same(kernel, numpy_out)
    if damage in ("duplicate", "zero_area", "at_limit"):
        assert kernel[2][192:].all()
    if damage in ("huge", "beyond_limit", "offset_too_large", "one_point"):
        assert not kernel[2].any()


def test_bad_calls_are_refused():
    v, f = box_in_box_soup()
    part, closed = enclosure.closed_parts(v, f)
    c8, out = closed.astype(np.uint8), np.zeros(len(f), np.uint8)
    args = (enclosure.MAX_SHELLS, *enclosure.PROBE, enclosure.LIMIT, 2)
    bad_face, bad_part = f.copy(), part.copy()
    bad_face[3, 1] = len(v)
    bad_part[7] = len(closed)
    # the calls below differ from these, which work: welded ids, and the soup's own vertices (a part a triangle)
    assert np.array_equal(KERNEL.parts(enclosure.weld(v), f, 2)[1], closed) and closed.any()
    assert np.array_equal(KERNEL.parts(len(v), f, 2)[0], np.arange(len(f)))
    calls = [lambda: KERNEL.parts(np.arange(len(v), dtype=np.int64), bad_face, 2),
             lambda: KERNEL.parts(np.full(len(v), -1, np.int64), f, 2),
             lambda: KERNEL.parts(np.arange(len(v), dtype=np.int64), f[:, :2].copy(), 2),
             lambda: KERNEL.parts(len(v), bad_face, 2),
             lambda: KERNEL.parts(len(v) - 1, f, 2),
             lambda: KERNEL.parts(-1, f, 2),
             lambda: KERNEL.parts(2**32, f, 2),
             lambda: KERNEL.enclosed(v, bad_face, part, c8, OFFSET, 16, *args, out),
             lambda: KERNEL.enclosed(v, f, bad_part, c8, OFFSET, 16, *args, out),
             lambda: KERNEL.enclosed(v, f, part, c8, OFFSET, 16, *args, out[:-1]),
             lambda: KERNEL.enclosed(v.astype(np.float32), f, part, c8, OFFSET, 16, *args, out),
             lambda: KERNEL.enclosed(v, f, part, c8, OFFSET, 0, *args, out),
             lambda: KERNEL.enclosed(v, f, part, c8, np.nan, 16, *args, out)]
    for call in calls:
        with pytest.raises((ValueError, TypeError)):
            call()


@pytest.mark.slow
@pytest.mark.parametrize("others", [8, 16, 32])
def test_same_faces_with_many_shells(others, monkeypatch):
    """Shell bits past the 8th, 16th and 32nd (the kernel's cells carry 1, 2, 4 or 8 bytes
    of them, as few as the shells need). ``others`` boxes of the largest volume take the
    first bits; a box of the next bit holds seven small boxes, one at its centre (enclosed)
    and one 1e-6 from each of its walls: that one's side along the wall is not enclosed
    (its cells are touched by the wall); a kernel that lost the box's bit would certify it
    where the wall's cell has its probe point inside. The same parts and faces as NumPy,
    on one thread and two."""
    parts = [np.array([1.0, -1.6, -1.6]) + 0.8 * np.array(at) + es.cuboid([0, 0, 0], [1, 1, 1]) * 0.7
             for at in list(np.ndindex(2, 4, 4))[:others]]
    parts.append(-0.3 + es.cuboid([0, 0, 0], [1, 1, 1], step=0.1) * 0.6)
    centre, wall_side = [np.zeros(len(p), bool) for p in parts], [np.zeros(len(p), bool) for p in parts]
    for axis, sign in [(0, 0)] + [(a, s) for a in range(3) for s in (-1, 1)]:
        at = np.zeros(3)
        at[axis] = sign * (0.25 - 1e-6)
        small = at - 0.05 + es.cuboid([0, 0, 0], [1, 1, 1]) * 0.1
        parts.append(small)
        centre.append(np.full(len(small), sign == 0))
        wall_side.append(sign * small[:, :, axis].mean(axis=1) > 0.29)
    centre, wall_side = np.concatenate(centre), np.concatenate(wall_side)
    v, f = soup(np.concatenate(parts))
    for threads in ("1", "2"):
        monkeypatch.setenv("SCATTER_THREADS", threads)
        kernel, numpy_out = both_paths(v, f, monkeypatch)
        assert same(kernel, numpy_out)
        enclosed = kernel[2]
        assert enclosed[centre].all() and wall_side.sum() == 12 and not enclosed[wall_side].any()


@pytest.mark.slow
def test_same_faces_for_many_parts_split_between_threads(monkeypatch):
    """400 small boxes (192 faces each, some turned, some crossing the big box's wall or
    each other) in a big box, as a triangle soup: 77,000 faces, so parts and certificate
    are split between threads with runs of faces cut at the threads' bounds. The same parts
    and faces as NumPy on 1, 2, 3 and 7 threads."""
    rng = np.random.default_rng(5)
    parts = [es.cuboid([-2, -2, -2], [2, 2, 2], step=1.0)]
    for _ in range(400):
        c, h = rng.uniform(-2.1, 2.1, 3), rng.uniform(0.02, 0.12)
        box = c - h + es.cuboid([0, 0, 0], [1, 1, 1], step=0.25) * 2 * h
        parts.append((box - c) @ random_rotation(rng).T + c if rng.random() < 0.5 else box)
    v, f = soup(np.concatenate(parts))
    assert len(f) > 65536
    _, expected = both_paths(v, f, monkeypatch)
    for threads in ("1", "2", "3", "7"):
        monkeypatch.setenv("SCATTER_THREADS", threads)
        assert same(kernel_path(v, f), expected), threads
    assert 0 < expected[2].sum() < len(f) - len(parts[0]) and len(expected[1]) == 401
