"""Sharp edges (``--edges``): which edges are sharp, points on them, the interleaving of
edge and face points, near points around edges, and the command line's rules.

Statistical tests use fixed seeds and the level LEVEL; each is paired with a variant
that must fail it."""

import math

import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st

import scatter_cli
from scatter_cli.run.options import edge_share
from scatter_cli.sampling import edges as edges_module, sharp
from scatter_cli.sampling.normals import face_normals
from scatter_cli.stats.chisquare import chi2_gof

from .conftest import ROOT, run_scatter, scatter_in_process
from .test_cli import assert_one_line_error

LEVEL = 1e-3
EXTENTS = (1.0, 2.0, 3.0)


def box_mesh():
    """A box 1 x 2 x 3 centred at (0.5, -1, 2), as trimesh builds it (welded, 12 faces)."""
    box = trimesh.creation.box(extents=EXTENTS)
    box.apply_translation((0.5, -1.0, 2.0))
    return box


def box_edges():
    """The 12 edges of box_mesh as (a, b) float64 pairs, and their unit directions."""
    lo = np.array([0.0, -2.0, 0.5])
    size = np.array(EXTENTS)
    out = []
    for axis in range(3):
        others = [c for c in range(3) if c != axis]
        for i in (0, 1):
            for j in (0, 1):
                a = lo.copy()
                a[others[0]] += i * size[others[0]]
                a[others[1]] += j * size[others[1]]
                b = a.copy()
                b[axis] += size[axis]
                out.append((a, b))
    return out


def nearest_edge(points):
    """(edge index (n,), distance (n,), position along it in [0, 1] (n,)) of each point's
    nearest box edge (segment)."""
    best = np.full(len(points), np.inf)
    which = np.zeros(len(points), np.int64)
    along = np.zeros(len(points))
    for k, (a, b) in enumerate(box_edges()):
        d = b - a
        t = np.clip((points - a) @ d / (d @ d), 0.0, 1.0)
        dist = np.linalg.norm(points - (a + t[:, None] * d), axis=1)
        better = dist < best
        best[better], which[better], along[better] = dist[better], k, t[better]
    return which, best, along


def arrays_of(mesh):
    """(vertices, faces, unit face normals) of a trimesh mesh, as the sampler has them."""
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    return v, f, face_normals(v, f)


# -- which edges are sharp --------------------------------------------------------------

def test_a_box_has_twelve_sharp_edges():
    found = sharp.sharp_edges(*arrays_of(box_mesh()))
    assert len(found) == 12 and (found.kind == 2).all() and np.allclose(found.angle, 90.0)


def hinge(degrees):
    """Two triangles sharing the edge (0,0,0)-(1,0,0), their normals ``degrees`` apart."""
    t = math.radians(degrees)
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -math.cos(t), math.sin(t)]], float)
    return v, np.array([[0, 1, 2], [1, 0, 3]], np.int64)


@pytest.mark.parametrize("degrees,is_sharp", [(15.001, True), (14.999, False), (90.0, True), (1.0, False)])
def test_a_crease_is_sharp_from_the_angle_on(degrees, is_sharp):
    v, f = hinge(degrees)
    n = face_normals(v, f)
    found = sharp.sharp_edges(v, f, n, 15.0)
    interior = found.kind == 2
    assert interior.sum() == is_sharp
    if is_sharp:
        assert found.angle[interior][0] == pytest.approx(degrees, abs=1e-9)


def test_the_angle_threshold_is_the_option():
    v, f = hinge(20.0)
    n = face_normals(v, f)
    assert (sharp.sharp_edges(v, f, n, 19.0).kind == 2).sum() == 1
    assert (sharp.sharp_edges(v, f, n, 21.0).kind == 2).sum() == 0


