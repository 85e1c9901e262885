"""The new formats through the real command: suffixes, --ascii, --stats, errors."""

import json

import numpy as np
import pytest

from scatter_cli.errors import ScatterError

from .conftest import SAMPLES, run_scatter
from .test_cli import assert_one_line_error
from .test_pcd import read_pcd

MESH = SAMPLES / "boxvertexcolors.glb"


@pytest.mark.slow
def test_pcd_ascii_and_las_stats(tmp_path):
    pytest.importorskip("pypcd4")
    laspy = pytest.importorskip("laspy")
    import trimesh

    run_scatter("sample", MESH, "-n", 300, "-a", "color,normal", "--ascii", "-o", tmp_path / "a.pcd", check=True)
    run_scatter("sample", MESH, "-n", 300, "-a", "color,normal", "-o", tmp_path / "a.ply", check=True)
    pcd = read_pcd(tmp_path / "a.pcd")
    ply = trimesh.load(tmp_path / "a.ply")
    xyz = np.stack([pcd["x"], pcd["y"], pcd["z"]], axis=1)
    np.testing.assert_array_equal(xyz, np.asarray(ply.vertices, np.float32))
    np.testing.assert_array_equal(np.stack([pcd[c] for c in ("red", "green", "blue", "alpha")], axis=1), ply.colors)
    run_scatter("sample", MESH, "-n", 300, "-a", "color", "-o", tmp_path / "a.laz", "--stats", tmp_path / "s.json",
                check=True)
    report = json.loads((tmp_path / "s.json").read_text())["output"]["las"]
    las = laspy.read(tmp_path / "a.laz")
    xyz = np.stack([las.x, las.y, las.z], axis=1)
    assert np.abs(xyz - np.asarray(ply.vertices)).max() <= report["scale"][0] / 2 + 1e-7  # ply: float32
    assert las.header.point_count == 300


@pytest.mark.slow
def test_usd_instancer_from_the_suffix(tmp_path):
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    run_scatter("sample", MESH, "-n", 50, "-a", "orient", "-o", tmp_path / "i.usda", check=True)
    stage = Usd.Stage.Open(str(tmp_path / "i.usda"))
    assert len(UsdGeom.PointInstancer(stage.GetPrimAtPath("/Scatter/Instancer")).GetPositionsAttr().Get()) == 50


@pytest.mark.slow
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
    from scatter_cli.commands.merge import merge
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


# -- the room on the output's file system (sizes known beforehand) ----------------------



@pytest.mark.parametrize("attributes", ["", "normal,color,face"])
@pytest.mark.parametrize("fmt,crs", [("ply", None), ("npy", None), ("pcd", None), ("las", None), ("las", "EPSG:2056")])
def test_the_size_known_beforehand_is_the_size_written(tmp_path, fmt, crs, attributes):
    from scatter_cli import api
    from scatter_cli.writers import file_size, run_precision, write_samples

    if fmt == "las":
        pytest.importorskip("laspy")
    options = {}
    if crs:
        from scatter_cli.writers.crs import crs_wkt

        pytest.importorskip("pyproj")
        options = {"wkt": crs_wkt(crs)}
    run = api.prepare(str(MESH), 1234, attributes=attributes, precision=run_precision(fmt, "auto"))
    out = tmp_path / f"p.{fmt}"
    write_samples(run.chunks(), out, fmt, run.layout, run.size, crs=crs, **api.output_options(run, fmt))
    assert file_size(fmt, run.layout, run.size, **options, **api.output_options(run, fmt)) == out.stat().st_size


@pytest.mark.parametrize("fmt,ascii", [("csv", False), ("xyz", False), ("ply", True), ("pcd", True), ("laz", False),
                                       ("usd", False)])
def test_text_compressed_and_in_memory_sizes_are_not_known(fmt, ascii):
    from scatter_cli.run.columns import column_layout
    from scatter_cli.writers import file_size

    assert file_size(fmt, column_layout({}, np.dtype("<f4")), 10, ascii, bounds=np.eye(2, 3)) is None


