"""Exact closest points (scatter_cli/volume/distance.py) and ray-parity labels (scatter_cli/volume/parity.py)
against brute force written here, O(points x faces): the distance to each triangle as the
least of its interior projection and its three edges, and the winding number as a sum of
solid angles (van Oosterom and Strackee). Each check is paired with a broken variant that
must fail it: a tree with a node's box emptied (its faces never looked at), and a crossing
test without the tie rule along a ray through vertices and edges. The kernel and the NumPy
path give the same bytes, whatever the threads; the kernel refuses bad arrays."""

import os

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scatter_cli.volume import distance, parity

from .conftest import SAMPLES

KERNEL = distance._kernel
needs_kernel = pytest.mark.skipif(
    KERNEL is None and os.environ.get("SCATTER_REQUIRE_KERNELS", "") in ("", "0"),
    reason="compiled kernels not built (SCATTER_REQUIRE_KERNELS=1 makes this a failure)",
)


# ---- brute force ----

def _cross(u, v):
    return np.stack([u[..., 1] * v[..., 2] - u[..., 2] * v[..., 1], u[..., 2] * v[..., 0] - u[..., 0] * v[..., 2],
                     u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]], axis=-1)


def pair_distance(tri, p):
    """Distances (...,) of points p (..., 3) to triangles tri (..., 3, 3), broadcast."""
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    best = None
    for s, e in ((a, b), (b, c), (c, a)):
        u = e - s
        uu = (u * u).sum(-1)
        t = np.clip(((p - s) * u).sum(-1) / np.where(uu > 0, uu, 1.0), 0.0, 1.0)
        d = np.linalg.norm(p - (s + t[..., None] * u), axis=-1)
        best = d if best is None else np.minimum(best, d)
    n = _cross(b - a, c - a)
    nn = (n * n).sum(-1)
    ok = nn > 0
    h = ((p - a) * n).sum(-1) / np.where(ok, nn, 1.0)
    q = p - h[..., None] * n
    inside = ok
    for s, e in ((a, b), (b, c), (c, a)):
        inside = inside & ((_cross(e - s, q - s) * n).sum(-1) >= 0)
    return np.where(inside, np.minimum(best, np.abs(h) * np.sqrt(nn)), best)


def brute_distance(tri, points, block=64):
    """(n,) exact distances of points to the triangle set tri (F, 3, 3)."""
    return np.concatenate([pair_distance(tri[None], points[i:i + block, None]).min(axis=1)
                           for i in range(0, len(points), block)])


