"""LAS / LAZ output read back by laspy: coordinates within the stated quantisation,
colours, Extra Bytes, header bounds and counts; a georeferenced terrain to 0.1 mm."""

import io
import shutil

import numpy as np
import pytest

import scatter_cli.api as api
import scatter_cli.writers.las as las_module
from scatter_cli.api import sampled_bounds
from scatter_cli.errors import ScatterError
from scatter_cli.sampling.plan import chunk_ranges
from scatter_cli.writers import run_precision, write_samples

from .conftest import SAMPLES

laspy = pytest.importorskip("laspy")


def write(path, mesh=SAMPLES / "boxvertexcolors.glb", n=3000, attributes="normal,color,face,orient", span=None,
          crs=None, **kw):
    fmt = str(path).rsplit(".", 1)[1]
    run = api.prepare(mesh, n, attributes=attributes, seed=6, precision=run_precision(fmt, "auto"), **kw)
    a, b = span or (0, run.count)
    chunks = (run._job(a + i, a + j) for i, j in chunk_ranges(b - a, 1000))
    report = write_samples(chunks, path, fmt, run.layout, b - a, bounds=sampled_bounds(run.plan), crs=crs)
    return run.collect(), report


def terrain():
    """A 2 km x 1.5 km height field placed at UTM-like coordinates (~3e5 m east, ~1e5 m north)."""
    import trimesh

    x, y = np.meshgrid(np.linspace(0, 2000, 21), np.linspace(0, 1500, 16))
    z = 300 + 40 * np.sin(x / 300) * np.cos(y / 200)
    v = np.stack([x.ravel() + 345_678.25, y.ravel() + 123_456.5, z.ravel()], axis=1)
    i = np.arange(21 * 16).reshape(16, 21)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return trimesh.Trimesh(v, faces, process=False)


@pytest.mark.parametrize("block", [None, 700])
@pytest.mark.parametrize("suffix", ["las", "laz"])
def test_laspy_reads_coordinates_colours_and_extra_bytes(tmp_path, monkeypatch, suffix, block):
    # block 700: chunks of 1000 points cut into blocks of 700 and 300 (records, extremes)
    if block:
        monkeypatch.setattr(las_module, "BLOCK", block)
    s, report = write(tmp_path / f"t.{suffix}")
    las = laspy.read(tmp_path / f"t.{suffix}")
    q = report["las"]
    xyz = np.stack([las.x, las.y, las.z], axis=1)
    assert np.abs(xyz - s.points).max() <= q["scale"][0] / 2 * (1 + 1e-9)
    stored = np.stack([las.X, las.Y, las.Z], axis=1)
    np.testing.assert_array_equal(stored, np.rint((s.points - q["offset"]) / q["scale"][0]))
    assert q["max_error_of_diagonal"] <= 1e-6 and q["scale"][0] <= 1e-4
    assert las.header.point_format.id == 7 and las.header.point_count == len(s)
    np.testing.assert_array_equal(np.stack([las.red, las.green, las.blue], 1), s.color[:, :3].astype(np.uint16) * 257)
    np.testing.assert_array_equal(las.alpha, s.color[:, 3])
    np.testing.assert_array_equal(las.face_index, s.face)
    np.testing.assert_array_equal(np.stack([las.nx, las.ny, las.nz], 1), s.normal.astype(np.float32))
    np.testing.assert_array_equal(las.qw, s.orient[:, 3].astype(np.float32))
    assert list(las.point_format.extra_dimension_names) == ["nx", "ny", "nz", "qx", "qy", "qz", "qw",
                                                            "face_index", "alpha"]
    np.testing.assert_array_equal(las.header.mins, xyz.min(axis=0))
    np.testing.assert_array_equal(las.header.maxs, xyz.max(axis=0))
    assert las.header.point_format.size == 36 + 4 * 8 + 1
    assert list(las.header.number_of_points_by_return[:2]) == [len(s), 0]


def test_format_6_without_colour(tmp_path):
    s, _ = write(tmp_path / "t.las", attributes="")
    las = laspy.read(tmp_path / "t.las")
    assert las.header.point_format.id == 6 and las.header.point_format.size == 30
    assert las.header.version.minor == 4


