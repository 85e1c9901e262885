"""Stable placement (--stable): uniform, exact N, renumbering-proof and local under edits.

Statistical tests use fixed seeds and level ALPHA; each is paired with a broken variant
that must fail it. Faces are matched between an original and an edited mesh by their
world corners, rotated to start at the smallest corner (computed here in plain Python,
independently of the source's keys).
"""

import os

import numpy as np
import pytest

from scatter_cli.core import native
from scatter_cli.sampling.stable import source as stable, arrivals as stable_arrivals, faces as stable_faces, order as stable_order, weights as stable_weights
from scatter_cli.sampling.poisson import thinning
from scatter_cli.stats.chisquare import chi2_gof
from scatter_cli.sampling.stable.source import StableSource
from scatter_cli.loading.load import load_surface

from .conftest import SAMPLES, spread_triangles, triangles_mesh

ALPHA = 1e-3


def _mesh(v, f):
    import trimesh

    return trimesh.Trimesh(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64), process=False)


def _load(name):
    import trimesh

    m = trimesh.load(SAMPLES / name, process=False, force="mesh")
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def run(mesh, seed=0, **kw):
    """(source, RawChunk of all its points) for a trimesh mesh or a path (with ``radius``:
    the candidates' source and the dart-thrown set)."""
    src = StableSource(load_surface(mesh), seed, want_bary=True, **kw)
    if "radius" in kw:
        kept = thinning.dart_thrown(src, kw["radius"])
        return src, kept.draw(0, kept.count)
    return src, src.draw(0, src.count)


def face_ids(v, f):
    """(F,) list of face identities (bytes): corners rotated to start at the smallest
    (x, y, z), -0.0 as 0.0."""
    c = v[f] + 0.0  # (F, 3, 3)
    first = np.lexsort((c[:, :, 2], c[:, :, 1], c[:, :, 0]), axis=-1)[:, 0]
    turn = (first[:, None] + np.arange(3)) % 3
    rows = np.ascontiguousarray(c[np.arange(len(f))[:, None], turn].reshape(len(f), 9))
    return [r.tobytes() for r in rows]


def areas(v, f):
    t = v[f]
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)


# -- uniform ----------------------------------------------------------------------------


def quarter(bary):
    """(n,) 0..3: which of a face's four midpoint sub-triangles holds the point."""
    q = np.full(len(bary), 3)
    for k in range(3):
        q[bary[:, k] > 0.5] = k
    return q


def region_pvalue(v, f, raw, groups=64):
    """Chi-square p over regions (faces cut into ``groups`` runs of equal area, each run
    cut into its faces' four sub-triangles of a quarter of the area each)."""
    a = areas(v, f)
    run_of = np.minimum((np.cumsum(a) - a / 2) / a.sum() * groups, groups - 1).astype(int)
    region = run_of[raw.face] * 4 + quarter(raw.bary)
    observed = np.bincount(region, minlength=4 * groups)
    expected = np.repeat(np.bincount(run_of, a, minlength=groups) / 4, 4) / a.sum() * len(raw.face)
    keep = expected > 0
    return chi2_gof(observed[keep], expected[keep])[2]


def _spread():
    tri, _ = spread_triangles(np.linspace(-2, 1, 40))
    m = triangles_mesh(tri)
    return np.asarray(m.vertices), np.asarray(m.faces)


UNIFORM_MESHES = {"skull": lambda: _load("skull.ply"), "spot": lambda: _load("spot_triangulated.obj"),
                  "spread": _spread}


@pytest.mark.parametrize("name", sorted(UNIFORM_MESHES))
def test_uniform_per_equal_area_region(name):
    v, f = UNIFORM_MESHES[name]()
    _, raw = run(_mesh(v, f), seed=3, count=40_000)
    assert region_pvalue(v, f, raw) > ALPHA