def brute_winding(tri, points, block=64):
    """(n,) winding numbers: the solid angles of tri (F, 3, 3) seen from points, / 4 pi."""
    out = []
    for i in range(0, len(points), block):
        r = tri[None] - points[i:i + block, None, None]
        a, b, c = r[..., 0, :], r[..., 1, :], r[..., 2, :]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        num = (a * _cross(b, c)).sum(-1)
        den = la * lb * lc + (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
        out.append(2 * np.arctan2(num, den).sum(axis=1) / (4 * np.pi))
    return np.concatenate(out)


# ---- meshes ----

def mesh(name):
    """(vertices (V, 3), faces (F, 3) int64) of a test mesh."""
    if name == "icosphere":
        m = trimesh.creation.icosphere(2)
    elif name == "cube":
        m = trimesh.creation.box((2.0, 2.0, 2.0))
    elif name == "icosahedron":
        m = trimesh.load(SAMPLES / "icosahedron_binary.stl", process=False)
    elif name == "open-sphere":  # a cap removed
        s = trimesh.creation.icosphere(2)
        keep = s.triangles_center[:, 2] < 0.6
        m = trimesh.Trimesh(s.vertices, s.faces[keep], process=False)
    elif name == "inner-shell":  # the sphere and a copy at half size inside
        s = trimesh.creation.icosphere(2)
        m = trimesh.util.concatenate([s, trimesh.Trimesh(s.vertices * 0.5, s.faces, process=False)])
    elif name == "self-intersecting":  # two spheres through each other
        s = trimesh.creation.icosphere(2)
        m = trimesh.util.concatenate([s, trimesh.Trimesh(s.vertices + [0.8, 0.3, 0.1], s.faces, process=False)])
    elif name == "instanced":  # a box placed three times, rotated
        parts = []
        for k, shift in enumerate(([0, 0, 0], [3, 0.5, 0], [-1, 3, 1])):
            b = trimesh.creation.box((1.0, 2.0, 0.5))
            b.apply_transform(trimesh.transformations.rotation_matrix(0.4 * k + 0.3, [1, 2, 3 - k]))
            b.apply_translation(shift)
            parts.append(b)
        m = trimesh.util.concatenate(parts)
    elif name == "slivers":
        m = trimesh.load(SAMPLES / "narrow_triangles.obj", process=False, force="mesh")
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


CLOSED = ["icosphere", "cube", "icosahedron", "inner-shell", "instanced"]
ALL = CLOSED + ["open-sphere", "self-intersecting", "slivers"]


def query_points(tri, n=300, seed=0):
    """Points in the padded box, near the surface (within 1e-3 of the diagonal), at
    vertices and on edges: (m, 3) float64."""
    rng = np.random.default_rng(seed)
    lo, hi = tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0)
    pad = 0.1 * (hi - lo).max()
    box = rng.uniform(lo - pad, hi + pad, (n, 3))
    f = rng.integers(0, len(tri), n)
    w = rng.dirichlet([1, 1, 1], n)
    near = (tri[f] * w[:, :, None]).sum(1) + rng.normal(0, 1e-3 * np.linalg.norm(hi - lo), (n, 3))
    corners = tri[rng.integers(0, len(tri), 20), rng.integers(0, 3, 20)]
    g = rng.integers(0, len(tri), 20)
    edges = 0.5 * tri[g, 0] + 0.5 * tri[g, 1]
    return np.vstack([box, near, corners, edges])


def agrees(tree, tri, points):
    """Whether closest_points matches brute force: |distance| within 1e-9 of the diagonal,
    the closest point on the face named (within that), and as far from the point as said."""
    diag = np.linalg.norm(np.ptp(tri.reshape(-1, 3), axis=0))
    d, q, f = distance.closest_points(tree, points)
    exact = brute_distance(tri, points)
    on_face = pair_distance(tri[f], q)
    said = np.linalg.norm(points - q, axis=1)
    return bool(np.all(np.abs(d - exact) <= 1e-9 * diag) and np.all(on_face <= 1e-9 * diag)
                and np.all(np.abs(said - d) <= 1e-9 * diag))


def numpy_path(monkeypatch):
    monkeypatch.setattr(distance, "_kernel", None)
    monkeypatch.setattr(parity, "_kernel", None)


@pytest.fixture(params=["kernel", "numpy"])
def path(request, monkeypatch):
    if request.param == "numpy":
        numpy_path(monkeypatch)
    elif KERNEL is None:
        pytest.skip("compiled kernels not built")
    return request.param


# ---- distances ----

@pytest.mark.slow
@pytest.mark.parametrize("name", ALL)
def test_distances_are_exact(name, path):
    v, f = mesh(name)
    tri = v[f]
    tree = distance.TriangleTree(v, f)
    assert agrees(tree, tri, query_points(tri))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["icosphere", "instanced", "open-sphere"])
