"""Labels of the stored points: with float32 coordinates, a volume run labels the float32
points it writes (CLI.md, "Volume samples"), so that every row a reader gets is
consistent: its ``sdf`` is the exact signed distance of its own ``x y z``, its ``inside``
and ``winding`` are those of that point, and its ``face_index`` names a face at that
distance. Checked against brute force built apart from the kernels
(tests/volume_reference.py), in world space and in a normalized frame."""

import numpy as np
import pytest
import trimesh

import scatter_cli.api as api
from scatter_cli.loading.load import load_surface
from scatter_cli.run.bounds import in_frame
from scatter_cli.run.options import SampleOptions
from scatter_cli.sampling.plan import SamplePlan
from scatter_cli.volume.source import VolumeLabels, world_triangles
from tests.volume_reference import exact_distance, solid_angle_winding, triangle_distance

# A near sigma of a few float32 steps puts points where rounding them can change sides.
OPTIONS = dict(count=200, near=(0.01, 5e-7), box_share=0.2, attributes=("sdf", "inside", "winding", "face"),
               precision="float32", seed=3)


def closed_mesh():
    """A sphere of 320 faces away from the origin: its exact winding number is 0 or 1."""
    return trimesh.creation.icosphere(subdivisions=2).apply_translation([2.5, -1.5, 0.75])


def written_rows(tmp_path, normalize):
    """(the rows ``scatter sample`` writes to NPY, float32; the run's triangles (T, 3, 3)
    in the frame of the points)."""
    mesh = closed_mesh()
    run = api.sample_to(mesh, SampleOptions(normalize=normalize, **OPTIONS), tmp_path / "v.npy")
    triangles, _, _ = world_triangles(SamplePlan(load_surface(mesh)))
    return np.load(tmp_path / "v.npy"), in_frame(triangles, run.frame)


def check_rows(rows, triangles):
    """Each row's labels are those of its stored point: sdf its exact distance within
    float64 rounding (1e-12 of the diagonal), the sign and ``inside`` those of its exact
    winding number, ``winding`` within the approximation's error of it, and its face at
    that distance."""
    assert rows["x"].dtype == np.float32
    stored = np.stack([rows[c] for c in "xyz"], axis=1).astype(np.float64)
    corners = triangles.reshape(-1, 3)
    diag = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
    distance, _ = exact_distance(triangles, stored)
    winding = solid_angle_winding(triangles, stored)
    assert np.abs(np.abs(rows["sdf"]) - distance).max() <= 1e-12 * diag
    assert (rows["inside"] == (winding >= 0.5)).all()
    assert ((rows["sdf"] < 0) == (winding >= 0.5)).all()
    assert np.abs(rows["winding"] - winding).max() < 0.05
    named = triangle_distance(stored, triangles[rows["face_index"]])
    assert np.abs(named - distance).max() <= 1e-12 * diag


@pytest.mark.parametrize("normalize", ["none", "unit-sphere"])
def test_the_labels_are_those_of_the_float32_points_written(tmp_path, normalize):
    rows, triangles = written_rows(tmp_path, normalize)
    assert np.abs(rows["sdf"]).min() < 1e-6  # points within a few float32 steps of the surface
    check_rows(rows, triangles)


@pytest.mark.parametrize("normalize", ["none", "unit-sphere"])
def test_labels_of_the_unrounded_points_fail_that_check(tmp_path, monkeypatch, normalize):
    monkeypatch.setattr(VolumeLabels, "stored_points", lambda self, points, real_dtype: points)  # as before
    rows, triangles = written_rows(tmp_path, normalize)
    with pytest.raises(AssertionError):
        check_rows(rows, triangles)
