"""Winding numbers (scatter_cli/volume/winding.py) against brute force, and the compiled kernel
against its NumPy twin.

The reference is the exact winding number, the sum of every triangle's solid angle over
4 pi (van Oosterom and Strackee's formula with np.arctan2), written here independently of
the module. On closed, open, nested, self-intersecting and instanced surfaces the fast
value must be within 0.02 of it at points farther than 1e-3 of the diagonal from the
surface, and its label (w >= 0.5) must equal the exact one wherever the exact w is not
within 0.05 of 0.5. Each case is paired with a broken evaluation that must fail those
checks: nodes expanded when barely farther than their radius (accuracy 0.5), and the
dipole alone (order 0) at the default accuracy.
"""

import os

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from scatter_cli.core import native
from scatter_cli.volume import distance, winding
from scatter_cli.volume.winding import WindingTree, winding_numbers

from .conftest import SAMPLES

KERNEL = winding._kernel
needs_kernel = pytest.mark.skipif(
    KERNEL is None and os.environ.get("SCATTER_REQUIRE_KERNELS", "") in ("", "0"),
    reason="compiled kernels not built (SCATTER_REQUIRE_KERNELS=1 makes this a failure)",
)
CLOSE = 0.02  # |w - exact| away from the surface
MARGIN = 0.05  # labels must be right where |exact - 0.5| >= MARGIN
AWAY = 1e-3  # of the diagonal: "away from the surface"


def exact_winding(tri, points, chunk=32):
    """(n,) exact winding numbers of triangles ``tri`` (F, 3, 3) at ``points`` (n, 3): the sum
    of every triangle's solid angle (van Oosterom and Strackee), over 4 pi."""
    corner = tri.reshape(-1, 9).T  # (9, F): one row per coordinate, so each step is one array op
    out = np.empty(len(points))
    for at in range(0, len(points), chunk):
        q = points[at:at + chunk]
        ax, ay, az, bx, by, bz, cx, cy, cz = (corner[k][None, :] - q[:, k % 3, None] for k in range(9))
        la, lb, lc = np.sqrt(ax * ax + ay * ay + az * az), np.sqrt(bx * bx + by * by + bz * bz), np.sqrt(cx * cx + cy * cy + cz * cz)
        det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
        den = la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (bx * cx + by * cy + bz * cz) * la + (cx * ax + cy * ay + cz * az) * lb
        out[at:at + chunk] = np.arctan2(det, den).sum(axis=1) / (2 * np.pi)
    return out


def distance_to(tri, points):
    """(n,) distance from ``points`` to the triangles ``tri`` (F, 3, 3): the volume's exact
    closest points, which tests/test_distance.py holds to brute force."""
    return distance.closest_points(distance.TriangleTree.from_triangles(tri), points)[0]


def query_points(tri, n_box=1200, n_near=600, seed=0):
    """Points uniform in the box grown by 0.1 of its largest side, and points within 1e-3..3e-2
    of the diagonal from surface points along the face normals, on both sides."""
    rng = np.random.default_rng(seed)
    lo, hi = tri.reshape(-1, 3).min(axis=0), tri.reshape(-1, 3).max(axis=0)
    pad = 0.1 * (hi - lo).max()
    box = rng.uniform(lo - pad, hi + pad, size=(n_box, 3))
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    face = rng.choice(len(tri), size=n_near, p=area / area.sum())
    u, v = rng.random(n_near), rng.random(n_near)
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    t = tri[face]
    on = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    normal = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    diag = np.linalg.norm(hi - lo)
    offset = rng.choice([-1, 1], n_near) * diag * np.exp(rng.uniform(np.log(1e-3), np.log(3e-2), n_near))
    return np.vstack([box, on + offset[:, None] * normal])


def icosphere(subdivisions=3, radius=1.0, centre=(0, 0, 0)):
    m = trimesh.creation.icosphere(subdivisions, radius=radius)
    return m.triangles + np.asarray(centre, float)


def open_sphere():
    """An icosphere with the cap z > 0.6 removed."""
    tri = icosphere(3)
    return tri[tri[:, :, 2].max(axis=1) <= 0.6]