def test_a_tree_that_skips_a_node_fails(name, path):
    v, f = mesh(name)
    tri = v[f]
    points = query_points(tri)
    tree = distance.TriangleTree(v, f)
    # the node whose faces most points find closest: empty its box, so no walk enters it
    leaves = (len(tree.lo) + 1) // 2
    _, _, face = distance.closest_points(tree, points)
    slot = np.argsort(tree.order)[face]
    node = int(np.bincount(slot // tree.leaf).argmax()) + leaves - 1
    broken = distance.TriangleTree(v, f)  # (before its first query: the kernel keeps its own copy of the boxes)
    broken.lo[node], broken.hi[node] = np.inf, -np.inf
    assert not agrees(broken, tri, points)


def test_a_tree_pickles_without_the_kernels_copy():
    import pickle

    v, f = mesh("icosphere")
    tree = distance.TriangleTree(v, f)
    points = query_points(v[f])
    before = distance.closest_points(tree, points)
    again = distance.closest_points(pickle.loads(pickle.dumps(tree)), points)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(before, again))


def test_ties_go_to_the_lowest_face():
    v, f = mesh("cube")
    tree = distance.TriangleTree(v, f)
    far = v * 3.0  # each corner's closest point is that corner, on several faces
    d, q, face = distance.closest_points(tree, far)
    assert np.array_equal(q, v)
    lowest = [np.flatnonzero((f == i).any(axis=1)).min() for i in range(len(v))]
    assert np.array_equal(face, lowest)
    # the same triangle twice: the first one; reversed faces: still the least index
    tri = np.concatenate([v[f], v[f]])
    _, _, twice = distance.closest_points(distance.TriangleTree.from_triangles(tri), far)
    assert np.array_equal(twice, lowest)
    _, _, flipped = distance.closest_points(distance.TriangleTree(v, f[::-1]), far)
    assert np.array_equal(flipped, [np.flatnonzero((f[::-1] == i).any(axis=1)).min() for i in range(len(v))])


def test_triangles_and_indexed_faces_give_the_same_answer():
    v, f = mesh("icosahedron")
    points = query_points(v[f])
    a = distance.closest_points(distance.TriangleTree(v, f), points)
    b = distance.closest_points(distance.TriangleTree.from_triangles(v[f]), points)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


# ---- parity ----

@pytest.mark.slow
@pytest.mark.parametrize("name", CLOSED)
def test_parity_is_exact_on_closed_meshes(name, path):
    v, f = mesh(name)
    tri = v[f]
    points = query_points(tri)
    diag = np.linalg.norm(np.ptp(v, axis=0))
    off = brute_distance(tri, points) > 1e-9 * diag
    w = brute_winding(tri, points[off])
    expected = np.round(np.abs(w)).astype(int) % 2 == 1  # inside both shells: w = 2, even
    inside = parity.parity_inside(distance.TriangleTree(v, f), points[off])
    assert np.array_equal(inside, expected)


def grazing(v, f, direction, steps=(0.25, 0.5, 1.0)):
    """Points whose ray along ``direction`` (dyadic components) runs through a vertex or
    the midpoint of an edge of v[f]: (m, 3)."""
    edges = 0.5 * v[f[:, [0, 1, 2]]] + 0.5 * v[f[:, [1, 2, 0]]]
    targets = np.vstack([v, edges.reshape(-1, 3)])
    return np.vstack([targets - s * np.asarray(direction) for s in steps])


RAY = (0.5, 0.25, 1.0)  # sheared exactly: its rays meet the target points exactly


def no_tie_rule(e, ex, ey):
    """a broken side(): an edge function of 0 counts as inside for both faces of the edge"""
    return np.where(e >= 0, 1, -1).astype(np.int8)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cube", "icosahedron", "icosphere"])
@pytest.mark.parametrize("broken", [False, True])
def test_parity_counts_a_crossing_at_an_edge_or_vertex_once(name, broken, path, monkeypatch):
    v, f = mesh(name)
    tri = v[f]
    points = grazing(v, f, RAY)
    diag = np.linalg.norm(np.ptp(v, axis=0))
    points = points[brute_distance(tri, points) > 1e-6 * diag]
    expected = np.abs(brute_winding(tri, points)) > 0.5
    if broken:
        numpy_path(monkeypatch)
        monkeypatch.setattr(parity, "side", no_tie_rule)
    inside = parity.parity_inside(distance.TriangleTree(v, f), points, dirs=[RAY])
    assert np.array_equal(inside, expected) != broken


@pytest.mark.parametrize("name", ["cube", "icosahedron"])
def test_the_fixed_rays_outvote_a_grazing_one(name, path):
    v, f = mesh(name)
    dirs = parity.directions(3)
    # points whose first fixed ray runs through a vertex or an edge's midpoint
    points = grazing(v, f, dirs[0], steps=(0.3, 0.7, 1.3))
    tri = v[f]
    diag = np.linalg.norm(np.ptp(v, axis=0))
    points = points[brute_distance(tri, points) > 1e-6 * diag]
    expected = np.abs(brute_winding(tri, points)) > 0.5
    assert np.array_equal(parity.parity_inside(distance.TriangleTree(v, f), points), expected)


def test_the_fixed_directions_are_off_the_axes_and_diagonals():
    d = parity.directions(7)
    a = np.sort(np.abs(d), axis=1)
    assert np.allclose(np.linalg.norm(d, axis=1), 1) and a.min() >= 0.1 and np.diff(a, axis=1).min() >= 0.1
    assert np.array_equal(parity.directions(3), d[:3])


# ---- the two paths, threads ----

@needs_kernel
@pytest.mark.parametrize("name", ALL)
def test_kernel_and_numpy_give_the_same_bytes(name, monkeypatch):
    v, f = mesh(name)
    tree = distance.TriangleTree(v, f)
    points = query_points(v[f], seed=3)
    kernel = distance.closest_points(tree, points) + (parity.parity_inside(tree, points, rays=5),)
    numpy_path(monkeypatch)
    numpy_tree = distance.TriangleTree(v, f)
    for field in ("order", "triangles", "thin", "lo", "hi"):
        assert getattr(numpy_tree, field).tobytes() == getattr(tree, field).tobytes(), field
    twin = distance.closest_points(numpy_tree, points) + (parity.parity_inside(numpy_tree, points, rays=5),)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(kernel, twin))