def test_terrain_coordinates_within_a_tenth_of_a_millimetre(tmp_path):
    s, report = write(tmp_path / "terrain.las", mesh=terrain(), n=5000, attributes="")
    assert s.points.dtype == np.float64
    las = laspy.read(tmp_path / "terrain.las")
    error = np.abs(np.stack([las.x, las.y, las.z], axis=1) - s.points).max()
    assert error < 1e-4
    # the test can tell: float32 coordinates of the same points are off by more than that
    assert np.abs(s.points.astype(np.float32) - s.points).max() > 1e-4


@pytest.mark.parametrize("block", [None, 256])
@pytest.mark.parametrize("suffix", ["las", "laz"])
def test_same_bytes_for_any_chunk_size(tmp_path, monkeypatch, suffix, block):
    # the writer reuses its record array: chunks that shrink and grow must not leave
    # anything of the one before; block 256: chunks cut into several blocks and a tail
    if block:
        monkeypatch.setattr(las_module, "BLOCK", block)
    run = api.prepare(SAMPLES / "boxvertexcolors.glb", 2000, attributes="color,normal,face", seed=1,
                      precision="float64")
    for k, cuts in enumerate(([0, 2000], [0, 333, 340, 1100, 1101, 2000])):
        chunks = (run._job(a, b) for a, b in zip(cuts, cuts[1:]))
        write_samples(chunks, tmp_path / f"{k}.{suffix}", suffix, run.layout, run.count,
                      bounds=sampled_bounds(run.plan))
    assert (tmp_path / f"0.{suffix}").read_bytes() == (tmp_path / f"1.{suffix}").read_bytes()


@pytest.mark.parametrize("suffix", ["las", "laz"])
def test_shards_merge_to_the_run(tmp_path, suffix):
    from scatter_cli.commands.merge import merge

    write(tmp_path / f"whole.{suffix}")
    write(tmp_path / f"a.{suffix}", span=(0, 1234))
    write(tmp_path / f"b.{suffix}", span=(1234, 3000))
    merge([tmp_path / f"a.{suffix}", tmp_path / f"b.{suffix}"], tmp_path / f"m.{suffix}")
    assert (tmp_path / f"m.{suffix}").read_bytes() == (tmp_path / f"whole.{suffix}").read_bytes()


@pytest.mark.parametrize("m", [1, 255, 256, 257, 1000, 2048])
def test_column_extremes(m):
    q = np.random.default_rng(m).integers(-2**31 + 2, 2**31 - 2, 3 * m).astype(np.int32)
    lo, hi = las_module.column_extremes(q)
    np.testing.assert_array_equal(lo, q.reshape(-1, 3).min(axis=0))
    np.testing.assert_array_equal(hi, q.reshape(-1, 3).max(axis=0))


def failing_write(path):
    """Write a LAS file whose third chunk fails to be made; returns the writer threads left running."""
    import threading

    run = api.prepare(SAMPLES / "boxvertexcolors.glb", 3000, seed=1, precision="float64")

    def chunks():
        yield run._job(0, 1000)
        yield run._job(1000, 2000)
        raise RuntimeError("sampling failed")

    with pytest.raises(RuntimeError, match="sampling failed"):
        write_samples(chunks(), path, "las", run.layout, run.count, bounds=sampled_bounds(run.plan))
    return [t for t in threading.enumerate() if t.name.startswith("las-write")]


def test_a_failed_write_stops_the_writer_thread_and_leaves_no_file(tmp_path, monkeypatch):
    assert failing_write(tmp_path / "t.las") == []
    assert not list(tmp_path.iterdir())
    # the check can tell: a writer that does not stop its thread leaves it running
    from scatter_cli.writers.las import LasWriter

    monkeypatch.setattr(LasWriter, "close", lambda self: None)
    assert failing_write(tmp_path / "u.las")


def test_standard_output_is_refused():
    run = api.prepare(SAMPLES / "boxvertexcolors.glb", 10, precision="float64")
    stream = io.BytesIO()
    stream.seekable = lambda: False
    from scatter_cli.writers.las import LasWriter

    writer = LasWriter(stream, run.layout, 10, sampled_bounds(run.plan))
    with pytest.raises(ScatterError, match="needs a file"):
        writer.header()


def test_without_laspy_one_line_saying_what_to_install(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "laspy", None)
    with pytest.raises(ScatterError, match=r"needs laspy and lazrs: pip install laspy lazrs pyproj$"):
        write(tmp_path / "t.las", n=10)
    assert not list(tmp_path.iterdir())