def instanced():
    """Three rotated, scaled and moved copies of a torus, as world-space triangles."""
    torus = trimesh.creation.torus(1.0, 0.35, major_sections=24, minor_sections=12).triangles
    rng = np.random.default_rng(5)
    out = []
    for k in range(3):
        rot = trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3]
        out.append(torus @ rot.T * (0.6 + 0.3 * k) + np.array([1.6 * k, 0.4 * k, -0.3 * k]))
    return np.concatenate(out)


def sample(name):
    return trimesh.load(SAMPLES / name, force="mesh").triangles


CASES = {
    "icosphere": lambda: icosphere(3),
    "icosahedron_stl": lambda: sample("icosahedron_binary.stl"),
    "skull": lambda: sample("skull.ply"),
    "open_sphere": open_sphere,
    "hemisphere_off": lambda: sample("hemisphere.off"),
    "inner_shell": lambda: np.concatenate([icosphere(3), icosphere(2, 0.5)]),  # w = 2 inside both
    "self_intersecting": lambda: np.concatenate([icosphere(3), icosphere(3, 0.8, (0.9, 0.2, 0.1))]),
    "instanced": instanced,
}
FEW_POINTS = {"skull": (240, 120)}  # brute force on 100k faces: fewer points


@pytest.fixture(scope="module")
def case_data():
    """name -> (triangles, points, exact w, points away from the surface) on demand."""
    cache = {}

    def get(name):
        if name not in cache:
            tri = np.ascontiguousarray(CASES[name](), dtype=np.float64)
            points = query_points(tri, *FEW_POINTS.get(name, (1200, 600)))
            diag = np.linalg.norm(np.ptp(tri.reshape(-1, 3), axis=0))
            cache[name] = (tri, points, exact_winding(tri, points), distance_to(tri, points) > AWAY * diag)
        return cache[name]

    return get


def failures(w, exact, away):
    """(points off by more than CLOSE away from the surface, wrong labels off the margin)."""
    off = np.count_nonzero(away & (np.abs(w - exact) > CLOSE))
    wrong = np.count_nonzero((np.abs(exact - 0.5) >= MARGIN) & ((w >= 0.5) != (exact >= 0.5)))
    return off, wrong


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_winding_numbers_match_brute_force(name, case_data):
    tri, points, exact, away = case_data(name)
    assert away.sum() > 0.8 * len(points)
    w = winding_numbers(WindingTree(tri), points)
    assert failures(w, exact, away) == (0, 0)
    assert np.abs(w - exact)[away].max() <= CLOSE


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
@pytest.mark.parametrize("broken", [{"accuracy": 0.5}, {"order": 0}])
def test_broken_evaluations_fail_the_same_checks(name, broken, case_data):
    tri, points, exact, away = case_data(name)
    if broken == {"order": 0} and name in ("icosahedron_stl",):
        pytest.skip("20 faces: too few nodes for the dipole's error to show")
    assert failures(winding_numbers(WindingTree(tri), points, **broken), exact, away) != (0, 0)


@pytest.mark.slow
def test_the_reference_sees_a_flipped_triangle(case_data):
    """The checks are sharp enough to catch one triangle turned over."""
    tri, points, exact, away = case_data("icosphere")
    flipped = tri.copy()
    flipped[0] = flipped[0, ::-1]
    assert failures(winding_numbers(WindingTree(flipped), points), exact, away) != (0, 0)


@pytest.mark.slow
def test_closed_surfaces_give_whole_numbers_away_from_them(case_data):
    tri, points, exact, away = case_data("inner_shell")
    w = winding_numbers(WindingTree(tri), points)
    assert set(np.round(exact[away]).astype(int)) == {0, 1, 2}
    assert np.abs(w - np.round(exact))[away].max() <= CLOSE


def test_indexed_and_soup_input_build_the_same_tree():
    m = trimesh.creation.icosphere(2)
    a, b = WindingTree(m.vertices, m.faces), WindingTree(m.triangles)
    assert np.array_equal(a.nodes, b.nodes) and np.array_equal(a.links, b.links)
    assert np.array_equal(a.triangles, b.triangles) and np.array_equal(a.face, b.face)