@pytest.mark.slow
@needs_kernel
def test_threads_and_chunks_change_nothing(monkeypatch):
    v, f = mesh("self-intersecting")
    tree = distance.TriangleTree(v, f)
    points = query_points(v[f], n=3000, seed=5)
    monkeypatch.setenv("SCATTER_THREADS", "1")
    one = distance.closest_points(tree, points) + (parity.parity_inside(tree, points),)
    monkeypatch.setenv("SCATTER_THREADS", "3")
    three = distance.closest_points(tree, points) + (parity.parity_inside(tree, points),)
    for threads in ("2", "7", "20"):  # (20: more than the kernels start)
        monkeypatch.setenv("SCATTER_THREADS", threads)
        more = distance.closest_points(tree, points) + (parity.parity_inside(tree, points),)
        assert all(a.tobytes() == b.tobytes() for a, b in zip(one, more)), threads
    halves = [distance.closest_points(tree, points[s]) + (parity.parity_inside(tree, points[s]),)
              for s in (slice(0, 1234), slice(1234, None))]
    chunked = tuple(np.concatenate([h[k] for h in halves]) for k in range(4))
    monkeypatch.setattr(distance, "CHUNK", 700)
    small = distance.closest_points(tree, points) + (parity.parity_inside(tree, points),)
    assert all(a.tobytes() == b.tobytes() == c.tobytes() == d.tobytes() for a, b, c, d in zip(one, three, chunked, small))


# ---- bad input ----

