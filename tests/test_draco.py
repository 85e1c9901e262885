"""glTF with Draco-compressed meshes: decoded under node transforms and instancing like any
scene, and a one-line error naming the extra to install when DracoPy is missing.

Two-sample tests compare voxel counts (chi-square contingency) at significance ALPHA,
with a paired must-fail case.
"""

import os

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli.errors import ScatterError
from scatter_cli.loading.load import load_surface

from .conftest import SAMPLES, run_scatter
from testkit.gltfwrite import glb_bytes
from .test_scenes import two_sample_p

pytest.importorskip("DracoPy")

ALPHA = 1e-3
BITS = 14


def _placements():
    rot = trimesh.transformations.rotation_matrix(0.9, [0, 1, 1])
    stretch = rot @ np.diag([2.0, 0.5, 1.0, 1.0])
    stretch[:3, 3] = [3, 0, 0]
    lifted = np.eye(4)
    lifted[:3, 3] = [0, 0, 2]
    return stretch, lifted


def _glb(tmp_path, name, *, draco, transform=True, preserve_order=True):
    """The cow placed twice (a stretch and a copy of the same mesh) and a sphere once."""
    cow = trimesh.load(SAMPLES / "spot_triangulated.obj", process=False)
    ball = trimesh.creation.icosphere(subdivisions=2)
    stretch, lifted = _placements()
    nodes = [(0, stretch if transform else None), (0, None), (1, lifted)]
    path = tmp_path / name
    path.write_bytes(glb_bytes([(cow.vertices, cow.faces), (ball.vertices, ball.faces)], nodes, draco=draco,
                               quantization_bits=BITS, preserve_order=preserve_order))
    return path


def test_decoded_faces_match_the_uncompressed_ones_up_to_quantisation(tmp_path):
    plain = load_surface(_glb(tmp_path, "plain.glb", draco=False))
    packed = load_surface(_glb(tmp_path, "draco.glb", draco=True))
    assert len(packed.geometries) == len(plain.geometries) == 2  # the cow stored once
    assert [i.name for i in packed.instances] == [i.name for i in plain.instances]
    assert sorted((i.name, packed.geometries[i.geometry].faces.shape) for i in packed.instances) == [
        ("node0", (5856, 3)), ("node1", (5856, 3)), ("node2", (320, 3))]
    for a, b in zip(packed.instances, plain.instances):
        assert (a.matrix is None) == (b.matrix is None)
        if a.matrix is not None:
            np.testing.assert_allclose(a.matrix, b.matrix, atol=1e-12)
    for g, h in zip(packed.geometries, plain.geometries):
        np.testing.assert_array_equal(g.faces, h.faces)
        step = np.ptp(h.vertices, axis=0).max() / (2**BITS - 1)
        err = np.abs(g.vertices - h.vertices).max()
        assert 0 < err <= step  # moved by quantisation, by no more than one step


def test_reordered_draco_mesh_has_the_same_triangles(tmp_path):
    # Draco's default reorders vertices and faces: the same triangles, in another order.
    plain = load_surface(_glb(tmp_path, "plain.glb", draco=False))
    packed = load_surface(_glb(tmp_path, "draco.glb", draco=True, preserve_order=False))
    from scipy.spatial import cKDTree

    for g, h in zip(packed.geometries, plain.geometries):
        step = np.ptp(h.vertices, axis=0).max() / (2**BITS - 1)
        a, b = g.vertices[g.faces], h.vertices[h.faces]  # (F, 3, 3) corners
        assert len(a) == len(b)
        dist, match = cKDTree(b.mean(axis=1)).query(a.mean(axis=1))
        assert dist.max() <= step and len(np.unique(match)) == len(b)  # one to one
        # every corner of a decoded triangle is a corner of its match, moved by quantisation
        gap = np.linalg.norm(a[:, :, None, :] - b[match][:, None, :, :], axis=-1).min(axis=2)
        assert gap.max() <= step