def numpy_path(monkeypatch):
    """Switch the stable modules' kernel off (as SCATTER_NUMPY=1 does at import)."""
    for module in (stable, stable_faces, stable_order):
        monkeypatch.setattr(module, "_kernel", None)


@pytest.mark.parametrize("name", ["skull", "spread"])
def test_uniform_test_catches_a_rate_not_proportional_to_area(name, monkeypatch):
    """Broken variant: every face arrives at rate sqrt(area)."""
    v, f = UNIFORM_MESHES[name]()
    true_areas = stable_faces.doubled_areas
    numpy_path(monkeypatch)  # the broken variant is made on the NumPy path
    monkeypatch.setattr(stable_faces, "doubled_areas", lambda cols: np.sqrt(2 * true_areas(cols)))
    _, raw = run(_mesh(v, f), seed=3, count=40_000)
    assert region_pvalue(v, f, raw) < ALPHA


def test_exact_count_and_the_prefix_of_a_longer_run():
    v, f = _load("spot_triangulated.obj")
    _, whole = run(_mesh(v, f), seed=5, count=3000)
    assert len(whole.points) == 3000
    for k in (1, 17, 500, 2500):
        _, longer = run(_mesh(v, f), seed=5, count=3000 + k)
        assert longer.points[:3000].tobytes() == whole.points.tobytes()
    _, other_seed = run(_mesh(v, f), seed=6, count=3000)
    assert other_seed.points.tobytes() != whole.points.tobytes()


# -- renumbering ------------------------------------------------------------------------


def renumbered(v, f, seed=1):
    """The same surface: faces shuffled, vertices renumbered, each face rotated a b c -> b c a
    or c a b."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(v))
    new_v = np.empty_like(v)
    new_v[perm] = v
    g = perm[f][rng.permutation(len(f))]
    turn = rng.integers(0, 3, len(g))
    g = np.stack([g[np.arange(len(g)), (turn + k) % 3] for k in range(3)], axis=1)
    return new_v, g


def write_obj(path, v, f):
    with open(path, "w") as out:
        out.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in v.tolist())
        out.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f.tolist())


def write_ply(path, v, f):
    """Binary PLY with double vertices (trimesh's exporter writes float32)."""
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\nproperty double x\n"
            f"property double y\nproperty double z\nelement face {len(f)}\n"
            "property list uchar int vertex_indices\nend_header\n")
    rows = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    rows["n"], rows["i"] = 3, f
    with open(path, "wb") as out:
        out.write(head.encode() + np.ascontiguousarray(v, dtype="<f8").tobytes() + rows.tobytes())


@pytest.mark.parametrize("name", ["spot_triangulated.obj", "pediment_join_plate_12.stl"])
def test_renumbered_rotated_and_resaved_mesh_gives_the_same_bytes(name, tmp_path):
    v, f = _load(name)
    _, ref = run(_mesh(v, f), seed=2, count=5000)
    rv, rf = renumbered(v, f)
    write_obj(tmp_path / "r.obj", rv, rf)
    write_ply(tmp_path / "r.ply", rv, rf)
    for other in (_mesh(rv, rf), str(tmp_path / "r.obj"), str(tmp_path / "r.ply")):
        _, got = run(other, seed=2, count=5000)
        assert got.points.tobytes() == ref.points.tobytes()
    # must fail: a mirrored winding is another face
    _, mirrored = run(_mesh(v, f[:, ::-1]), seed=2, count=5000)
    assert mirrored.points.tobytes() != ref.points.tobytes()


# -- edits ------------------------------------------------------------------------------


def _ball(v, f, frac, where=0):
    """Faces (bool (F,)) whose centroid is among the ``frac`` nearest to vertex ``where``."""
    c = v[f].mean(axis=1)
    d = np.linalg.norm(c - v[where], axis=1)
    return d <= np.quantile(d, frac)