def test_tree_covers_every_triangle_once_within_each_nodes_radius():
    tri = instanced()
    tri[7] = tri[7, [0, 0, 1]]  # zero area: left out
    tri[9, 1, 2] = np.nan  # not finite: left out
    tree = WindingTree(tri)
    assert sorted(tree.face) == sorted(set(range(len(tri))) - {7, 9})
    assert np.array_equal(tree.triangles.reshape(-1, 3, 3), tri[tree.face])
    skip, first, count = tree.links.T
    n = len(skip)
    leaf = count > 0
    assert np.array_equal(leaf, skip == np.arange(n) + 1)  # leaves are exactly the nodes without children
    assert np.array_equal(np.sort(first[leaf]), np.cumsum(np.r_[0, count[leaf]])[:-1])  # leaves tile the triangles
    assert np.all(count <= winding.LEAF)
    # each node's triangles are its leaves' triangles; all their corners within its radius
    for i in range(n):
        inside = (np.arange(n) >= i) & (np.arange(n) < skip[i]) & leaf
        idx = np.concatenate([np.arange(f, f + c) for f, c in zip(first[inside], count[inside])])
        corners = tree.triangles[idx].reshape(-1, 3)
        assert np.linalg.norm(corners - tree.nodes[i, :3], axis=1).max() <= tree.nodes[i, 3] * (1 + 1e-12)


def test_infinite_accuracy_is_the_exact_sum(case_data):
    tri, points, exact, _ = case_data("open_sphere")
    w = winding_numbers(WindingTree(tri), points, accuracy=float("inf"))
    assert np.abs(w - exact).max() < 1e-12
    assert np.abs(winding_numbers(WindingTree(tri), points) - exact).max() > 1e-6  # (the default is not exact)


def test_non_finite_points_get_nan_and_no_faces_give_zero():
    tree = WindingTree(icosphere(1))
    w = winding_numbers(tree, np.array([[np.nan, 0, 0], [0, np.inf, 0], [0, 0, 0]]))
    assert np.isnan(w[:2]).all() and abs(w[2] - 1) < 1e-12
    assert np.array_equal(winding_numbers(WindingTree(np.zeros((0, 3, 3))), np.ones((4, 3))), np.zeros(4))


def test_bad_options_are_refused():
    tree = WindingTree(icosphere(1))
    for bad in ({"order": 3}, {"accuracy": 0.0}, {"accuracy": float("nan")}):
        with pytest.raises(ValueError):
            winding_numbers(tree, np.zeros((1, 3)), **bad)


# ---- the kernel and its NumPy twin ----

def numpy_winding(monkeypatch, tree, points, **kw):
    with monkeypatch.context() as m:
        m.setattr(winding, "_kernel", None)
        return winding_numbers(tree, points, **kw)


@needs_kernel
def test_the_kernel_is_built():
    assert KERNEL is not None and KERNEL.FIELDS == winding.FIELDS


@pytest.mark.slow
@needs_kernel
@pytest.mark.parametrize("name", CASES)
@pytest.mark.parametrize("options", [{}, {"order": 0, "accuracy": 1.0}, {"order": 1, "accuracy": 3.0}])
def test_kernel_and_numpy_give_the_same_bytes(name, options, case_data, monkeypatch):
    tri, points, _, _ = case_data(name)
    tree = WindingTree(tri)
    k = winding_numbers(tree, points, **options)
    assert k.tobytes() == numpy_winding(monkeypatch, tree, points, **options).tobytes()


@pytest.mark.slow
@needs_kernel
def test_same_bytes_whatever_the_threads_and_chunks(case_data, monkeypatch):
    tri, points, _, _ = case_data("self_intersecting")
    tree = WindingTree(tri)
    ref = winding_numbers(tree, points)
    for threads, chunk in ((1, 7), (2, 1 << 20), (3, 600), (7, 1 << 20), (8, 1 << 20), (20, 1 << 20)):
        monkeypatch.setattr(native, "worker_count", lambda t=threads: t)
        monkeypatch.setattr(winding, "CHUNK", chunk)
        assert winding_numbers(tree, points).tobytes() == ref.tobytes()
        if threads in (3, 8):  # the NumPy walk's steps are whole-chunk array ops: tiny chunks only cost time
            assert numpy_winding(monkeypatch, tree, points).tobytes() == ref.tobytes()
    # the parity check is sharp: the same terms added in another order change some bytes
    reordered = WindingTree(tri)
    for f, c in reordered.links[reordered.links[:, 2] > 1][:, 1:]:
        reordered.triangles[f:f + c] = reordered.triangles[f:f + c][::-1].copy()
    assert winding_numbers(reordered, points).tobytes() != ref.tobytes()


