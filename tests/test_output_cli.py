"""The new formats through the real command: suffixes, --ascii, --stats, errors."""

import json

import numpy as np
import pytest

from scatter_cli.errors import ScatterError

from .conftest import SAMPLES, run_scatter
from .test_cli import assert_one_line_error

MESH = SAMPLES / "boxvertexcolors.glb"


def test_pcd_ascii_and_las_stats(tmp_path):
    o3d = pytest.importorskip("open3d")
    laspy = pytest.importorskip("laspy")
    run_scatter("sample", MESH, "-n", 300, "-a", "color,normal", "--ascii", "-o", tmp_path / "a.pcd", check=True)
    run_scatter("sample", MESH, "-n", 300, "-a", "color,normal", "-o", tmp_path / "a.ply", check=True)
    cloud = o3d.io.read_point_cloud(str(tmp_path / "a.pcd"))
    ply = o3d.io.read_point_cloud(str(tmp_path / "a.ply"))
    np.testing.assert_array_equal(np.asarray(cloud.points, np.float32), np.asarray(ply.points, np.float32))
    np.testing.assert_array_equal(np.asarray(cloud.colors), np.asarray(ply.colors))
    run_scatter("sample", MESH, "-n", 300, "-a", "color", "-o", tmp_path / "a.laz", "--stats", tmp_path / "s.json",
                check=True)
    report = json.loads((tmp_path / "s.json").read_text())["output"]["las"]
    las = laspy.read(tmp_path / "a.laz")
    xyz = np.stack([las.x, las.y, las.z], axis=1)
    assert np.abs(xyz - np.asarray(ply.points)).max() <= report["scale"][0] / 2 + 1e-7  # ply: float32
    assert las.header.point_count == 300


def test_usd_instancer_from_the_suffix(tmp_path):
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    run_scatter("sample", MESH, "-n", 50, "-a", "orient", "-o", tmp_path / "i.usda", check=True)
    stage = Usd.Stage.Open(str(tmp_path / "i.usda"))
    assert len(UsdGeom.PointInstancer(stage.GetPrimAtPath("/Scatter/Instancer")).GetPositionsAttr().Get()) == 50


def test_las_into_a_pipe_is_one_line_and_ascii_las_a_usage_error(tmp_path):
    proc = run_scatter("sample", MESH, "-n", 10, "-f", "las")
    assert_one_line_error(proc, 1, "needs a file")
    assert proc.stdout == b""
    assert_one_line_error(run_scatter("sample", MESH, "-n", 10, "--ascii", "-o", tmp_path / "x.las"), 2, "--ascii")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("suffix,ascii", [("pcd", False), ("pcd", True), ("las", False), ("laz", False)])
def test_merge_joins_shards_into_the_run(tmp_path, suffix, ascii):
    if suffix != "pcd":
        pytest.importorskip("laspy")
    from scatter_cli import api
    from scatter_cli.merge import merge
    from scatter_cli.writers import run_precision, write_samples

    def write(path, shard=None):
        run = api.prepare(str(MESH), 1001, attributes="normal,color,orient", chunk_size=97, shard=shard,
                          precision=run_precision(suffix, "auto"))
        write_samples(run.chunks(), str(path), suffix, run.layout, run.size, ascii, **api.output_options(run, suffix))

    write(tmp_path / f"whole.{suffix}")
    parts = [tmp_path / f"p{k}.{suffix}" for k in range(3)]
    for k, part in enumerate(parts):
        write(part, (k, 3))
    assert merge(parts, tmp_path / f"m.{suffix}") == 1001
    assert (tmp_path / f"m.{suffix}").read_bytes() == (tmp_path / f"whole.{suffix}").read_bytes()
    other = tmp_path / f"other.{suffix}"
    run = api.prepare(str(MESH), 10, precision=run_precision(suffix, "auto"))
    write_samples(run.chunks(), str(other), suffix, run.layout, run.size, ascii, **api.output_options(run, suffix))
    with pytest.raises(ScatterError, match="other"):
        merge([parts[0], other], tmp_path / f"n.{suffix}")
