"""The compiled kernels give the same bytes as the NumPy code they stand in for.

Every other test runs with the kernels (CI builds them), so these parity tests are what
carries those results over to the NumPy path that runs where no C compiler was found.
"""

import os
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli import greedy, native, pairs, sampling, thinning
from scatter_cli.loaders import load_surface
from scatter_cli.surface import Geometry, Instance, Surface

from .conftest import SAMPLES, run_user, spread_triangles, triangles_mesh

REPO = Path(__file__).resolve().parents[1]
KERNELS_BUILT = sampling._kernel is not None and pairs._kernel is not None
# Without a C compiler the install runs the NumPy path alone and these tests have nothing to
# compare; .ci/run sets SCATTER_REQUIRE_KERNELS=1 so that there a missing kernel fails.
pytestmark = pytest.mark.skipif(
    not KERNELS_BUILT and os.environ.get("SCATTER_REQUIRE_KERNELS", "") in ("", "0"),
    reason="compiled kernels not built (SCATTER_REQUIRE_KERNELS=1 makes this a failure)",
)


@pytest.fixture
def numpy_only(monkeypatch):
    """A function that runs ``fn()`` with both kernels switched off."""

    def run(fn):
        with monkeypatch.context() as m:
            m.setattr(sampling, "_kernel", None)
            m.setattr(pairs, "_kernel", None)
            return fn()

    return run


def test_the_kernels_are_built():
    # CI must exercise the compiled path: a silent fallback would leave it untested.
    assert KERNELS_BUILT


def test_the_kernels_share_the_numpy_paths_constants():
    # what the C code and the NumPy path must agree on, read from both sides
    assert sampling._kernel.DRAWS_PER_POINT == sampling.DRAWS_PER_POINT
    assert pairs._kernel.BITS == pairs.BITS
    assert pairs._kernel.MAX_CELLS == pairs.MAX_CELLS
    assert pairs._kernel.CROWD_SCALE == greedy.CROWD_SCALE


def test_scatter_numpy_switches_them_off(monkeypatch):
    monkeypatch.setenv("SCATTER_NUMPY", "1")
    assert native.kernel("_csampling") is None
    monkeypatch.setenv("SCATTER_NUMPY", "0")
    assert native.kernel("_csampling") is not None


def same_samples(a, b):
    assert a.points.dtype == b.points.dtype
    assert a.points.tobytes() == b.points.tobytes()
    assert sorted(a.attributes) == sorted(b.attributes)
    for key in a.attributes:
        assert a.attributes[key].tobytes() == b.attributes[key].tobytes(), key


def with_degenerate_faces():
    tri, _ = spread_triangles(np.arange(-9, 4))
    tri[3] = [[0, 0, 5], [1, 0, 5], [2, 0, 5]]  # collinear: never chosen
    tri[7] = [[1e6, 1e6, 1e6], [1e6 + 1e-3, 1e6, 1e6], [1e6, 1e6 + 2e-3, 1e6]]  # far away, tiny
    return triangles_mesh(tri)