def kernel_args(tree, points):
    out = np.empty(len(points))
    return [points, tree.nodes, tree.links, tree.triangles, 2.0, 2, 2, out]


@needs_kernel
def test_kernel_refuses_bad_arrays():
    tree = WindingTree(icosphere(1))
    points = np.zeros((5, 3))
    good = kernel_args(tree, points)
    KERNEL.winding(*good)
    bad_links = []
    inner = tree.links[1, 0]  # the end of the root's left subtree: a node inside it ends after it
    for row, col, value in ((0, 0, 0), (3, 0, 3), (0, 0, len(tree.links) + 1), (len(tree.links) - 1, 1, -1),
                            (len(tree.links) - 1, 2, len(tree.triangles)), (len(tree.links) - 1, 2, -1),
                            (2, 0, inner + 1)):
        links = tree.links.copy()
        links[row, col] = value
        bad_links.append(links)
    assert 2 < inner < len(tree.links) - 1
    readonly = np.empty(5)
    readonly.flags.writeable = False
    bad = [
        (0, points.astype(np.float32)), (0, np.zeros((5, 2))), (0, np.zeros((3, 5)).T), (0, [[0.0, 0, 0]]),
        (1, tree.nodes[:, :-1].copy()), (1, tree.nodes[:-1]), (2, tree.links.astype(np.int32)),
        (3, tree.triangles.reshape(-1, 3)), (4, "2"), (5, 3), (5, -1), (6, 0), (7, np.empty(4)),
        (7, np.empty(5, np.float32)), (7, readonly),
    ] + [(2, links) for links in bad_links]
    for at, value in bad:
        args = list(good)
        args[at] = value
        with pytest.raises((TypeError, ValueError)):
            KERNEL.winding(*args)


finite = st.floats(-1e6, 1e6, allow_nan=False, width=64)
coordinate = st.one_of(finite, st.sampled_from([0.0, 1e-300, -1e-300, 1e300, -1e300, np.nan, np.inf]))


@pytest.mark.slow
@needs_kernel
@settings(max_examples=60)
@given(st.lists(st.tuples(*[coordinate] * 9), min_size=0, max_size=40),
       st.lists(st.tuples(*[coordinate] * 3), min_size=1, max_size=30),
       st.sampled_from([0.3, 1.0, 2.0]), st.integers(0, 2))
def test_fuzzed_soups_give_the_same_bytes_on_both_paths(tris, points, accuracy, order):
    """Winding numbers, and the trees built with the kernel's helpers and without."""
    tri = np.array(tris, dtype=np.float64).reshape(-1, 3, 3)
    tri = np.concatenate([tri, tri[:3, [0, 0, 1]]])  # and some zero-area copies
    points = np.array(points, dtype=np.float64)
    with np.errstate(all="ignore"):
        tree = WindingTree(tri)
        k = winding_numbers(tree, points, accuracy=accuracy, order=order)
        saved, winding._kernel = winding._kernel, None
        try:
            n = winding_numbers(tree, points, accuracy=accuracy, order=order)
            numpy_tree = WindingTree(tri)
        finally:
            winding._kernel = saved
    assert k.tobytes() == n.tobytes()
    assert tree.nodes.tobytes() == numpy_tree.nodes.tobytes() and tree.links.tobytes() == numpy_tree.links.tobytes()