def test_draco_scene_samples_like_the_uncompressed_one(tmp_path):
    n = 30_000
    plain = scatter_cli.sample(_glb(tmp_path, "plain.glb", draco=False), n, seed=1, precision="float64")
    packed = scatter_cli.sample(_glb(tmp_path, "draco.glb", draco=True), n, seed=2, precision="float64")
    assert two_sample_p(packed.points, plain.points) > ALPHA


def test_must_fail_draco_scene_without_the_node_transform(tmp_path):
    n = 30_000
    plain = scatter_cli.sample(_glb(tmp_path, "plain.glb", draco=False), n, seed=1, precision="float64")
    wrong = scatter_cli.sample(_glb(tmp_path, "bad.glb", draco=True, transform=False), n, seed=2,
                               precision="float64")
    assert two_sample_p(wrong.points, plain.points) < ALPHA


def test_points_lie_on_the_decoded_faces(tmp_path):
    import DracoPy

    path = _glb(tmp_path, "draco.glb", draco=True, preserve_order=False)
    s = scatter_cli.sample(path, 5_000, seed=3, attributes=["face", "bary", "object"], precision="float64")
    # the decoded triangles straight from DracoPy, not through the loader under test
    doc, blob = _chunks(path.read_bytes())
    decoded = []
    for mesh in doc["meshes"]:
        ext = mesh["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]
        v = doc["bufferViews"][ext["bufferView"]]
        d = DracoPy.decode(blob[v["byteOffset"] : v["byteOffset"] + v["byteLength"]])
        decoded.append(np.asarray(d.points, dtype=np.float64)[np.asarray(d.faces).reshape(-1, 3)])
    stretch, lifted = _placements()
    where = {"node0": (0, stretch), "node1": (0, np.eye(4)), "node2": (1, lifted)}
    expect = np.empty_like(s.points)
    for k, inst in enumerate(load_surface(path).instances):
        mesh, m = where[inst.name]
        rows = s.object == k
        tri = decoded[mesh][s.face[rows]] @ m[:3, :3].T + m[:3, 3]  # (r, 3, 3) world corners
        expect[rows] = np.einsum("rc,rcx->rx", s.bary[rows], tri)
    assert np.bincount(s.object, minlength=3).min() > 0
    np.testing.assert_allclose(s.points, expect, atol=1e-9)


def _chunks(data):
    import json
    import struct

    size = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20 : 20 + size])
    return doc, data[20 + size + 8 :]


@pytest.mark.slow
def test_missing_dracopy_gives_one_line(tmp_path):
    path = _glb(tmp_path, "draco.glb", draco=True)
    fake = tmp_path / "nodraco"
    fake.mkdir()
    (fake / "DracoPy.py").write_text("raise ImportError(\"No module named 'DracoPy'\")\n")
    env = {"PYTHONPATH": os.pathsep.join([str(fake), os.environ.get("PYTHONPATH", "")])}
    out = tmp_path / "out.ply"
    proc = run_scatter("sample", path, "-n", "100", "-o", out, env=env)
    err = proc.stderr.decode().strip().splitlines()
    assert proc.returncode == 1 and not out.exists()
    assert len(err) == 1 and err[0].startswith(f"error: {path}:")
    assert "pip install DracoPy" in err[0]


def test_missing_dracopy_from_python(tmp_path, monkeypatch):
    path = _glb(tmp_path, "draco.glb", draco=True)
    monkeypatch.setitem(__import__("sys").modules, "DracoPy", None)  # `import DracoPy` raises ImportError
    with pytest.raises(ScatterError, match=r"pip install DracoPy"):
        load_surface(path)
    # an uncompressed glTF never asks for it
    assert load_surface(_glb(tmp_path, "plain.glb", draco=False)).face_count > 0


def test_trimesh_without_a_draco_handler_gives_one_line(tmp_path, monkeypatch):
    from trimesh.exchange.gltf import extensions

    path = _glb(tmp_path, "draco.glb", draco=True)
    handlers = dict(extensions._handlers["primitive_preprocess"])
    handlers.pop("KHR_draco_mesh_compression")
    monkeypatch.setitem(extensions._handlers, "primitive_preprocess", handlers)  # as an older trimesh
    with pytest.raises(ScatterError, match=r"trimesh 5.2 or later .*pip install DracoPy"):
        load_surface(path)
