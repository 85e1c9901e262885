"""Volume samples (--volume, --near): where the points are, and what they are labelled.

Statistical tests use fixed seeds and reject at the stated level; each is paired with a
variant that must fail the same test (a biased box, sigma taken as a variance, a flipped
sign)."""

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli.volume.source import gaussians, parts_of, sampling_box, volume_uniforms, world_triangles
from scatter_cli.sampling.plan import SamplePlan
from scatter_cli.loading.load import load_surface
from scatter_cli.stats.chisquare import chi2_gof
from tests.conftest import SAMPLES, scaled_scene
from tests.volume_reference import exact_distance, solid_angle_winding

LEVEL = 1e-3  # statistical tests reject at this level

LABELS = ("sdf", "inside", "winding", "closest", "face", "object")


def _box_cells(points, box, k=4):
    """Counts of points in a k x k x k grid over ``box``."""
    cell = np.floor((points - box[0]) / (box[1] - box[0]) * k).astype(int)
    cell = np.clip(cell, 0, k - 1)
    return np.bincount((cell[:, 0] * k + cell[:, 1]) * k + cell[:, 2], minlength=k**3)


def _triangles(path_or_mesh):
    surface = load_surface(path_or_mesh)
    return world_triangles(SamplePlan(surface))


# -- where the points are ------------------------------------------------------------------

def test_box_points_are_uniform_in_the_padded_box():
    s = scatter_cli.sample(SAMPLES / "skull.ply", 64000, volume=True, seed=5, precision="float64")
    tris, _, _ = _triangles(SAMPLES / "skull.ply")
    box = sampling_box(tris, 0.1)
    assert (s.points >= box[0]).all() and (s.points <= box[1]).all()
    counts = _box_cells(s.points, box)
    assert chi2_gof(counts, np.ones(64))[2] > LEVEL
    # a biased box (u**1.1 along x) fails the same test
    biased = s.points.copy()
    u = (biased[:, 0] - box[0, 0]) / (box[1, 0] - box[0, 0])
    biased[:, 0] = box[0, 0] + u**1.1 * (box[1, 0] - box[0, 0])
    assert chi2_gof(_box_cells(biased, box), np.ones(64))[2] < LEVEL


def test_padding_grows_the_box_by_its_largest_side():
    tris, _, _ = _triangles(SAMPLES / "icosahedron_binary.stl")
    lo, hi = tris.reshape(-1, 3).min(0), tris.reshape(-1, 3).max(0)
    box = sampling_box(tris, 0.25)
    assert np.allclose(box[0], lo - 0.25 * (hi - lo).max()) and np.allclose(box[1], hi + 0.25 * (hi - lo).max())


def _near_distances(points, tris):
    return exact_distance(tris, points)[0]


@pytest.mark.slow
def test_near_points_are_a_surface_point_plus_a_gaussian_of_deviation_sigma():
    """Two-sample test of the distance to the surface: ours against a reference made in
    the test (trimesh's uniform surface points plus NumPy's normals times sigma)."""
    from scipy.stats import ks_2samp

    mesh = trimesh.creation.icosphere(subdivisions=2)
    sigma = 0.05
    s = scatter_cli.sample(mesh, 3000, near=(sigma,), seed=11, precision="float64")
    tris = mesh.triangles
    ours = _near_distances(s.points, tris)
    rng = np.random.default_rng(123)
    base, _ = trimesh.sample.sample_surface(mesh, 3000, seed=7)
    reference = _near_distances(base + rng.normal(0.0, sigma, (3000, 3)), tris)
    assert ks_2samp(ours, reference).pvalue > LEVEL
    # sigma taken as a variance (mesh_to_sdf's mistake) fails the same test
    wrong = _near_distances(base + rng.normal(0.0, np.sqrt(sigma), (3000, 3)), tris)
    assert ks_2samp(ours, wrong).pvalue < LEVEL


def test_parts_take_their_shares():
    u = volume_uniforms(3, 0, 60000)[:, 0]
    part = parts_of(u, 0.2, 3)
    counts = np.bincount(part + 1, minlength=4)
    expected = np.array([0.2, 0.8 / 3, 0.8 / 3, 0.8 / 3]) * len(u)
    assert chi2_gof(counts, expected)[2] > LEVEL
    # shares 0.3 / 0.7 claimed while 0.2 / 0.8 is drawn fails
    assert chi2_gof(counts, np.array([0.3, 0.7 / 3, 0.7 / 3, 0.7 / 3]))[2] < LEVEL


def test_gaussians_are_standard_normal():
    from scipy.stats import kstest

    z = gaussians(volume_uniforms(0, 0, 20000)[:, 4:8])
    for c in range(3):
        assert kstest(z[:, c], "norm").pvalue > LEVEL
    assert abs(np.corrcoef(z.T)[0, 1]) < 0.05 and abs(np.corrcoef(z.T)[1, 2]) < 0.05
    assert kstest(z[:, 0] * 1.1, "norm").pvalue < LEVEL


def test_a_prefix_is_the_shorter_run_and_chunks_change_nothing():
    mesh = SAMPLES / "hemisphere.off"
    opts = dict(near=(0.02, 0.005), box_share=0.3, attributes=("sdf", "inside", "closest"), seed=2)
    long = scatter_cli.sample(mesh, 3000, **opts)
    short = scatter_cli.sample(mesh, 1000, chunk_size=77, **opts)
    assert short.points.tobytes() == long.points[:1000].tobytes()
    for key in ("sdf", "inside", "closest"):
        assert short.attributes[key].tobytes() == long.attributes[key][:1000].tobytes()


# -- what they are labelled ---------------------------------------------------------------

