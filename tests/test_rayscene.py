"""The compiled Embree scene (scatter_cli/sampling/exterior/_cembree.c) gives embreex's verdicts, and the
face-normal kernel gives normals.face_normals' NumPy values, bit for bit.

embreex builds its scene by copying the mesh element by element; the kernel shares the
arrays with the same library. Both are robust scenes of one triangle geometry per mesh,
queried with the same rays, so every verdict must agree, including rays that start on a
face or graze an edge. Each comparison is paired with a broken variant (a scene missing
its last face, normals with the edges swapped) that the same check must catch.
"""

import os

import numpy as np
import pytest

from scatter_cli.sampling import normals
from scatter_cli.sampling.exterior import rayscene
from scatter_cli.loading.load import load_surface

from . import exterior_scenes as es
from .conftest import awkward_mesh, run_scatter

pytest.importorskip("embreex")
REQUIRED = os.environ.get("SCATTER_REQUIRE_KERNELS", "") not in ("", "0")
COMPILED = rayscene._compiled()
pytestmark = pytest.mark.skipif(COMPILED is None and not REQUIRED,
                                reason="the Embree kernel is not built (SCATTER_REQUIRE_KERNELS=1 makes this a failure)")


def test_the_kernel_finds_the_library_and_is_used():
    assert COMPILED is not None and rayscene.embree_library() is not None
    assert rayscene.RayScene()._c is not None


def scenes(monkeypatch, meshes, drop_last=False):
    """(kernel scene, embreex scene) of ``meshes`` [(vertices (n, 3), faces (m, 3))];
    ``drop_last``: the kernel's scene misses the last face of the last mesh (broken)."""
    fast = rayscene.RayScene()
    for k, (v, f) in enumerate(meshes):
        fast.add(v, f[:-1] if drop_last and k == len(meshes) - 1 else f, np.zeros(3))
    fast.commit()
    with monkeypatch.context() as m:
        m.setattr(rayscene, "_compiled", lambda: None)
        slow = rayscene.RayScene()
    assert fast._c is not None and slow._c is None
    for v, f in meshes:
        slow.add(v, f, np.zeros(3))
    slow.commit()
    return fast, slow


