"""``--normalize`` on surface runs: points written as (p - offset) * scale, where the offset
is the centre of the sampled surface's box and the scale makes its largest side 2
(unit-cube) or puts its farthest used vertex at distance 1 (unit-sphere); the frame is in
``--stats``. Each mesh carries a stray vertex far away that no face uses: a frame taken
from every vertex instead of the used ones fails these tests."""

import json

import numpy as np
import pytest
import trimesh

import scatter_cli

from .conftest import run_scatter

STRAY = [50.0, -80.0, 20.0]


def mesh_with_stray_vertex():
    """Two triangles (one tilted) and a vertex that no face references."""
    v = np.array([[0.0, 0, 0], [3, 0, 0], [0, 1, 0], [1, 2, 5], [2, 1, 4], [1, 1, 6], STRAY])
    return trimesh.Trimesh(v, [[0, 1, 2], [3, 4, 5]], process=False), v[:6]


def test_unit_cube_maps_the_used_box_to_minus_one_one_on_its_largest_side():
    mesh, used = mesh_with_stray_vertex()
    lo, hi = used.min(0), used.max(0)
    s = scatter_cli.sample(mesh, 5000, seed=3, precision="float64", normalize="unit-cube")
    frame = s.info["normalize"]
    np.testing.assert_allclose(frame["offset"], (lo + hi) / 2, rtol=0, atol=1e-15)
    assert frame["scale"] == pytest.approx(2 / (hi - lo).max(), rel=1e-15)
    box = (np.stack([lo, hi]) - frame["offset"]) * frame["scale"]
    assert (box[1] - box[0]).max() == pytest.approx(2, rel=1e-15)
    assert np.all(s.points >= -1 - 1e-12) and np.all(s.points <= 1 + 1e-12)
    # the same points as the plain run, moved into the frame
    plain = scatter_cli.sample(mesh, 5000, seed=3, precision="float64")
    np.testing.assert_allclose(s.points, (plain.points - frame["offset"]) * frame["scale"], rtol=0, atol=1e-14)


def test_unit_sphere_puts_the_farthest_used_vertex_at_distance_one():
    mesh, used = mesh_with_stray_vertex()
    s = scatter_cli.sample(mesh, 5000, seed=3, precision="float64", normalize="unit-sphere")
    frame = s.info["normalize"]
    distances = np.linalg.norm((used - frame["offset"]) * frame["scale"], axis=1)
    assert distances.max() == pytest.approx(1, rel=1e-15)
    assert np.linalg.norm(s.points, axis=1).max() <= 1 + 1e-12


def test_the_frame_follows_instances_in_world_space():
    box = trimesh.creation.box(extents=[1, 1, 1])
    scene = trimesh.Scene()
    scene.add_geometry(box, node_name="a")
    far = np.eye(4)
    far[:3, 3] = [10, 0, 0]
    scene.add_geometry(box, node_name="b", transform=far)
    s = scatter_cli.sample(scene, 2000, precision="float64", normalize="unit-cube")
    np.testing.assert_allclose(s.info["normalize"]["offset"], [5, 0, 0], atol=1e-12)
    assert s.info["normalize"]["scale"] == pytest.approx(2 / 11)


@pytest.mark.slow
def test_none_writes_world_space_and_a_bad_mode_is_a_usage_error(tmp_path):
    mesh, _ = mesh_with_stray_vertex()
    path = tmp_path / "m.ply"
    mesh.export(path)
    plain = run_scatter("sample", path, "-n", "50", "-f", "npy", check=True).stdout
    assert run_scatter("sample", path, "-n", "50", "-f", "npy", "--normalize", "none", check=True).stdout == plain
    proc = run_scatter("sample", path, "--normalize", "unit-ball")
    assert proc.returncode == 2 and proc.stderr.decode().startswith("error: unknown normalize 'unit-ball'")


@pytest.mark.slow
def test_the_command_writes_the_frame_to_stats(tmp_path):
    mesh, used = mesh_with_stray_vertex()
    path = tmp_path / "m.ply"
    mesh.export(path)
    proc = run_scatter("sample", path, "-n", "100", "--normalize", "unit-cube", "-o", tmp_path / "p.csv",
                       "--stats", tmp_path / "s.json", check=True)
    frame = json.loads((tmp_path / "s.json").read_text())["normalize"]
    assert frame["mode"] == "unit-cube" and frame["scale"] == pytest.approx(2 / 6)  # the used box: 3 x 2 x 6
    pts = np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1)
    assert np.abs(pts).max() <= 1 + 1e-6 and proc.returncode == 0