@pytest.mark.skipif(shutil.which("pdal") is None,
                    reason="pdal not installed (Debian 12 does not package it, PyPI has no wheel)")
@pytest.mark.parametrize("suffix", ["las", "laz"])
def test_pdal_info_accepts_the_file(tmp_path, suffix):
    write(tmp_path / f"t.{suffix}")
    from .conftest import run_user

    assert run_user(["pdal", "info", str(tmp_path / f"t.{suffix}")]).returncode == 0


# -- coordinate system (--crs) ---------------------------------------------------------

GLOBAL_ENCODING_AT, WKT_BIT = 6, 1 << 4  # header bytes 6-7: global encoding; bit 4: WKT


def crs_records(header):
    return [(v.user_id, v.record_id) for v in header.vlrs if v.user_id == "LASF_Projection"]


@pytest.mark.parametrize("suffix", ["las", "laz"])
@pytest.mark.parametrize("attributes", ["", "normal,color"])
def test_every_file_has_the_wkt_bit_and_no_crs_record_without_crs(tmp_path, suffix, attributes):
    write(tmp_path / f"t.{suffix}", attributes=attributes)
    raw = (tmp_path / f"t.{suffix}").read_bytes()
    assert int.from_bytes(raw[GLOBAL_ENCODING_AT:GLOBAL_ENCODING_AT + 2], "little") & WKT_BIT
    header = laspy.read(tmp_path / f"t.{suffix}").header
    assert header.point_format.id in (6, 7) and crs_records(header) == [] and header.parse_crs() is None


@pytest.mark.parametrize("suffix", ["las", "laz"])
def test_an_epsg_code_is_one_wkt_record_read_back_by_laspy(tmp_path, suffix):
    pyproj = pytest.importorskip("pyproj")
    write(tmp_path / f"t.{suffix}", crs="EPSG:2056")
    header = laspy.read(tmp_path / f"t.{suffix}").header
    assert crs_records(header) == [("LASF_Projection", 2112)]  # WKT, no GeoTIFF keys
    assert header.global_encoding.wkt
    assert header.parse_crs() == pyproj.CRS.from_epsg(2056)


def test_a_wkt_is_recorded_as_given(tmp_path):
    pyproj = pytest.importorskip("pyproj")
    wkt = pyproj.CRS.from_epsg(32632).to_wkt()  # WKT2, as a user may have it
    write(tmp_path / "t.las", crs=wkt)
    header = laspy.read(tmp_path / "t.las").header
    assert [v.string for v in header.vlrs if v.record_id == 2112] == [wkt]
    assert header.parse_crs().to_epsg() == 32632


@pytest.mark.parametrize("value", ["EPSG:0", "EPSG:", "UTM 32N", "GEOGCS[oops"])
def test_a_crs_that_is_neither_epsg_nor_wkt_is_a_usage_error(tmp_path, value):
    from scatter_cli.errors import ScatterUsageError

    pytest.importorskip("pyproj")
    with pytest.raises(ScatterUsageError, match="--crs"):
        write(tmp_path / "t.las", crs=value)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("suffix", ["las", "laz"])
def test_merge_keeps_the_crs_and_refuses_another(tmp_path, suffix):
    pytest.importorskip("pyproj")
    from scatter_cli.commands.merge import merge

    write(tmp_path / f"whole.{suffix}", crs="EPSG:2056")
    write(tmp_path / f"a.{suffix}", span=(0, 1234), crs="EPSG:2056")
    write(tmp_path / f"b.{suffix}", span=(1234, 3000), crs="EPSG:2056")
    merge([tmp_path / f"a.{suffix}", tmp_path / f"b.{suffix}"], tmp_path / f"m.{suffix}")
    assert (tmp_path / f"m.{suffix}").read_bytes() == (tmp_path / f"whole.{suffix}").read_bytes()
    write(tmp_path / f"c.{suffix}", span=(1234, 3000), crs="EPSG:2193")
    with pytest.raises(ScatterError, match=f"c.{suffix}: columns or types differ"):
        merge([tmp_path / f"a.{suffix}", tmp_path / f"c.{suffix}"], tmp_path / f"n.{suffix}")