@pytest.mark.slow
@needs_kernel
@settings(max_examples=60)
@given(st.lists(st.tuples(st.integers(-3, 40), st.integers(-3, 80), st.integers(-3, 12)), min_size=1, max_size=30))
def test_fuzzed_links_are_refused_or_walked_safely(rows):
    """Random links: the kernel refuses them, or walks them within its arrays (the
    sanitizer run, benchmarks/winding_sanitizers.py, checks that) as the NumPy path does."""
    nodes = np.random.default_rng(len(rows)).normal(size=(len(rows), winding.FIELDS))
    links = np.array(rows, dtype=np.int64)
    tri = np.random.default_rng(1).normal(size=(64, 9))
    points = np.random.default_rng(2).normal(size=(7, 3))
    out = np.empty(7)
    try:
        KERNEL.winding(points, nodes, links, tri, 1.0, 2, 2, out)
        tree = type("Tree", (), {"nodes": nodes, "links": links, "triangles": tri})
        with np.errstate(all="ignore"):
            assert out.tobytes() == winding._numpy_winding(points, tree, 1.0, 2).tobytes()
    except ValueError:
        skip, first, count = links.T
        i = np.arange(len(links))
        assert np.any((skip <= i) | (skip > len(links)) | (first < 0) | (first > 64) | (count < 0)
                      | (count > 64 - first)) or not nested(skip)


def nested(skip):
    """Whether the subtrees [i, skip[i]) of a preorder tree nest: none ends after one it
    starts in."""
    return all(skip[j] <= skip[i] for i in range(len(skip)) for j in range(i + 1, min(skip[i], len(skip))))


@pytest.mark.slow
@needs_kernel
@settings(max_examples=80)
@given(st.lists(st.tuples(*[coordinate] * 3), min_size=0, max_size=60))
def test_kernel_morton_codes_and_order_are_numpys(points):
    """The kernel's Morton codes (tree and query order) and their stable order are the
    NumPy functions', on finite, huge, tied and non-finite coordinates; and the tree built
    with either is the same."""
    p = np.array(points, dtype=np.float64).reshape(-1, 3)
    p = np.concatenate([p, p[: len(p) // 2]])  # ties
    saved = winding._kernel
    with np.errstate(all="ignore"):
        codes, order = winding._morton(p), winding._stable_order(winding._morton(p))
        winding._kernel = None
        try:
            want, want_order = winding._morton(p), np.argsort(winding._morton(p), kind="stable")
        finally:
            winding._kernel = saved
    assert codes.dtype == want.dtype and codes.tobytes() == want.tobytes()
    assert order.tobytes() == want_order.astype(np.int64).tobytes()


def _numpy_layout(codes, leaf, top_bit=None):
    """winding._layout on the NumPy path (with another ``_top_bit``: a broken variant)."""
    saved, saved_top = winding._kernel, winding._top_bit
    winding._kernel = None
    if top_bit is not None:
        winding._top_bit = top_bit
    try:
        return winding._layout(codes, leaf)
    finally:
        winding._kernel, winding._top_bit = saved, saved_top


@needs_kernel
@settings(max_examples=80, deadline=None)
@given(codes=st.lists(st.one_of(st.integers(0, 2**63 - 1), st.integers(0, 7), st.sampled_from([0, 1 << 40, 3 << 40])),
                      max_size=300), leaf=st.integers(1, 9))
def test_kernel_layout_is_numpys(codes, leaf):
    """The kernel's nodes over sorted codes (distinct, tied, all equal, sharing high bits)
    are _layout's, and it refuses codes out of order."""
    codes = np.sort(np.array(codes, dtype=np.uint64))
    got = KERNEL.layout(codes, leaf)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(got, _numpy_layout(codes, leaf)))
    if len(np.unique(codes)) > 1:
        with pytest.raises(ValueError):
            KERNEL.layout(np.ascontiguousarray(codes[::-1]), leaf)
    with pytest.raises(ValueError):
        KERNEL.layout(codes, 0)


@needs_kernel
@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(*[coordinate] * 9), min_size=0, max_size=30))
def test_kernel_area_normals_and_centroids_are_numpys(rows):
    """The kernel's area normals and centroids are the NumPy path's, on finite, huge and
    non-finite corners."""
    tri = np.array(rows, dtype=np.float64).reshape(-1, 3, 3)
    with np.errstate(all="ignore"):
        an, g = KERNEL.faces(np.ascontiguousarray(tri.reshape(-1, 9)))
        want_an, want_g = winding._area_normals(tri), (tri[:, 0] + tri[:, 1] + tri[:, 2]) / 3.0
    np.testing.assert_array_equal(an, want_an)
    np.testing.assert_array_equal(g, want_g)
    with pytest.raises((TypeError, ValueError)):
        KERNEL.faces(tri.reshape(-1, 3))