def moved_instances():
    """One geometry placed three times, one of them with a non-uniform scale."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    g = Geometry("ball", mesh.vertices, mesh.faces)
    stretch = np.diag([3.0, 0.5, 1.0, 1.0])
    stretch[:3, 3] = [10, 0, 0]
    shift = np.eye(4)
    shift[:3, 3] = [0, -7.25, 1e3]
    return Surface([g], [Instance("a", 0, None), Instance("b", 0, stretch), Instance("c", 0, shift)], "balls")


def one_moved_mesh():
    mesh = trimesh.load(SAMPLES / "koala.obj", process=False)
    m = np.array([[0.0, 2.0, 0.0, 1.5], [-1.0, 0.0, 0.0, 3.0], [0.0, 0.0, 0.25, -2.0], [0.0, 0.0, 0.0, 1.0]])
    g = Geometry("koala", mesh.vertices, mesh.faces)
    return Surface([g], [Instance("moved", 0, m)], "moved koala")


CASES = [
    ("skull", dict()),
    ("skull", dict(method="stratified")),
    ("skull", dict(method="sobol")),
    ("skull", dict(attributes="face,bary,normal", precision="float32")),
    ("degenerate", dict(attributes="face,bary")),
    ("instances", dict(attributes="face,object,normal")),
    ("moved", dict(attributes="normal")),
    ("truck", dict(attributes="face,object,smooth-normal,color")),
    ("colors", dict(weight="vertex-color:r")),
    ("textured", dict(weight="texture:g")),
]


def mesh_for(name, sample_mesh):
    return {
        "skull": lambda: sample_mesh("skull.ply"),
        "degenerate": with_degenerate_faces,
        "instances": moved_instances,
        "moved": one_moved_mesh,
        "truck": lambda: sample_mesh("cesiummilktruck.glb"),
        "colors": lambda: sample_mesh("boxvertexcolors.glb"),
        "textured": lambda: sample_mesh("boxtextured.glb"),
    }[name]()


@pytest.mark.parametrize("name,options", CASES, ids=[f"{n}-{'-'.join(o) or 'plain'}" for n, o in CASES])
def test_sampling_is_byte_identical_without_the_kernel(name, options, sample_mesh, numpy_only):
    mesh = mesh_for(name, sample_mesh)
    surface = mesh if isinstance(mesh, Surface) else load_surface(mesh)
    kw = dict(count=20_011, seed=7, precision="float64", chunk_size=4096) | options
    same_samples(scatter_cli.sample(surface, **kw), numpy_only(lambda: scatter_cli.sample(surface, **kw)))


@pytest.mark.parametrize("name", ["skull", "degenerate", "instances", "moved"])
def test_face_order_gives_the_same_bytes(name, sample_mesh, numpy_only):
    # On large meshes the kernel computes a chunk's points in face order (the plan's
    # in_face_order); forced on here, it must not change a byte, whatever the chunk size.
    mesh = mesh_for(name, sample_mesh)
    surface = mesh if isinstance(mesh, Surface) else load_surface(mesh)
    plan = sampling.SamplePlan(surface)
    plan.in_face_order = True
    whole = plan.draw(0, 30_011, 3, want_bary=True)
    parts = [plan.draw(a, min(a + 7_000, 30_011), 3, want_bary=True) for a in range(0, 30_011, 7_000)]
    reference = numpy_only(lambda: sampling.SamplePlan(surface).draw(0, 30_011, 3, want_bary=True))
    for field in ("points", "face", "bary", "instance"):
        expected = getattr(reference, field).tobytes()
        assert getattr(whole, field).tobytes() == expected, field
        assert np.concatenate([getattr(p, field) for p in parts]).tobytes() == expected, field


def test_large_meshes_go_in_face_order_and_larger_chunks():
    small = sampling.SamplePlan(load_surface(trimesh.creation.icosphere(subdivisions=3)))
    large = sampling.SamplePlan(load_surface(trimesh.creation.icosphere(subdivisions=7)))  # 327,680 faces
    assert not small.in_face_order and small.default_chunk == sampling.DEFAULT_CHUNK
    assert large.in_face_order and large.default_chunk == sampling.LARGE_MESH_CHUNK


@pytest.mark.parametrize("options", [dict(poisson=True, count=3000), dict(radius=0.02)])
def test_thinning_is_byte_identical_without_the_kernel(options, sample_mesh, numpy_only):
    surface = load_surface(sample_mesh("koala.obj"))
    kw = dict(seed=3, attributes="face", **options)
    a = scatter_cli.sample(surface, **kw)
    b = numpy_only(lambda: scatter_cli.sample(surface, **kw))
    same_samples(a, b)
    assert a.info.get("d_min") == b.info.get("d_min")


def point_sets():
    rng = np.random.default_rng(11)
    sphere = rng.normal(size=(20_000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    clustered = np.repeat(rng.random((200, 3)), 40, axis=0) + rng.normal(scale=1e-4, size=(8000, 3))
    duplicated = np.repeat(rng.random((500, 3)), 30, axis=0)  # all but one of each over the cap
    wall = rng.random((10_000, 3)) * [1, 1, 0]
    wall[::2, 2] = 0.013  # two sheets closer than the radius
    far = rng.random((3000, 3)) * 1e-3 + 1e7  # huge coordinates, small extent
    # cells along a diagonal: their box is too large for the kernel's table of cells, which
    # then searches the sorted cell list instead
    line = rng.random((4000, 1)) * [1.0, 1.0, 1.0] + rng.normal(scale=1e-3, size=(4000, 3))
    # about 160 neighbours a point: more pairs than the kernel lists, so it finds them again
    dense = rng.random((20_000, 3)) * [1, 1, 0]
    return {"sphere": (sphere, 0.05), "clustered": (clustered, 0.02), "duplicated": (duplicated, 0.03),
            "wall": (wall, 0.02), "far": (far, 1e-4), "line": (line, 0.003), "dense": (dense, 0.05)}


@pytest.mark.parametrize("name", list(point_sets()))
def test_thinning_kernels_match_numpy(name, numpy_only):
    points, radius = point_sets()[name]
    by_radius = thinning.thin_by_radius(points, radius)
    np.testing.assert_array_equal(by_radius, numpy_only(lambda: thinning.thin_by_radius(points, radius)))
    count = max(2, len(by_radius) // 2)
    area = 1.0  # only scales the first radius tried
    idx, d_min = thinning.thin_to_count(points, count, area)
    idx2, d_min2 = numpy_only(lambda: thinning.thin_to_count(points, count, area))
    np.testing.assert_array_equal(idx, idx2)
    assert d_min == d_min2 and len(idx) == count


@pytest.mark.parametrize("name", ["sphere", "clustered", "far"])
def test_pair_kernel_finds_the_pairs_of_the_numpy_search(name):
    points, radius = point_sets()[name]
    i, j, d = pairs.all_pairs(points, radius)
    i2, j2, d2 = pairs.self_pairs(points, radius)
    key, key2 = np.lexsort((j, i)), np.lexsort((j2, i2))
    np.testing.assert_array_equal(i[key], i2[key2])
    np.testing.assert_array_equal(j[key], j2[key2])
    assert d[key].tobytes() == d2[key2].tobytes()


@pytest.mark.parametrize("threads", ["1", "2", "5"])
def test_greedy_does_not_depend_on_the_thread_count(threads, monkeypatch):
    # enough points for the kernel to split the crowding pass (16,384 a thread at least)
    points = np.random.default_rng(5).normal(size=(90_000, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    radius = 0.02
    monkeypatch.setenv("SCATTER_THREADS", "1")
    want = thinning.thin_by_radius(points, radius)
    monkeypatch.setenv("SCATTER_THREADS", threads)
    np.testing.assert_array_equal(thinning.thin_by_radius(points, radius), want)


_THIN_IN_A_CHILD = """
import sys
import numpy as np
from scatter_cli import pairs, thinning
from tests.test_native import point_sets
out = {}
for name in ("sphere", "clustered", "wall"):
    points, radius = point_sets()[name]
    out[name + "-radius"] = thinning.thin_by_radius(points, radius)
    out[name + "-count"] = thinning.thin_to_count(points, 500, 1.0)[0]
    i, j, d = pairs.all_pairs(points, radius)
    key = np.lexsort((j, i))
    out[name + "-pairs"] = np.stack([i[key], j[key], d[key].view(np.int64)])