def test_boundary_and_non_manifold_edges_are_always_sharp():
    # a flat square (two coplanar triangles): its 4 boundary edges, not the diagonal
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]], np.int64)
    found = sharp.sharp_edges(v, f, face_normals(v, f))
    assert sorted(found.kind.tolist()) == [1, 1, 1, 1]
    # three flat-ish faces on one edge (a fin): the shared edge is non-manifold, whatever the angle
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, -1, 1e-3]], float)
    f = np.array([[0, 1, 2], [1, 0, 3], [1, 0, 4]], np.int64)
    found = sharp.sharp_edges(v, f, face_normals(v, f), 179.0)
    assert (found.kind == 3).sum() == 1 and found.face[found.kind == 3][0] == 0


def test_degenerate_faces_have_no_edges():
    v, f = hinge(90.0)
    v = np.vstack([v, [[0.2, 0.0, 0.0]]])
    f = np.vstack([f, [[0, 1, 4]]])  # zero area, on the shared edge
    n = face_normals(v, f)
    valid = np.any(n != 0, axis=1)
    assert valid.tolist() == [True, True, False]
    found = sharp.sharp_edges(v, f, n)
    assert (found.kind == 2).sum() == 1 and (found.kind == 3).sum() == 0


def test_split_corners_link_as_the_welded_mesh():
    """An STL repeats each corner per face: linked by position, it has the welded mesh's
    edges (the broken variant, linking by vertex number, finds only boundaries)."""
    box = box_mesh()
    split_v = box.vertices[box.faces].reshape(-1, 3)
    split_f = np.arange(len(split_v)).reshape(-1, 3)
    welded = sharp.sharp_edges(*arrays_of(box))
    normals = face_normals(split_v, split_f)
    split = sharp.sharp_edges(split_v, split_f, normals)
    assert np.array_equal(split.slot, welded.slot) and np.array_equal(split.kind, welded.kind)
    by_number = np.arange(len(split_v))[:, None] * np.ones(3)  # every vertex a position of its own
    assert (sharp.sharp_edges(by_number, split_f, normals).kind == 1).all()


def random_meshes():
    """Triangle lists with shared and repeated positions, -0.0, degenerate and invalid faces."""
    grid = st.sampled_from([0.0, -0.0, 0.5, 1.0, 2.0])
    return st.tuples(st.lists(st.tuples(grid, grid, grid), min_size=3, max_size=12),
                     st.lists(st.tuples(st.integers(0, 11), st.integers(0, 11), st.integers(0, 11)), min_size=1,
                              max_size=30),
                     st.lists(st.booleans(), min_size=30, max_size=30))


@pytest.mark.slow
@given(random_meshes(), st.sampled_from(["1", "3", "7"]))
def test_the_kernel_finds_the_edges_numpy_finds(mesh, threads):
    """Fuzzed triangle lists, on several thread counts (more threads than vertices too):
    the kernel's arrays are its NumPy twin's."""
    coords, faces, valid = mesh
    v = np.array(coords, float)
    f = np.array(faces, np.int64) % len(v)
    ok = np.array(valid[: len(f)], bool)
    normals = face_normals(v, f)
    with pytest.MonkeyPatch.context() as m:
        m.setenv("SCATTER_THREADS", threads)
        for limit in (np.inf, 0.9):
            kernel = sharp.edge_slots(v, f, ok, normals, limit)
            twin = sharp._numpy_edge_slots(v, f, ok, normals, limit)
            for field in ("head", "second", "count", "rest"):
                assert np.array_equal(getattr(kernel, field), getattr(twin, field)), (field, limit)


def _mix64(z):
    """_cedges.c's mix64, on Python integers."""
    mask = (1 << 64) - 1
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
    return z ^ (z >> 31)


def _bits(x):
    return int(np.array(x + 0.0, np.float64).view(np.uint64))


def _position_hash(p):
    """The kernel's hash of a position (its edge keys are made of these)."""
    b = [_bits(c) for c in p]
    return _mix64(b[0] ^ _mix64(b[1] ^ _mix64(b[2])))


def _colliding(p):
    """A position other than ``p`` with the same hash, every coordinate in a plain range:
    the hash is invertible in its first coordinate, so pick the others and solve for it."""
    b = [_bits(c) for c in p]
    rest = _mix64(b[1] ^ _mix64(b[2]))
    for k in range(1, 100000):
        y = p[1] + k * 1e-3
        x = float(np.array(b[0] ^ rest ^ _mix64(_bits(y) ^ _mix64(b[2])), np.uint64).view(np.float64))
        if 1e-3 < abs(x) < 1e3:
            return (x, y, p[2])
    raise AssertionError("no colliding position found")