def rays(meshes, n, seed):
    """(origins, directions) (n, 3) float32: from points on the faces (on them, or a few
    roundings off either side) in random directions, half of them along the normals."""
    rng = np.random.default_rng(seed)
    tri = np.concatenate([v[f] for v, f in meshes])
    face = rng.integers(0, len(tri), n)
    u = rng.random((n, 2))
    s = np.sqrt(u[:, 0])
    b = np.stack([1 - s, s * (1 - u[:, 1]), s * u[:, 1]], axis=1)
    p = np.einsum("ij,ijk->ik", b, tri[face])
    normal = normals.face_normals(tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3))[face]
    off = rng.choice([0.0, 1e-7, -1e-7, 1e-5], n)[:, None]
    d = rng.normal(size=(n, 3))
    d[: n // 2] = normal[: n // 2] * rng.choice([1.0, -1.0], (n // 2, 1))
    return (p + off * normal).astype(np.float32), d.astype(np.float32)


def mesh_list(scene):
    surface = load_surface(scene)
    return [(surface.world_vertices(inst), surface.geometries[inst.geometry].faces) for inst in surface.instances]


@pytest.mark.parametrize("build", [es.box_in_box, es.car, es.bowl])
def test_same_verdicts_as_embreex(build, monkeypatch, tmp_path):
    path = tmp_path / "scene.glb"
    build()[0].export(path)
    meshes = mesh_list(path)
    fast, slow = scenes(monkeypatch, meshes)
    o, d = rays(meshes, 60000, seed=1)
    hit = fast.occluded(o, d)
    assert 0.05 < hit.mean() < 0.95  # the rays test both verdicts
    np.testing.assert_array_equal(hit, slow.occluded(o, d))


def test_a_scene_missing_a_face_fails_the_same_check(monkeypatch, tmp_path):
    path = tmp_path / "scene.glb"
    es.box_in_box()[0].export(path)
    meshes = mesh_list(path)
    fast, slow = scenes(monkeypatch, meshes, drop_last=True)
    o, d = rays(meshes, 60000, seed=1)
    assert np.any(fast.occluded(o, d) != slow.occluded(o, d))


@pytest.mark.slow
def test_exterior_output_is_the_same_without_the_kernels(tmp_path):
    path = tmp_path / "car.glb"
    es.car()[0].export(path)
    outs = []
    for env in ({}, {"SCATTER_NUMPY": "1"}):
        out = tmp_path / f"out{len(outs)}.ply"
        run_scatter("sample", path, "--exterior", "-n", "20000", "-a", "normal,face", "-o", out, check=True, env=env)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


def numpy_normals(v, f):
    """The normals as np.cross and np.linalg.norm give them."""
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(np.isfinite(n), n, 0.0)


@pytest.mark.parametrize("seed, center", [(0, None), (1, None), (2, None), (0, [0.3, -1e150, 7.0]), (1, [1.0, 1.0, 1.0])])
def test_face_normals_kernel_is_numpys_bit_for_bit(seed, center, monkeypatch):
    """The normals of the faces less a centre (none, one far off, one at a vertex)."""
    v, f = awkward_mesh(seed)
    assert normals._kernel is not None
    with np.errstate(all="ignore"):
        fast = normals.face_normals(v, f, center)
        monkeypatch.setattr(normals, "_kernel", None)
        slow = normals.face_normals(v, f, center)
        want = numpy_normals(v - (0.0 if center is None else np.array(center)), f)
    assert fast.tobytes() == slow.tobytes() == np.ascontiguousarray(want).tobytes()
    assert np.any(fast != 0) and (center is not None or np.all(fast[:2] == 0))


def test_buffers_are_numpys_float32_of_the_vertices_less_the_centre():
    """The arrays the kernel shares with Embree: (v - center) as float32 (NaN, inf, huge and
    tiny coordinates), a zero fourth column, the indices as int32; an index out of range
    is refused."""
    v, f = awkward_mesh(3)
    center = np.array([0.25, -3e38, 1e-300])
    with np.errstate(all="ignore"):
        v4, f32 = COMPILED.buffers(v, center, f)
        want = (v - center).astype(np.float32)
    assert v4.shape == (len(v), 4) and v4[:, :3].tobytes() == want.tobytes() and not v4[:, 3].any()
    assert f32.dtype == np.int32 and np.array_equal(f32, f)
    assert COMPILED.buffers(v, center + 1.0, f)[0][:, :3].tobytes() != want.tobytes()  # (the check can fail)
    for bad in (len(v), -1):
        g = f.copy()
        g[7, 2] = bad
        with pytest.raises(ValueError, match="out of range"):
            COMPILED.buffers(v, center, g)


def test_normals_with_the_edges_swapped_fail_the_same_check():
    v, f = awkward_mesh(0)
    with np.errstate(all="ignore"):
        assert normals.face_normals(v, f[:, [0, 2, 1]]).tobytes() != np.ascontiguousarray(numpy_normals(v, f)).tobytes()


def test_kernels_refuse_bad_arrays():
    scene = COMPILED.new_scene()
    v = np.zeros((3, 4), np.float32)
    with pytest.raises(ValueError, match="out of range"):
        COMPILED.add(scene, v, np.array([[0, 1, 3]], np.int32))
    with pytest.raises(ValueError, match="out of range"):
        COMPILED.add(scene, v, np.array([[0, -1, 2]], np.int32))
    with pytest.raises(TypeError):
        COMPILED.add(scene, v.astype(np.float64), np.array([[0, 1, 2]], np.int32))
    with pytest.raises(TypeError):
        COMPILED.occluded(scene, np.zeros((2, 3), np.float32), np.zeros((1, 3), np.float32), np.empty(2, bool))
    with pytest.raises(ValueError, match="out of range"):
        normals._kernel.unit_normals(np.zeros((3, 3)), np.array([[0, 1, 3]]), np.empty((1, 3)), np.zeros(3))
    with pytest.raises(TypeError):
        normals._kernel.unit_normals(np.zeros((3, 3)), np.array([[0, 1, 2]]), np.empty((1, 3)), np.zeros(2))


def test_a_library_that_does_not_load_falls_back_to_embreex(monkeypatch):
    monkeypatch.setattr(rayscene, "embree_library", lambda: "/nonexistent/libembree4.so")
    monkeypatch.setattr(COMPILED, "load", lambda path: (_ for _ in ()).throw(OSError("no such file")))
    assert rayscene._compiled() is None
    assert rayscene.RayScene()._c is None