@needs_kernel
def test_a_layout_split_at_the_wrong_bit_is_not_the_kernels():
    """The paired failure: splitting where the last code begins (bit 0) instead of at
    the top differing bit gives other nodes than the kernel's."""
    codes = np.array([0, 1, 2, 3, 8, 9, 10, 11], dtype=np.uint64)
    got = KERNEL.layout(codes, 1)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(got, _numpy_layout(codes, 1)))
    broken = _numpy_layout(codes, 1, lambda x: np.zeros(len(x), np.uint64))
    assert any(a.tobytes() != b.tobytes() for a, b in zip(got, broken))


@pytest.mark.slow
def test_trees_built_with_and_without_the_kernel_are_the_same(monkeypatch):
    mesh = trimesh.load(SAMPLES / "skull.ply", process=False)
    a = WindingTree(np.asarray(mesh.vertices, float), np.asarray(mesh.faces))
    monkeypatch.setattr(winding, "_kernel", None)
    b = WindingTree(np.asarray(mesh.vertices, float), np.asarray(mesh.faces))
    assert all(x.tobytes() == y.tobytes() for x, y in zip((a.nodes, a.links, a.triangles, a.face),
                                                         (b.nodes, b.links, b.triangles, b.face)))


@needs_kernel
def test_kernel_morton_refuses_bad_arrays():
    for bad in (np.zeros((4, 2)), np.zeros((4, 3), np.float32), np.zeros((3, 4)).T):
        with pytest.raises((TypeError, ValueError)):
            KERNEL.morton(bad)
    for bad in (np.array([2**63], np.uint64), np.zeros(3, np.int64)):
        with pytest.raises((TypeError, ValueError)):
            KERNEL.order(bad)


@needs_kernel
def test_kernel_radii_refuses_bad_arrays():
    tree = WindingTree(icosphere(1))
    skip, start, count = (tree.links[:, k].copy() for k in range(3))
    end = np.array([(start[k:skip[k]] + count[k:skip[k]]).max() for k in range(len(skip))])  # its last leaf's end
    centre = np.ascontiguousarray(tree.nodes[:, :3])
    out = np.empty(len(skip))
    KERNEL.radii(tree.triangles, centre, start, end, skip, out)
    assert out.tobytes() == tree.nodes[:, 3].tobytes()
    empty, beyond = end.copy(), end.copy()
    empty[3], beyond[-1] = start[3], len(tree.triangles) + 1
    for args in ((tree.triangles, centre, start, empty, skip, out), (tree.triangles, centre, start, beyond, skip, out),
                 (tree.triangles, centre, start - 1, end, skip, out), (tree.triangles, centre[:-1], start, end, skip, out),
                 (tree.triangles.reshape(-1, 3), centre, start, end, skip, out),
                 (tree.triangles, centre, start, end, skip, np.empty(len(skip), np.float32))):
        with pytest.raises((TypeError, ValueError)):
            KERNEL.radii(*args)


@needs_kernel
def test_kernel_subtree_sums_are_numpys_and_refuse_bad_arrays(monkeypatch):
    tree = WindingTree(icosphere(2))
    skip, start = tree.links[:, 0].copy(), tree.links[:, 1].copy()
    rng = np.random.default_rng(2)
    rows = rng.normal(size=(5, len(tree.triangles))) * 10.0 ** rng.integers(-300, 300, size=(5, len(tree.triangles)))
    rows[rng.random(rows.shape) < 0.2] = -0.0
    rows[0, 7], rows[1, 9], rows[2, 11] = np.inf, -np.inf, np.nan
    out = np.empty((len(skip), 5))
    KERNEL.subtree_sums(rows, start, skip, out)
    monkeypatch.setattr(winding, "_kernel", None)
    with np.errstate(all="ignore"):
        assert out.tobytes() == winding._subtree_sums(rows, start, skip).tobytes()
    leaves = np.flatnonzero(tree.links[:, 2] > 0)
    big = np.flatnonzero(tree.links[leaves[:-1], 2] >= 6)[0]
    wide = start.copy()
    wide[leaves[big + 1]] += 3  # the leaf before takes 3 more triangles: more than 8
    for args in ((rows, wide, skip, out), (rows, start - 1, skip, out), (rows, start + len(tree.triangles), skip, out),
                 (rows, start, np.where(skip == len(skip), len(skip) + 5, skip), out), (rows[0], start, skip, out),
                 (rows, start, skip, out[:, :4].copy()), (rows, start, skip[:-1], out)):
        with pytest.raises((TypeError, ValueError)):
            KERNEL.subtree_sums(*args)