def _capped_sphere():
    """An icosphere with the faces of its top cap removed: an open surface."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    keep = sphere.triangles_center[:, 2] < 0.7
    return trimesh.Trimesh(sphere.vertices, sphere.faces[keep], process=False)


def _double_shell():
    outer = trimesh.creation.icosphere(subdivisions=2)
    inner = trimesh.creation.icosphere(subdivisions=1, radius=0.5)
    return trimesh.util.concatenate([outer, inner])


CASES = {
    "closed": lambda: trimesh.creation.icosphere(subdivisions=2),
    "icosahedron": lambda: SAMPLES / "icosahedron_binary.stl",
    "open": _capped_sphere,
    "inner-shell": _double_shell,
    "instanced": scaled_scene,
}


def _check_labels(s, tris, instance, face, flip=False):
    w_exact = solid_angle_winding(tris, s.points.astype(np.float64))
    d_exact, _ = exact_distance(tris, s.points.astype(np.float64))
    diag = float(np.linalg.norm(tris.reshape(-1, 3).max(0) - tris.reshape(-1, 3).min(0)))
    away = d_exact > 1e-3 * diag
    clear = np.abs(w_exact - 0.5) >= 0.05
    inside = s.inside.astype(bool) ^ flip
    assert np.abs(s.winding - w_exact)[away].max() < 0.02
    assert (inside == (w_exact >= 0.5))[clear].all()
    assert np.abs(np.abs(s.sdf) - d_exact).max() < 1e-9 * diag
    assert ((s.sdf < 0) == inside)[d_exact > 0].all()
    # the closest point lies on the face named, at the distance reported
    m = int(face.max()) + 1
    keys = instance * m + face
    order = np.argsort(keys)
    wanted = s.object.astype(np.int64) * m + s.face
    rows = order[np.minimum(np.searchsorted(keys[order], wanted), len(keys) - 1)]
    assert (keys[rows] == wanted).all()
    gap = np.array([exact_distance(tris[r : r + 1], c[None])[0][0] for r, c in zip(rows[:200], s.closest[:200])])
    assert gap.max() < 1e-9 * diag
    assert np.abs(np.linalg.norm(s.closest - s.points, axis=1) - np.abs(s.sdf)).max() < 1e-9 * diag


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_labels_match_brute_force(case):
    mesh = CASES[case]()
    s = scatter_cli.sample(mesh, 1500, near=(0.05,), box_share=0.5, attributes=LABELS, seed=4, precision="float64")
    tris, instance, face = _triangles(mesh)
    _check_labels(s, tris, instance, face)


@pytest.mark.slow
def test_a_flipped_sign_fails_the_label_check():
    mesh = CASES["closed"]()
    s = scatter_cli.sample(mesh, 500, volume=True, attributes=LABELS, seed=4, precision="float64")
    tris, instance, face = _triangles(mesh)
    with pytest.raises(AssertionError):
        _check_labels(s, tris, instance, face, flip=True)


@pytest.mark.slow
def test_normalized_frames():
    mesh = SAMPLES / "skull.ply"
    tris, _, _ = _triangles(mesh)
    corners = tris.reshape(-1, 3)
    lo, hi = corners.min(0), corners.max(0)
    cube = scatter_cli.sample(mesh, 4000, volume=True, normalize="unit-cube", padding=0.0, precision="float64")
    assert np.abs(cube.points).max() <= 1 + 1e-12
    assert np.isclose(cube.points.max(0) - cube.points.min(0), 2 * (hi - lo) / (hi - lo).max(), rtol=0.02).all()
    sphere = scatter_cli.sample(mesh, 10, volume=True, normalize="unit-sphere", attributes=("sdf",),
                                precision="float64")
    scale = sphere.info["normalize"]["scale"]
    center = np.asarray(sphere.info["normalize"]["offset"])
    assert np.isclose(np.linalg.norm((corners - center) * scale, axis=1).max(), 1.0)
    world = scatter_cli.sample(mesh, 10, volume=True, attributes=("sdf",), precision="float64")
    assert np.allclose((world.points - center) * scale, sphere.points)
    assert np.allclose(world.sdf * scale, sphere.sdf)


def _tree_arrays(trees):
    """Every array of each tree (the distance and the winding tree), by attribute."""
    return [{k: v for k, v in vars(t).items() if isinstance(v, np.ndarray)} for t in trees]


def _assert_same_trees(a, b):
    for x, y in zip(_tree_arrays(a), _tree_arrays(b)):
        assert x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x)


def _built_both_ways(monkeypatch):
    """(the label trees built one after the other, built at the same time)."""
    import scatter_cli.core.native as native
    from scatter_cli.volume.source import label_trees

    tris = _triangles(trimesh.creation.icosphere(subdivisions=3))[0]
    monkeypatch.setattr(native, "worker_count", lambda: 1)
    in_turn = label_trees(tris, True, True)
    monkeypatch.setattr(native, "worker_count", lambda: 2)
    return in_turn, label_trees(tris, True, True)


def test_the_label_trees_are_the_same_built_together_or_in_turn(monkeypatch):
    _assert_same_trees(*_built_both_ways(monkeypatch))


def test_a_tree_built_otherwise_on_its_thread_fails_that_check(monkeypatch):
    import threading

    import scatter_cli.volume.winding as winding

    def elsewhere(t):  # on another thread than the main one: the faces in another order
        return tree(t if threading.current_thread() is threading.main_thread() else t[::-1])

    tree = winding.WindingTree
    monkeypatch.setattr(winding, "WindingTree", elsewhere)
    with pytest.raises(AssertionError):
        _assert_same_trees(*_built_both_ways(monkeypatch))