np.savez(sys.argv[1], **out)
"""


def test_the_avx512_loops_keep_the_same_points(tmp_path):
    """With and without the AVX-512 distance loops (SCATTER_NO_AVX512=1) the kernel finds
    the same pairs and keeps the same points. (On a CPU without AVX-512 both runs take
    the plain loops.)"""
    runs = []
    for plain in ("", "1"):
        out = tmp_path / f"plain{plain}.npz"
        env = {"SCATTER_NO_AVX512": plain}  # empty means unset
        run_user([sys.executable, "-c", _THIN_IN_A_CHILD, str(out)], cwd=REPO, env=env, check=True)
        runs.append(np.load(out))
    assert set(runs[0].files) == set(runs[1].files)
    for key in runs[0].files:
        np.testing.assert_array_equal(runs[0][key], runs[1][key], err_msg=key)


def test_kernels_refuse_bad_arrays_instead_of_crashing():
    k = sampling._kernel
    out = np.empty(1)
    with pytest.raises(ValueError, match="out of range"):
        k.areas(np.zeros((3, 3)), np.array([[0, 1, 3]]), None, out)
    with pytest.raises(TypeError):
        k.areas(np.zeros((3, 3), dtype=np.float32), np.array([[0, 1, 2]]), None, out)
    with pytest.raises(TypeError):
        pairs._kernel.grid(np.zeros((4, 2)), np.zeros(3), 1.0, 0)


@pytest.mark.parametrize("seed,start", [(0, 0), (7, 3), (2**63 + 5, 10**12), (123456789, 2**40 + 1)])
def test_the_kernels_generator_is_numpys_stream(seed, start, sample_mesh, numpy_only):
    # The kernel draws PCG64DXSM itself: any start, far into the stream, must match NumPy.
    surface = load_surface(sample_mesh("koala.obj"))
    a = sampling.SamplePlan(surface).draw(start, start + 1000, seed, want_bary=True)
    b = numpy_only(lambda: sampling.SamplePlan(surface).draw(start, start + 1000, seed, want_bary=True))
    for field in ("points", "face", "bary"):
        assert getattr(a, field).tobytes() == getattr(b, field).tobytes(), field