@needs_kernel
def test_kernel_moments_refuse_bad_arrays():
    tri = icosphere(1)
    an = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centroid, origin = tri.mean(axis=1), np.zeros(3)
    flat, out = tri.reshape(-1, 9), np.empty((34, len(tri)))
    KERNEL.moments(flat, an, centroid, origin, out)
    for args in ((flat, an[:-1], centroid, origin, out), (flat, an, centroid[:-1], origin, out),
                 (flat, an, centroid, np.zeros(2), out), (flat, an, centroid, origin, out[:33]),
                 (flat.reshape(-1, 3), an, centroid, origin, out), (flat, an, centroid, origin, out.astype(np.float32))):
        with pytest.raises((TypeError, ValueError)):
            KERNEL.moments(*args)


@needs_kernel
def test_kernel_expansions_are_numpys_and_refuse_bad_arrays(monkeypatch):
    rng = np.random.default_rng(4)
    sums = rng.normal(size=(40, 34)) * 10.0 ** rng.integers(-150, 150, size=(40, 34))
    sums[3, 0], sums[5, 9], sums[7, 20] = 0.0, np.inf, np.nan
    origin, out = rng.normal(size=3), np.zeros((40, winding.FIELDS))
    KERNEL.expansions(sums, origin, out)
    monkeypatch.setattr(winding, "_kernel", None)
    with np.errstate(all="ignore"):
        assert out.tobytes() == winding._expansions(sums, origin).tobytes()
    for args in ((sums[:, :33].copy(), origin, out), (sums, origin[:2].copy(), out), (sums, origin, out[:39]),
                 (sums, origin, out[:, :27].copy()), (np.ones((40, 34), np.float32), origin, out), (sums.T, origin, out)):
        with pytest.raises((TypeError, ValueError)):
            KERNEL.expansions(*args)


def nested_links(rng, size, triangles):
    """(N, 3) int64 links of a random forest of nested subtrees in preorder: inner nodes of
    0 to 3 children (0: an inner node of no subtree), leaves of 0 to 4 triangles, and
    some leaves over subtrees of their own (the walk skips those)."""
    rows = []

    def node(depth):
        at = len(rows)
        rows.append(None)
        inner = depth < 5 and rng.random() < 0.6
        if inner or rng.random() < 0.1:
            for _ in range(rng.integers(0, 4)):
                node(depth + 1)
        count = 0 if inner else int(rng.integers(0, 5))
        rows[at] = (len(rows), int(rng.integers(0, triangles - count + 1)), count)

    while len(rows) < size:
        node(0)
    return np.array(rows, dtype=np.int64)


@pytest.mark.slow
@needs_kernel
@pytest.mark.parametrize("seed", range(6))
def test_kernel_walks_any_nested_links_as_the_numpy_path(seed):
    """On random nested links (not only the trees WindingTree makes), each point's terms
    are the NumPy walk's, in its order: the four lanes' shared walk never loses a lane."""
    rng = np.random.default_rng(seed)
    links = nested_links(rng, 300, 40)
    nodes = rng.normal(size=(len(links), winding.FIELDS))
    nodes[:, :3] = rng.uniform(-2, 2, size=(len(links), 3))
    nodes[:, 3] = rng.uniform(0, 1, size=len(links))
    tree = type("Tree", (), {"nodes": nodes, "links": links, "triangles": rng.uniform(-2, 2, size=(40, 9))})
    points = rng.uniform(-2, 2, size=(400, 3))
    assert (links[:, 2] == 0).any() and (links[:, 0] == np.arange(len(links)) + 1)[links[:, 2] == 0].any()
    for beta, order in ((0.5, 2), (1.5, 1), (3.0, 0)):
        out = np.empty(len(points))
        KERNEL.winding(points, nodes, links, tree.triangles, beta, order, 2, out)
        with np.errstate(all="ignore"):
            want = winding._numpy_winding(points, tree, beta, order)
        assert out.tobytes() == want.tobytes()