def test_room_is_checked_to_the_byte(tmp_path, monkeypatch):
    import os

    from scatter_cli.writers import open_output

    class Fs:
        f_blocks, f_bavail, f_frsize = 5000, 1000, 4096

    monkeypatch.setattr(os, "statvfs", lambda path: Fs)
    with open_output(tmp_path / "fits.ply", 4_096_000):  # exactly the room left
        pass
    with pytest.raises(ScatterError, match=r"needs 4.1 MB \(4,096,001 bytes\), its file system has 4.1 MB "
                                           r"\(4,096,000 bytes\) free"):
        with open_output(tmp_path / "over.ply", 4_096_001):
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fits.ply"]
    with open_output(os.devnull, 10**20):  # a device: not checked
        pass


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["ply", "npy", "pcd", "las"])
def test_a_count_that_cannot_fit_is_refused_before_any_work(tmp_path, fmt):
    if fmt == "las":
        pytest.importorskip("laspy")
    proc = run_scatter("sample", MESH, "-n", 10**15, "-o", tmp_path / f"big.{fmt}", timeout=60)
    assert_one_line_error(proc, 1, f"big.{fmt}: the output needs")
    assert " PB (" in proc.stderr.decode() and "free" in proc.stderr.decode()
    assert not list(tmp_path.iterdir())


# -- merge: directories, and only the formats it joins ----------------------------------

@pytest.mark.slow
def test_merge_of_a_directory_says_it_is_one(tmp_path):
    part = tmp_path / "a.ply"
    run_scatter("sample", MESH, "-n", 10, "-o", part, check=True)
    (tmp_path / "parts").mkdir()
    assert_one_line_error(run_scatter("merge", tmp_path / "parts", "-o", tmp_path / "m.ply"), 1, "is a directory")
    assert_one_line_error(run_scatter("merge", part, "-o", tmp_path / "parts"), 1, "is a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.ply", "parts"]


@pytest.mark.slow
def test_merge_offers_only_the_formats_it_joins(tmp_path):
    from scatter_cli.writers import MERGEABLE

    assert "usd" not in MERGEABLE and {"ply", "las", "laz"} <= set(MERGEABLE)
    proc = run_scatter("merge", tmp_path / "a.bin", "-o", tmp_path / "m.bin")
    assert_one_line_error(proc, 2, f"pass -f {'|'.join(MERGEABLE)}")
    proc = run_scatter("merge", tmp_path / "a.usd", tmp_path / "b.usd", "-o", tmp_path / "m.usd")
    assert_one_line_error(proc, 2, f"merge cannot join USD files (it joins: {', '.join(MERGEABLE)})")
    assert_one_line_error(run_scatter("merge", tmp_path / "a.ply", "-f", "usd", "-o", tmp_path / "m.ply"), 2,
                          "merge cannot join USD")


# -- --crs through the command ----------------------------------------------------------

@pytest.mark.slow
def test_crs_through_sample_and_batch(tmp_path):
    laspy = pytest.importorskip("laspy")
    pyproj = pytest.importorskip("pyproj")
    run_scatter("sample", MESH, "-n", 100, "--crs", "EPSG:2056", "-o", tmp_path / "s.laz", check=True)
    run_scatter("batch", MESH, "-n", 100, "--crs", "EPSG:2056", "-o", tmp_path / "b" / "{stem}.laz", "-q",
                check=True)
    assert (tmp_path / "s.laz").read_bytes() == (tmp_path / "b" / "boxvertexcolors.laz").read_bytes()
    assert laspy.read(tmp_path / "s.laz").header.parse_crs() == pyproj.CRS.from_epsg(2056)


@pytest.mark.slow
@pytest.mark.parametrize("command", ["sample", "batch"])
def test_crs_elsewhere_or_malformed_is_a_usage_error(tmp_path, command):
    pytest.importorskip("pyproj")
    out = tmp_path / ("{stem}" if command == "batch" else "p")
    assert_one_line_error(run_scatter(command, MESH, "-n", 10, "--crs", "EPSG:2056", "-o", f"{out}.ply"), 2,
                          "--crs applies to LAS/LAZ output only")
    assert_one_line_error(run_scatter(command, MESH, "-n", 10, "--crs", "UTM 32N", "-o", f"{out}.las"), 2,
                          "--crs 'UTM 32N': neither EPSG:N nor WKT")
    assert not list(tmp_path.iterdir())