def test_bad_input_is_refused():
    v, f = mesh("cube")
    for bad in (f + len(v), f - len(v), f[:, :2]):
        with pytest.raises(ValueError):
            distance.TriangleTree(v, bad)
    for vertices in (np.where(v > 0, np.nan, v), np.where(v > 0, np.inf, v)):
        with pytest.raises(ValueError):
            distance.TriangleTree(vertices, f)
    with pytest.raises(ValueError):
        distance.TriangleTree(v, f[:0])
    tree = distance.TriangleTree(v, f)
    for points in (np.array([[0.0, np.nan, 0.0]]), np.array([[0.0, np.inf, 0.0]]), np.zeros((2, 2)),
                   np.array([[0.0, 1e70, 0.0]])):
        with pytest.raises(ValueError):
            distance.closest_points(tree, points)
        with pytest.raises(ValueError):
            parity.parity_inside(tree, points)


@needs_kernel
def test_the_kernel_refuses_bad_arrays():
    v, f = mesh("icosphere")
    t = distance.TriangleTree(v, f)
    p = np.zeros((4, 3))
    out = (np.empty(4), np.empty((4, 3)), np.empty(4, np.int64))
    visit = np.arange(4)

    def call(tri=t.triangles, order=t.order, thin=t.thin, lo=t.lo, hi=t.hi, leaf=t.leaf, points=p, visit=visit, tol=0.0,
             outs=out, wide=None):
        KERNEL.closest(tri, order, thin, lo, hi, leaf, points, visit, tol, *outs, 2, wide)

    call()  # the good calls pass, without and with the tree's wide form
    call(wide=t.wide())
    other = distance.TriangleTree(*mesh("cube"))
    nan = t.triangles.copy()
    nan[3, 4] = np.nan
    bad_order = t.order.copy()
    bad_order[0] = len(f)
    cases = [dict(tri=nan), dict(order=bad_order), dict(order=t.order[:-1]), dict(thin=t.thin[:-1]), dict(thin=t.thin.view(bool)), dict(lo=t.lo[:-1], hi=t.hi[:-1]),
             dict(leaf=0), dict(leaf=t.leaf * 2), dict(points=np.full((4, 3), np.nan)), dict(points=np.zeros((4, 2))),
             dict(points=np.zeros((4, 3), np.float32)), dict(visit=np.array([0, 1, 1, 3])),
             dict(visit=np.array([0, 1, 2, 4])), dict(tol=np.nan), dict(outs=(np.empty(3),) + out[1:]),
             dict(tri=np.asfortranarray(t.triangles)), dict(wide=other.wide()), dict(wide=t.lo)]
    for case in cases:
        with pytest.raises((ValueError, TypeError)):
            call(**case)
    axes, shear, inverse = parity.shears(parity.directions(3))
    inside = np.empty(4, bool)
    KERNEL.crossings(t.triangles, t.order, t.thin, t.lo, t.hi, t.leaf, p, axes, shear, inverse, 0.0, inside, 2)
    bad_axes = axes.copy()
    bad_axes[0] = (0, 0, 2)
    for args in ((bad_axes, shear, inverse, 0.0), (axes, shear, np.zeros_like(inverse), 0.0),
                 (axes, shear, inverse, -1.0), (axes, shear[:2], inverse, 0.0)):
        with pytest.raises((ValueError, TypeError)):
            KERNEL.crossings(t.triangles, t.order, t.thin, t.lo, t.hi, t.leaf, p, *args, inside, 2)
    with pytest.raises(ValueError):
        KERNEL.order(np.full((5, 9), np.nan), 4, 2)
    for bad in (t.triangles.reshape(-1, 3), t.triangles[:, :6]):
        with pytest.raises(ValueError):
            KERNEL.order(np.ascontiguousarray(bad), t.leaf, len(t.lo) // 2 + 1)
    assert KERNEL.thin(t.triangles).tobytes() == t.thin.tobytes()
    assert all(a.tobytes() == b.tobytes() for a, b in zip(KERNEL.boxes(t.triangles, t.leaf, len(t.lo) // 2 + 1), (t.lo, t.hi)))
    for args in ((t.triangles.reshape(-1, 3),), (t.triangles.astype(np.float32),), (np.asfortranarray(t.triangles),)):
        with pytest.raises((ValueError, TypeError)):
            KERNEL.thin(*args)
        with pytest.raises((ValueError, TypeError)):
            KERNEL.boxes(*args, t.leaf, len(t.lo) // 2 + 1)
    for leaf, leaves in ((0, 64), (t.leaf, len(t.lo) // 2), (t.leaf, len(t.lo) + 1), (t.leaf, 3), (65, 1)):
        with pytest.raises(ValueError):  # too few leaves, more than needed, not a power of two, too wide
            KERNEL.boxes(t.triangles, leaf, leaves)


# ---- fuzz ----

@pytest.mark.slow
@needs_kernel
@settings(max_examples=60, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), faces=st.integers(1, 40), scale=st.sampled_from([1e-100, 1e-8, 1.0, 1e8, 1e100]),
       degenerate=st.sampled_from(["none", "points", "segments", "duplicates", "slivers"]))
def test_fuzz_kernel_against_numpy_and_brute_force(seed, faces, scale, degenerate, monkeypatch):
    rng = np.random.default_rng(seed)
    tri = rng.normal(size=(faces, 3, 3)) * scale
    k = rng.integers(0, faces, max(1, faces // 3))
    if degenerate == "points":
        tri[k] = tri[k, :1]
    elif degenerate == "segments":
        tri[k, 2] = tri[k, 0] * 0.25 + tri[k, 1] * 0.75
    elif degenerate == "duplicates":
        tri[k] = tri[0]
    elif degenerate == "slivers":
        tri[k, 2] = tri[k, 0] * 0.5 + tri[k, 1] * 0.5 + rng.normal(size=(len(k), 3)) * scale * 1e-9
    # points anywhere, at corners, and just off the faces (where the faces' disks and the
    # nodes' cylinders bound the distance most tightly)
    w = rng.dirichlet(np.ones(3), 20)
    on = np.einsum("ij,ijk->ik", w, tri[rng.integers(0, faces, 20)])
    points = np.vstack([rng.normal(size=(40, 3)) * scale * 2, tri[rng.integers(0, faces, 10), 0],
                        on + rng.normal(size=(20, 3)) * scale * 10.0 ** rng.integers(-12, 0, (20, 1))])
    tree = distance.TriangleTree.from_triangles(tri)
    kernel = distance.closest_points(tree, points) + (parity.parity_inside(tree, points),)
    with monkeypatch.context() as m:
        numpy_path(m)
        twin = distance.closest_points(tree, points) + (parity.parity_inside(tree, points),)
        numpy_tree = distance.TriangleTree.from_triangles(tri)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(kernel, twin))
    assert all(getattr(tree, k).tobytes() == getattr(numpy_tree, k).tobytes() for k in ("order", "thin", "lo", "hi"))
    d, q, face = kernel[:3]
    extent = np.abs(tri).max() + np.abs(points).max()
    # brute force at unit scale (scale is not a power of two: exact to 1e-15)
    assert np.all(np.abs(d / scale - brute_distance(tri / scale, points / scale)) <= 1e-9 * extent / scale)
    assert np.all(pair_distance(tri[face] / scale, q / scale) <= 1e-9 * extent / scale)


@pytest.mark.slow
@needs_kernel
@settings(max_examples=60, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 3000), scale=st.sampled_from([1e-100, 1.0, 1e100]),
       flat=st.booleans(), tied=st.booleans())
def test_kernel_visit_order_is_numpys(seed, n, scale, flat, tied):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3)) * scale
    if flat:
        p[:, 1] = 0.5  # one axis without extent
    if tied:
        p = np.round(p / scale * 2) * scale / 2
    got = KERNEL.visit(np.ascontiguousarray(p))
    saved, distance._kernel = distance._kernel, None
    try:
        want = distance.visit_order(p)
    finally:
        distance._kernel = saved
    assert got.tobytes() == want.tobytes()
    with pytest.raises(ValueError):
        KERNEL.visit(np.array([[0.0, np.nan, 0.0]]))