def edit_move(v, f):
    """Move the vertices of a region (a few percent of the faces) along z."""
    region = np.unique(f[_ball(v, f, 0.03, len(v) // 3)])
    v = v.copy()
    v[region, 2] += 0.01 * np.ptp(v[:, 2])
    return v, f


def edit_delete(v, f):
    return v, f[~_ball(v, f, 0.05, len(v) // 2)]


def edit_add(v, f):
    """A new patch: the region of a few percent of the faces copied and lifted."""
    part = f[_ball(v, f, 0.04, 0)]
    lifted = v + np.array([0.0, 0.0, 1.5 * np.ptp(v[:, 2])])
    return np.vstack([v, lifted]), np.vstack([f, part + len(v)])


def edit_subdivide(v, f):
    """Split the largest face at its centroid into three."""
    k = int(np.argmax(areas(v, f)))
    a, b, c = f[k]
    m = len(v)
    v = np.vstack([v, v[f[k]].mean(axis=0)])
    return v, np.vstack([np.delete(f, k, axis=0), [[a, b, m], [b, c, m], [c, a, m]]])


EDITS = {"move": edit_move, "delete": edit_delete, "add": edit_add, "subdivide": edit_subdivide}
EDIT_MESHES = {"skull": "skull.ply", "plate": "pediment_join_plate_12.stl", "terrain": "hemisphere.off"}


def split_faces(v, f, v2, f2):
    """(unchanged (F,) bool of the original's faces, unchanged (F2,) of the edited's,
    area kept, area removed, area added)."""
    old, new = face_ids(v, f), face_ids(v2, f2)
    in_new, in_old = set(new), set(old)
    same_old = np.array([x in in_new for x in old])
    same_new = np.array([x in in_old for x in new])
    a, a2 = areas(v, f), areas(v2, f2)
    return same_old, same_new, a[same_old].sum(), a[~same_old].sum(), a2[~same_new].sum()


def expected_changed(n, kept, removed, added, reps=400, seed=0):
    """Mean and sd of the fraction of the N points that an edit moves, from the areas
    alone: three Poisson processes (faces kept, removed, added); the original keeps the
    first N of kept + removed, the edit the first N of kept + added; a point stays when
    it is a kept-face arrival before both N-th arrivals."""
    rng = np.random.default_rng(seed)
    rates = np.array([kept, removed, added])
    length = int(n * rates.sum() / (kept + min(removed, added)) * 1.2) + 100
    labels = rng.choice(3, size=(reps, length), p=rates / rates.sum())
    ck, cr, ca = (np.cumsum(labels == k, axis=1) for k in range(3))
    end_old = np.argmax(ck + cr >= n, axis=1)
    end_new = np.argmax(ck + ca >= n, axis=1)
    stays = ck[np.arange(reps), np.minimum(end_old, end_new)]
    changed = 1 - stays / n
    return changed.mean(), changed.std()


def _points_on(raw, unchanged):
    return raw.points[unchanged[raw.face]]


EDIT_CASES = [(m, e) for m in sorted(EDIT_MESHES) for e in sorted(EDITS) if m != "skull" or e in ("delete", "move")]


@pytest.mark.slow
@pytest.mark.parametrize("mesh, edit", EDIT_CASES)
def test_an_edit_moves_only_the_points_it_should(mesh, edit):
    n = 6000
    v, f = _load(EDIT_MESHES[mesh])
    v2, f2 = EDITS[edit](v, f)
    same_old, same_new, kept, removed, added = split_faces(v, f, v2, f2)
    assert not same_old.all() or not same_new.all()
    _, before = run(_mesh(v, f), seed=4, count=n)
    _, after = run(_mesh(v2, f2), seed=4, count=n)
    a, b = _points_on(before, same_old), _points_on(after, same_new)
    common = min(len(a), len(b))
    # arrivals on unchanged faces are the same ones, so one run's are a prefix of the other's
    assert a[:common].tobytes() == b[:common].tobytes()
    mean, sd = expected_changed(n, kept, removed, added)
    assert abs((1 - common / n) - mean) <= 3 * sd + 1.0 / n


def test_the_edit_test_catches_a_source_keyed_by_face_index(monkeypatch):
    """Broken variant: faces keyed by their index (as Blender seeds them): deleting faces
    renumbers the later ones and reshuffles their points."""
    original = stable_faces.face_keys
    counter = {"next": 0}

    def by_index(cols, seed, extra=None):
        start = counter["next"]
        counter["next"] += len(cols[0])
        return original([np.arange(start, start + len(cols[0]), dtype=np.float64)] * 9, seed)

    v, f = _load("hemisphere.off")
    v2, f2 = edit_delete(v, f)
    same_old, same_new, *_ = split_faces(v, f, v2, f2)
    numpy_path(monkeypatch)  # the broken variant is made on the NumPy path
    monkeypatch.setattr(stable_faces, "face_keys", by_index)
    _, before = run(_mesh(v, f), seed=4, count=6000)
    counter["next"] = 0
    _, after = run(_mesh(v2, f2), seed=4, count=6000)
    a, b = _points_on(before, same_old), _points_on(after, same_new)
    common = min(len(a), len(b))
    assert a[:common].tobytes() != b[:common].tobytes()


def test_expected_fraction_model_matches_a_direct_simulation():
    """The model's mean for a pure deletion: removed / total (the kept faces' points all
    stay, the threshold only moves later)."""
    mean, sd = expected_changed(5000, kept=9.0, removed=1.0, added=0.0)
    assert abs(mean - 0.1) < 3 * sd + 1e-3


@pytest.mark.parametrize("edit", sorted(EDITS))
def test_density_moves_no_point_outside_the_edited_faces(edit):
    v, f = _load("hemisphere.off")
    v2, f2 = EDITS[edit](v, f)
    same_old, same_new, *_ = split_faces(v, f, v2, f2)
    d = 2000.0
    src, before = run(_mesh(v, f), seed=8, density=d)
    _, after = run(_mesh(v2, f2), seed=8, density=d)
    assert _points_on(before, same_old).tobytes() == _points_on(after, same_new).tobytes()
    # the count is Poisson with mean D times the area
    assert abs(src.count - d * src.area) < 4 * np.sqrt(d * src.area)


# -- radius -----------------------------------------------------------------------------


def _min_pair_distance(p):
    from scipy.spatial import cKDTree

    return cKDTree(p).query(p, k=2)[0][:, 1].min()


def test_radius_set_is_spaced_maximal_and_local():
    v, f = _load("hemisphere.off")
    r = 0.05
    src, before = run(_mesh(v, f), seed=9, radius=r)
    assert _min_pair_distance(before.points) >= r
    # maximal: every candidate lies within r of a kept point
    from scipy.spatial import cKDTree

    cand = src.draw(0, src.count).points
    assert cKDTree(before.points).query(cand)[0].max() < r

    v2, f2 = edit_move(v, f)
    same_old, same_new, *_ = split_faces(v, f, v2, f2)
    _, after = run(_mesh(v2, f2), seed=9, radius=r)
    edited = np.vstack([v[f[~same_old]].reshape(-1, 3), v2[f2[~same_new]].reshape(-1, 3)])
    reach = max(np.linalg.norm(v[f[~same_old]] - v[f[~same_old]][:, [1, 2, 0]], axis=2).max(), 0.0)

    def far(p):  # farther than 2R from every edited face (vertex distance minus the longest edge)
        return cKDTree(edited).query(p)[0] - reach > 2 * r

    a, b = before.points[far(before.points)], after.points[far(after.points)]
    assert len(a) > 0.5 * len(before.points)
    assert a.tobytes() == b.tobytes()


# -- determinism ------------------------------------------------------------------------


@pytest.mark.parametrize("threads", ["1", "2", "3", "7"])
def test_any_chunking_and_thread_count_gives_the_same_bytes(threads, monkeypatch):
    v, f = _load("spot_triangulated.obj")
    src, ref = run(_mesh(v, f), seed=1, count=7000)
    monkeypatch.setenv("SCATTER_THREADS", threads)
    monkeypatch.setattr(stable_faces, "FACE_BLOCK", 1000)
    monkeypatch.setattr(stable_arrivals, "ARRIVAL_BLOCK", 777)
    monkeypatch.setattr(stable_order, "ROOM_SDS", -50.0)  # the kernel's arrays overflow: the second pass
    src2 = StableSource(load_surface(_mesh(v, f)), 1, want_bary=True, count=7000)
    for size in (1, 999, 7000):
        parts = [src2.draw(s, min(s + size, 7000)) for s in range(0, 7000, size)] if size > 1 else [
            src2.draw(s, s + 1) for s in range(0, 50)]
        got = np.concatenate([p.points for p in parts])
        assert got.tobytes() == ref.points[: len(got)].tobytes()


def test_duplicate_faces_have_their_own_streams():
    """A face listed twice has twice the weight: both copies get points, not the same ones."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 0, 0], [6, 0, 0], [5, 1, 0]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 1, 2], [3, 4, 5]])
    _, raw = run(_mesh(v, f), seed=0, count=3000)
    counts = np.bincount(raw.face, minlength=3)
    assert chi2_gof(counts, np.ones(3))[2] > ALPHA
    assert len(np.unique(raw.points, axis=0)) == 3000


def test_arrival_order_breaks_equal_times_by_key_then_counter():
    t = np.array([2.0, 1.0, 1.0, 1.0, 0.5])
    face = np.array([0, 1, 0, 1, 2])
    ctr = np.array([0, 7, 3, 2, 0], dtype=np.uint64)
    key = np.array([9, 4, 1], dtype=np.uint64)
    assert stable_order.arrival_order(t, face, ctr, key).tolist() == [4, 3, 1, 2, 0]


def test_canonical_rotation_keeps_winding_and_starts_at_the_smallest_corner():
    tri = np.array([[1.0, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 1, 1, 0, 0, 0, 1, 0], [0, 1, 0, 0, 0, 1, 1, 0, 0]])
    rot, cols = stable_faces.canonical(list(tri.T))
    out = np.stack(cols, axis=1)
    assert rot.tolist() == [2, 0, 1]
    assert (out == out[0]).all()
    assert out[0].tolist() == [0, 0, 1, 1, 0, 0, 0, 1, 0]


# -- the compiled kernel, scenes, weights, the command line ------------------------------


def _all_bytes(samples):
    return samples.points.tobytes() + b"".join(a.tobytes() for _, a in sorted(samples.attributes.items()))


CASES = [("skull.ply", dict(count=20_000)), ("skull.ply", dict(count=None, density=30.0)),
         ("pediment_join_plate_12.stl", dict(count=None, radius=1.5)), ("cesiummilktruck.glb", dict(count=5000)),
         # weights: the face table from NumPy; textures filter the kernel's sorted arrivals
         ("boxvertexcolors.glb", dict(count=5000, weight="vertex-color:r")),
         ("boxtextured.glb", dict(count=5000, weight="texture:g"))]
needs_kernel = pytest.mark.skipif(stable._kernel is None and os.environ.get("SCATTER_REQUIRE_KERNELS", "") in ("", "0"),
                                  reason="compiled kernels not built (SCATTER_REQUIRE_KERNELS=1 makes this a failure)")


@needs_kernel
@pytest.mark.parametrize("name, kw", CASES)
def test_kernel_and_numpy_paths_give_the_same_bytes(name, kw, monkeypatch):
    import scatter_cli

    assert stable._kernel is not None  # CI builds it: a silent fallback would leave it untested
    args = dict(stable=True, attributes=("face", "bary", "object"), **kw)
    compiled = scatter_cli.sample(str(SAMPLES / name), **args)
    numpy_path(monkeypatch)
    assert _all_bytes(scatter_cli.sample(str(SAMPLES / name), **args)) == _all_bytes(compiled)


class _SideSizes:
    """The stable kernel, recording the side arrays each order() call is given."""

    def __init__(self, kernel):
        self._kernel, self.sides = kernel, []

    def __getattr__(self, name):
        return getattr(self._kernel, name)

    def order(self, *args):
        self.sides.append(len(args[-1]))
        return self._kernel.order(*args)


@needs_kernel
@pytest.mark.parametrize("threads, room", [("2", None), ("3", None), ("7", None), ("2", -50.0)])
def test_kernel_sorts_across_threads_in_numpys_order(threads, room, monkeypatch):
    """Over 2^16 arrivals: several face ranges write into each time bucket, the threads
    sort bucket ranges in place, many a thread (each writing its lowest positions to side
    arrays while the range below may still be read), and with room -50 sd every bucket
    overflows and the pass reruns with exact room. The arrivals and their order are NumPy's."""
    table = stable_faces.FaceTable(load_surface(str(SAMPLES / "skull.ply")), 5)
    tau = 150_000 / table.total
    bits = stable_arrivals.counter_bits(table, tau)
    t0, face, ctr = stable_arrivals.all_arrivals(table, tau)
    order = stable_order.arrival_order(t0, face, ctr, table.key)
    monkeypatch.setenv("SCATTER_THREADS", threads)
    if room is not None:
        monkeypatch.setattr(stable_order, "ROOM_SDS", room)
    spy = _SideSizes(stable_order._kernel)
    monkeypatch.setattr(stable_order, "_kernel", spy)
    t, ids, dup = stable_order.kernel_arrivals(table, tau, bits)
    assert len(spy.sides) == native.PIECES_PER_THREAD * int(threads)
    # with slack in the buckets, every range but the first writes below its own segments
    assert (min(spy.sides[1:]) > 0) if room is None else (max(spy.sides) == 0)
    assert t.tobytes() == t0[order].tobytes()
    assert ids.tobytes() == stable_arrivals.pack(face, ctr, bits)[order].tobytes()
    assert not dup


@needs_kernel
def test_kernel_refuses_bad_buckets_and_segments():
    k, key, rate = stable._kernel, np.zeros(4, np.uint64), np.ones(4)
    t, ids, none = np.zeros(8), np.zeros(8, np.uint64), (np.empty(0), np.empty(0, np.uint64))
    arrivals = (key, rate, 1.0, 2.0, stable_arrivals.POISSON_CDF, 0, 4, 8, 8.0, 2, 8)
    with pytest.raises(ValueError, match="bad range"):  # a bucket that starts past its end
        k.arrivals(*arrivals, np.array([5, 0]), np.array([4, 8]), t, ids)
    with pytest.raises(ValueError, match="bad range"):  # a bucket that ends past the arrays
        k.arrivals(*arrivals, np.array([0, 4]), np.array([4, 9]), t, ids)
    with pytest.raises(ValueError, match="bad buckets"):  # two buckets for keys that need three
        k.arrivals(*arrivals[:-1], 9, np.zeros(2, np.int64), np.full(2, 8), t, ids)
    start, count = np.array([0, 3]), np.array([4, 2])  # segment 0 runs into segment 1
    with pytest.raises(ValueError, match="segments"):
        k.order(t, ids, start, count, 1, 0, 2, 8.0, 2, 8, key, 8, *none)
    with pytest.raises(ValueError, match="side"):  # positions 0..2 of bucket 1 go to the side
        k.order(t, ids, np.array([0, 3]), np.array([0, 3]), 1, 1, 2, 8.0, 2, 8, key, 8, *none)
    with pytest.raises(TypeError):  # corner rows of the wrong size
        k.place(np.zeros(1, np.uint64), 8, key, None, np.zeros((4, 3), np.int64), np.zeros((3, 3)), np.zeros((3, 9)),
                np.empty((1, 3)), None, None, False)


def test_scene_instances_are_keyed_in_world_space():
    """Instances moved by their node matrices get the bytes that the same faces get when
    their vertices are moved in the file instead (by the same float64 operations)."""
    import trimesh

    from scatter_cli.surface.model import apply_matrix

    from .conftest import scaled_scene

    scene = scaled_scene()
    baked = trimesh.Scene()
    for node in scene.graph.nodes_geometry:
        matrix, name = scene.graph[node]
        mesh = scene.geometry[name].copy()
        mesh.vertices = apply_matrix(np.asarray(matrix, dtype=np.float64)[:3], np.asarray(mesh.vertices, dtype=np.float64))
        baked.add_geometry(mesh, node_name=node, geom_name=node)
    a, b = run(scene, seed=1, count=4000)[1], run(baked, seed=1, count=4000)[1]
    assert a.points.tobytes() == b.points.tobytes()
    assert np.array_equal(a.instance, b.instance)
    assert set(np.unique(a.instance)) == set(range(4))


def test_vertex_colour_weight_rate_is_area_times_mean_weight():
    """Chi-square of face counts against area times the exact mean weight; the same counts
    must fail against area alone."""
    from scatter_cli.surface.model import apply_matrix
    from scatter_cli.sampling.weighting import VertexColorWeight

    surface = load_surface(str(SAMPLES / "boxvertexcolors.glb"))
    src = StableSource(surface, 2, count=20_000, weight=stable_weights.stable_weight(surface, "vertex-color:r"))
    raw = src.draw(0, src.count)
    exact = VertexColorWeight(surface, 0, "vertex-color:r")
    width = max(len(g.faces) for g in surface.geometries)
    counts = np.bincount(raw.instance * width + raw.face, minlength=len(surface.instances) * width)
    weighted, area_only = np.zeros(len(counts)), np.zeros(len(counts))
    for k, inst in enumerate(surface.instances):
        g = surface.geometries[inst.geometry]
        v = g.vertices if inst.matrix is None else apply_matrix(inst.matrix[:3], g.vertices)
        rows = k * width + np.arange(len(g.faces))
        area_only[rows] = areas(v, g.faces)
        weighted[rows] = area_only[rows] * exact.face_weights(k, inst)
    keep = weighted > 0
    assert counts[~keep].sum() == 0
    for expect, passes in ((weighted, True), (area_only, False)):
        p = chi2_gof(counts[keep], expect[keep], smallest_first=True)[2]  # faces: pooled smallest first
        assert (p > ALPHA) == passes


@pytest.mark.slow
def test_cli_stable_renumbered_file_gives_the_same_output_bytes(tmp_path):
    from .conftest import run_scatter

    v, f = _load("spot_triangulated.obj")
    write_ply(tmp_path / "a.ply", v, f)
    write_obj(tmp_path / "b.obj", *renumbered(v, f))
    outs = []
    for name in ("a.ply", "b.obj"):
        out = tmp_path / f"{name}.csv"
        run_scatter("sample", tmp_path / name, "--stable", "-n", "2000", "--seed", "3", "-o", out, check=True)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    assert len(outs[0].splitlines()) == 2001


@pytest.mark.slow
@pytest.mark.parametrize("bad", [["--method", "sobol"], ["--method", "stratified"], ["--poisson"]])
def test_cli_stable_with_another_method_or_poisson_is_a_usage_error_before_reading(bad, tmp_path):
    from .conftest import run_scatter

    proc = run_scatter("sample", tmp_path / "missing.ply", "--stable", *bad)
    assert proc.returncode == 2
    err = proc.stderr.decode().strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --stable") and "Traceback" not in proc.stderr.decode()


def test_texture_weight_thins_to_area_times_weight():
    """The texture-masked quad of test_attributes: u-histogram against the exact weighted
    mass; the unweighted stable points must fail it."""
    import scatter_cli

    from .test_attributes import chi_p, exact_u_bins, texture_mask_quad

    mesh = texture_mask_quad()
    n = 20_000
    edges = np.linspace(0, 1, 33)
    expect = exact_u_bins(mesh, 0, edges)
    expect = expect / expect.sum() * n
    s = scatter_cli.sample(mesh, n, stable=True, weight="texture:r", attributes=("uv",), precision="float64", seed=9)
    assert len(s.points) == n
    assert chi_p(np.histogram(s.uv[:, 0], edges)[0], expect) > ALPHA
    assert not np.any((s.uv[:, 0] > 1 / 16) & (s.uv[:, 0] < 7 / 16))
    u = scatter_cli.sample(mesh, n, stable=True, attributes=("uv",), precision="float64", seed=9)
    assert chi_p(np.histogram(u.uv[:, 0], edges)[0], expect) < ALPHA


@pytest.mark.parametrize("kw", [dict(count=3000), dict(count=None, density=400.0), dict(count=None, radius=0.05)])
def test_api_output_is_the_same_for_any_chunk_size_and_threads(kw, monkeypatch):
    import scatter_cli

    mesh = str(SAMPLES / "spot_triangulated.obj")
    ref = scatter_cli.sample(mesh, stable=True, attributes=("face", "bary"), **kw)
    monkeypatch.setenv("SCATTER_THREADS", "1")
    for size in (97, 1000):
        got = scatter_cli.sample(mesh, stable=True, attributes=("face", "bary"), chunk_size=size, **kw)
        assert _all_bytes(got) == _all_bytes(ref)


def _weighted_area(mesh_or_path, spec):
    """Exact area times weight over the surface: vertex colours by the exact per-face mean
    weight; the texture-masked quad by the mean of its weight over u (constant in v)."""
    from scatter_cli.surface.model import apply_matrix
    from scatter_cli.sampling.weighting import VertexColorWeight

    from .test_attributes import exact_u_bins

    surface = load_surface(mesh_or_path)
    if spec.startswith("texture"):
        g = surface.geometries[0]
        mean = exact_u_bins(mesh_or_path, 0, np.linspace(0, 1, 2))[0] / 200_000 / 255  # texels 0..255 -> 0..1
        return areas(g.vertices, g.faces).sum() * mean
    exact = VertexColorWeight(surface, 0, spec)
    total = 0.0
    for k, inst in enumerate(surface.instances):
        g = surface.geometries[inst.geometry]
        v = g.vertices if inst.matrix is None else apply_matrix(inst.matrix[:3], g.vertices)
        total += float(np.sum(areas(v, g.faces) * exact.face_weights(k, inst)))
    return total


@pytest.mark.parametrize("spec", ["vertex-color:r", "texture:r"])
def test_weighted_density_count_is_d_times_area_times_weight(spec):
    """--stable --density D --weight W: a Poisson count with mean D times the weighted area
    (docs/stable.md: no normalisation by the total weight, which would make every point
    depend on every face). Broken variant: the default method's count, round(D x area),
    must fail the same check."""
    import scatter_cli

    from .test_attributes import texture_mask_quad

    mesh = texture_mask_quad() if spec.startswith("texture") else str(SAMPLES / "boxvertexcolors.glb")
    d = 3000.0
    mean = d * _weighted_area(mesh, spec)
    got = len(scatter_cli.sample(mesh, None, density=d, stable=True, weight=spec, seed=4).points)
    default = len(scatter_cli.sample(mesh, None, density=d, weight=spec, seed=4).points)
    for count, passes in ((got, True), (default, False)):
        assert (abs(count - mean) < 4 * np.sqrt(mean)) == passes, (spec, count, mean)