def test_a_collision_of_edge_keys_never_joins_two_edges():
    """Two edges whose end positions hash alike, (P, A) and (Q, A) with hash(P) = hash(Q),
    get one 64-bit key in the kernel: it must still keep them apart, as its NumPy twin
    does. The variant that joins slots by key alone gets this mesh wrong."""
    p, a, b = (0.5, 0.25, 0.125), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    q = _colliding(p)
    assert q != p and _position_hash(q) == _position_hash(p)
    v = np.array([p, a, b, q], float)
    f = np.array([[0, 1, 2], [3, 1, 2]], np.int64)  # (P, A) and (Q, A): different edges, one key
    normals = face_normals(v, f)
    assert (np.abs(normals).sum(axis=1) > 0).all()
    twin = sharp._numpy_edge_slots(v, f, np.ones(2, bool), normals, np.inf)
    kernel = sharp.edge_slots(v, f, np.ones(2, bool), normals, np.inf)
    for field in ("head", "second", "count", "rest"):
        assert np.array_equal(getattr(kernel, field), getattr(twin, field)), field
    assert sorted(twin.count.tolist()) == [1, 1, 1, 1, 2]  # (A, B) shared, the other four alone
    by_key = {}  # the broken variant: slots joined by their positions' hashes alone
    for s in range(6):
        ends = f[s // 3, s % 3], f[s // 3, (s + 1) % 3]
        by_key.setdefault(frozenset(_position_hash(v[i]) for i in ends), []).append(s)
    assert sorted(len(slots) for slots in by_key.values()) == [2, 2, 2]  # two of them wrongly paired


def test_many_faces_on_one_edge_are_one_edge():
    """A fan of 40 faces around one edge (a run of slots long enough to be sorted apart),
    with the fan's outer edges beside it: the kernel's arrays are its NumPy twin's."""
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    rim = np.c_[np.cos(angles), np.sin(angles), np.full(40, 0.5)]
    v = np.vstack([[0, 0, 0], [0, 0, 1], rim])
    f = np.c_[np.zeros(40, np.int64), np.ones(40, np.int64), np.arange(2, 42)]
    f[::3] = f[::3, [1, 0, 2]]  # both directions along the shared edge
    normals = face_normals(v, f)
    for limit in (np.inf, 0.9):
        kernel = sharp.edge_slots(v, f, np.ones(40, bool), normals, limit)
        twin = sharp._numpy_edge_slots(v, f, np.ones(40, bool), normals, limit)
        for field in ("head", "second", "count", "rest"):
            assert np.array_equal(getattr(kernel, field), getattr(twin, field)), field
    assert twin.count.max() == 40


def test_the_kernel_refuses_an_index_out_of_range():
    if sharp._kernel is None:
        pytest.skip("no compiled kernels")
    out = [np.empty(3, np.int64) for _ in range(4)]
    with pytest.raises(ValueError, match="out of range"):
        sharp._kernel.edges(np.zeros((2, 3)), np.array([[0, 1, 2]], np.int64), np.ones(1, bool), np.zeros((1, 3)),
                            np.inf, 1, *out)


# -- points on the edges of a box --------------------------------------------------------

@pytest.fixture(scope="module")
def box_run():
    return scatter_cli.sample(box_mesh(), 60_000, seed=3, edges=0.5,
                              attributes=("normal", "face", "bary", "sharp"), precision="float64")


def test_edge_points_lie_on_the_edges(box_run):
    on = box_run.sharp == 1
    _, dist, _ = nearest_edge(box_run.points[on])
    assert dist.max() <= 1e-12 * max(EXTENTS)
    _, dist, _ = nearest_edge(box_run.points[~on])
    assert np.median(dist) > 0.1  # face points are spread over the faces


def test_edges_are_chosen_by_length(box_run):
    which, _, _ = nearest_edge(box_run.points[box_run.sharp == 1])
    lengths = np.array([np.linalg.norm(b - a) for a, b in box_edges()])
    counts = np.bincount(which, minlength=12)
    assert chi2_gof(counts, lengths)[2] > LEVEL
    assert chi2_gof(counts, np.ones(12))[2] < LEVEL  # the broken variant: edges chosen uniformly


def test_points_are_uniform_along_each_edge(box_run):
    from scipy.stats import kstest

    which, _, along = nearest_edge(box_run.points[box_run.sharp == 1])
    for k in range(12):
        assert kstest(along[which == k], "uniform").pvalue > LEVEL
    assert kstest(along[which == 0] ** 1.2, "uniform").pvalue < LEVEL  # the broken variant


def test_an_edge_point_has_its_edge_normal_and_lowest_face(box_run):
    """Built here from the box's faces: each box edge's two faces (those with both its
    ends as corners), the lower index of the two and the normalized sum of their normals."""
    box = box_mesh()
    on = np.flatnonzero(box_run.sharp == 1)
    which, _, _ = nearest_edge(box_run.points[on])
    normals = box.face_normals
    want_face, want_normal, other = [], [], []
    for a, b in box_edges():
        has = [f for f in range(12) if all(np.any(np.all(np.isclose(box.vertices[box.faces[f]], p), axis=1))
                                           for p in (a, b))]
        assert len(has) == 2
        want_face.append(min(has))
        other.append(max(has))
        total = normals[has[0]] + normals[has[1]]
        want_normal.append(total / np.linalg.norm(total))
    assert np.array_equal(box_run.face[on], np.array(want_face)[which])
    assert np.allclose(box_run.normal[on], np.array(want_normal)[which], atol=1e-12)
    # the broken variants: the other face, or that face's own normal
    assert not np.array_equal(box_run.face[on], np.array(other)[which])
    assert not np.allclose(box_run.normal[on], normals[np.array(want_face)[which]], atol=1e-3)
    # its barycentric weights are those of the point in that face, the third corner weighing nothing
    corners = box.vertices[box.faces[box_run.face[on]]]
    assert np.allclose(np.einsum("ij,ijk->ik", box_run.bary[on], corners), box_run.points[on], atol=1e-12)
    assert (np.count_nonzero(box_run.bary[on] == 0, axis=1) >= 1).all()


def test_face_points_are_uniform_by_area(box_run):
    face = box_run.face[box_run.sharp == 0]
    areas = box_mesh().area_faces
    assert chi2_gof(np.bincount(face, minlength=12), areas)[2] > LEVEL
    assert chi2_gof(np.bincount(face, minlength=12), np.ones(12))[2] < LEVEL  # the broken variant


@pytest.mark.slow
def test_the_edges_do_not_depend_on_vertex_numbering(tmp_path):
    """A split STL, the welded PLY of its float32 coordinates and the same PLY with its
    vertices renumbered give the same bytes; ordering the edges by vertex number would not."""
    box = box_mesh()
    box.export(tmp_path / "box.stl")
    v = np.asarray(box.vertices, np.float32).astype(np.float64)
    trimesh.Trimesh(v, box.faces, process=False).export(tmp_path / "box.ply")
    perm = np.random.default_rng(1).permutation(len(v))
    trimesh.Trimesh(v[perm], np.argsort(perm)[box.faces], process=False).export(tmp_path / "perm.ply")
    outs = []
    for name in ("box.stl", "box.ply", "perm.ply"):
        out = tmp_path / f"{name}.npy"
        run_scatter("sample", tmp_path / name, "-n", "3000", "--edges", "0.4", "-a", "normal,face,bary,sharp", "-o",
                    out, check=True)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] == outs[2]


def test_edge_order_by_vertex_number_would_differ(monkeypatch):
    """The broken variant of the test above: edges ordered by their lower vertex number."""
    box = box_mesh()
    v = np.asarray(box.vertices)
    perm = np.random.default_rng(1).permutation(len(v))
    renumbered = trimesh.Trimesh(v[perm], np.argsort(perm)[box.faces], process=False)
    real = sharp.sharp_edges

    def by_vertex(vertices, faces, normals, angle=15.0):
        found = real(vertices, faces, normals, angle)
        key = np.minimum(faces[found.face, found.corner], faces[found.face, (found.corner + 1) % 3])
        order = np.argsort(key, kind="stable")
        return sharp.SharpEdges(found.slot[order], found.kind[order], found.angle[order], found.normal[order])

    def run(mesh):
        monkeypatch.setattr(edges_module, "sharp_edges", by_vertex)
        return scatter_cli.sample(mesh, 500, edges=1).points

    assert not np.array_equal(run(box), run(renumbered))


# -- counts, the interleaving and determinism --------------------------------------------

def test_every_prefix_holds_its_share_of_edge_points():
    run = scatter_cli.sample(box_mesh(), 1000, edges="0.29", attributes=("sharp",))
    prefix = np.cumsum(run.sharp)
    k = np.arange(1, 1001)
    assert np.array_equal(prefix, k * 29 // 100)
    assert not np.array_equal(prefix, np.floor(k * 0.29).astype(int))  # the broken variant: float arithmetic


@pytest.mark.parametrize("text,fraction", [("0.29", (29, 100)), ("0.5", (1, 2)), ("1", (1, 1)), ("0", (0, 1)),
                                           ("2.5e-1", (1, 4)), ("0.3333333333333333333", (3333333333333333333, 10**19))])
def test_the_share_is_the_exact_decimal_written(text, fraction):
    share = edge_share(text)
    assert (share.numerator, share.denominator) == fraction


def test_a_long_decimal_share_is_counted_exactly():
    split = edges_module.Interleaving(edge_share("0.3333333333333333333"))
    mask = split.mask(10**15, 10**15 + 1000)
    assert mask.sum() == split.before(10**15 + 1000) - split.before(10**15)


@pytest.mark.slow
def test_chunks_threads_and_shards_give_the_same_bytes(tmp_path, monkeypatch):
    args = ["sample", box_mesh_file(tmp_path), "-n", "20000", "--edges", "0.37", "-a", "normal,sharp,bary"]
    whole = tmp_path / "whole.ply"
    run_scatter(*args, "-o", whole, check=True)
    chunked = tmp_path / "chunked.ply"  # (it and the shards through the command's entry point in this process)
    scatter_in_process(*args, "--chunk-size", "999", "-o", chunked, env={"SCATTER_THREADS": "3"}, check=True)
    parts = []
    for k in range(3):
        parts.append(tmp_path / f"part{k}.ply")
        scatter_in_process(*args, "--shard", f"{k}/3", "-o", parts[-1], check=True)
    merged = tmp_path / "merged.ply"
    run_scatter("merge", *parts, "-o", merged, check=True)
    assert whole.read_bytes() == chunked.read_bytes() == merged.read_bytes()


def box_mesh_file(folder):
    path = folder / "box.ply"
    if not path.exists():
        box_mesh().export(path)
    return path


def test_the_face_part_is_the_plain_run_of_its_count():
    """Face point j is point j of the run's face stream: a run with --edges 1/4 holds, in
    its face points, the first 3N/4 points of the plain run of the same seed."""
    mixed = scatter_cli.sample(box_mesh(), 4000, seed=9, edges=0.25, attributes=("sharp",))
    plain = scatter_cli.sample(box_mesh(), 3000, seed=9)
    assert np.array_equal(mixed.points[mixed.sharp == 0], plain.points)


@pytest.mark.slow
def test_a_mesh_with_no_sharp_edge_warns_and_samples_its_faces(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=3)
    sphere.export(tmp_path / "ball.ply")
    proc = run_scatter("sample", tmp_path / "ball.ply", "-n", "500", "--edges", "0.5", "-a", "sharp",
                       "-o", tmp_path / "out.npy")
    assert proc.returncode == 0
    assert b"no sharp edge at 15 degrees" in proc.stderr and b"ball.ply" in proc.stderr
    out = np.load(tmp_path / "out.npy")
    plain = scatter_cli.sample(tmp_path / "ball.ply", 500)
    assert (out["sharp"] == 0).all() and np.array_equal(out["x"], plain.points[:, 0].astype(np.float32))


# -- near points around edges --------------------------------------------------------------

def test_near_edge_points_follow_their_sigma():
    """The distance of a near point of an edge point to the box's edges is distributed as
    that of an edge point moved by an isotropic Gaussian offset of sigma: a reference
    built here, drawn with NumPy's own generator."""
    from scipy.stats import ks_2samp

    sigma = 0.02
    run = scatter_cli.sample(box_mesh(), 40_000, seed=5, near=(0.2,), near_edges=(sigma,), edges=0.5,
                             attributes=("sharp",), precision="float64")
    ours = nearest_edge(run.points[run.sharp == 1])[1]

    def reference(s, n=20_000):
        rng = np.random.default_rng(11)
        lengths = np.array([np.linalg.norm(b - a) for a, b in box_edges()])
        k = rng.choice(12, size=n, p=lengths / lengths.sum())
        ends = np.array(box_edges())
        t = rng.random(n)[:, None]
        on = ends[k, 0] + t * (ends[k, 1] - ends[k, 0])
        return nearest_edge(on + rng.normal(scale=s, size=(n, 3)))[1]

    assert ks_2samp(ours, reference(sigma)).pvalue > LEVEL
    assert ks_2samp(ours, reference(1.5 * sigma)).pvalue < LEVEL  # the broken variant: a wrong sigma
    # and the near points of face points keep the --near sigma
    far = nearest_edge(run.points[run.sharp == 0])[1]
    assert np.median(far) > 5 * sigma


def test_volume_points_are_sharp_only_near_edge_points():
    run = scatter_cli.sample(box_mesh(), 5000, near=(0.01,), box_share=0.3, edges=0.5,
                             attributes=("sharp", "sdf"))
    plain = scatter_cli.sample(box_mesh(), 5000, near=(0.01,), box_share=0.3, attributes=("sharp", "sdf"))
    assert 0 < run.sharp.sum() < 0.7 * 5000 * 0.5 + 200
    assert (plain.sharp == 0).all()
    # box points are unaffected: the runs agree wherever the point is a box point
    same = np.all(run.points == plain.points, axis=1)
    assert (run.sharp[same] == 0).all() and same.sum() > 0.25 * 5000


# -- the command line ----------------------------------------------------------------------

USAGE_ERRORS = [
    (["--edges", "1.5"], "--edges must be a share from 0 to 1"),
    (["--edges", "lots"], "--edges must be a share from 0 to 1"),
    (["--edges", "0.5", "--poisson"], "--edges does not combine with --poisson"),
    (["--edges", "0.5", "--radius", "0.1"], "--edges does not combine with --radius"),
    (["--edges", "0.5", "--stable"], "--edges does not combine with --stable"),
    (["--edges", "0.5", "--exterior"], "--edges does not combine with --exterior"),
    (["--edges", "0.5", "--method", "sobol"], "--edges does not combine with --method sobol"),
    (["--edges", "0.5", "--volume"], "--edges with --volume needs --near"),
    (["--sharp-angle", "30"], "--sharp-angle needs --edges"),
    (["--near", "0.1", "--near-edges", "0.01"], "--near-edges needs --edges"),
    (["--edges", "0.5", "--near-edges", "0.01"], "--near-edges needs --near"),
    (["--edges", "0.5", "--sharp-angle", "0"], "--sharp-angle must be a number of degrees in (0, 180]"),
    (["--edges", "0.5", "--sharp-angle", "181"], "--sharp-angle must be a number of degrees in (0, 180]"),
]


@pytest.mark.parametrize("args,words", USAGE_ERRORS)
def test_usage_errors(tmp_path, args, words):
    run = run_scatter if args == USAGE_ERRORS[0][0] else scatter_in_process  # one in a real process
    proc = run("sample", box_mesh_file(tmp_path), "-n", "10", *args, "-o", tmp_path / "out.ply")
    assert_one_line_error(proc, 2, words)
    assert not (tmp_path / "out.ply").exists()


@pytest.mark.slow
def test_both_batch_engines_write_what_sample_writes(tmp_path):
    """scatter batch, locally and on a Dask cluster, writes for each mesh what scatter
    sample writes (a box, a CAD part, a sphere with no sharp edge), warnings and all."""
    pytest.importorskip("distributed")
    from .test_batch_dask import start_cluster, stop

    folder = tmp_path / "in"
    folder.mkdir()
    box_mesh().export(folder / "box.ply")
    trimesh.creation.icosphere(subdivisions=3).export(folder / "ball.ply")
    (folder / "part.stl").write_bytes((ROOT / "samples" / "pediment_join_plate_12.stl").read_bytes())
    options = dict(count=2000, edges="0.4", attributes="normal,face,sharp")
    local = scatter_cli.batch([folder], str(tmp_path / "local" / "{stem}.ply"), jobs=2, **options)
    client, _, _, procs = start_cluster(1)
    try:
        remote = scatter_cli.batch([folder], str(tmp_path / "dask" / "{stem}.ply"), client=client, **options)
    finally:
        client.close()
        stop(procs)
    assert [r["status"] for r in local] == [r["status"] for r in remote] == ["written"] * 3
    for name in ("ball", "box", "part"):
        alone = tmp_path / f"{name}.ply"
        suffix = ".stl" if name == "part" else ".ply"
        run_scatter("sample", folder / f"{name}{suffix}", "-n", "2000", "--edges", "0.4", "-a", "normal,face,sharp",
                    "-o", alone, check=True)
        want = alone.read_bytes()
        assert (tmp_path / "local" / f"{name}.ply").read_bytes() == want
        assert (tmp_path / "dask" / f"{name}.ply").read_bytes() == want


@pytest.mark.slow
def test_preview_colours_edge_points_apart(tmp_path):
    """A point file with a sharp column is drawn with its edge points in SHARP_RGB over the
    normal colours; inside/outside colours come first (the rule's order)."""
    from scatter_cli.commands import render
    from scatter_cli.writers.pointfiles import read_points

    out = tmp_path / "box.ply"
    run_scatter("sample", box_mesh_file(tmp_path), "-n", "400", "--edges", "0.5", "-a", "normal,sharp", "-o", out,
                check=True)
    points = read_points(out)
    sharp_rows = points.attributes["sharp"] > 0
    assert sharp_rows.sum() == 200
    colors = render.point_colors(points.points, points.attributes)
    plain = render.point_colors(points.points, {"normal": points.attributes["normal"]})
    assert (colors[sharp_rows] == render.SHARP_RGB).all()
    assert np.array_equal(colors[~sharp_rows], plain[~sharp_rows])
    assert not (plain[sharp_rows] == render.SHARP_RGB).all()  # the broken variant: the column ignored
    inside = render.point_colors(points.points, {**points.attributes, "inside": np.ones(400)})
    assert (inside == render.INSIDE_RGB).all()


@pytest.mark.slow
@pytest.mark.parametrize("threads", ["1", "2", "3", "7", "16"])
def test_the_kernel_finds_the_same_edges_on_any_thread_count(threads, monkeypatch):
    """The skull (100k faces) and its corners repeated per face: the NumPy twin's edges
    whatever the threads (every step's shares are fixed, not raced for)."""
    if sharp._kernel is None:
        pytest.skip("no compiled kernels")
    skull = trimesh.load(ROOT / "samples" / "skull.ply", process=False)
    v, f = np.asarray(skull.vertices, float), np.asarray(skull.faces, np.int64)
    split_v = np.ascontiguousarray(v[f].reshape(-1, 3))
    monkeypatch.setenv("SCATTER_THREADS", threads)
    for vertices, faces in ((v, f), (split_v, np.arange(len(split_v)).reshape(-1, 3))):
        normals = face_normals(vertices, faces)
        valid = np.any(normals != 0, axis=1)
        got = sharp.edge_slots(vertices, faces, valid, normals, 0.99)
        want = sharp._numpy_edge_slots(vertices, faces, valid, normals, 0.99)
        for field in ("head", "second", "count", "rest"):
            assert np.array_equal(getattr(got, field), getattr(want, field)), field
