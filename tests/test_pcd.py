"""PCD output read back by an independent reader (pypcd4, which follows PCL's format
specification), and PCD parts merged into the run's bytes."""

import numpy as np
import pytest

import scatter_cli.api as api
from scatter_cli.commands.merge import merge
from scatter_cli.writers.pcd import pack_rgb
from scatter_cli.writers import write_samples

from .conftest import SAMPLES


def read_pcd(path):
    """field -> (n,) column, as pypcd4 reads ``path``; PCL's packed ``rgb`` (a float32 or
    uint32 field) as four (n,) uint8 columns red, green, blue, alpha."""
    from pypcd4 import PointCloud

    data = PointCloud.from_path(path).pc_data
    columns = {name: data[name] for name in data.dtype.names}
    if "rgb" in columns:
        packed = np.ascontiguousarray(columns.pop("rgb")).view(np.uint32)
        for name, shift in (("red", 16), ("green", 8), ("blue", 0), ("alpha", 24)):
            columns[name] = ((packed >> shift) & 255).astype(np.uint8)
    return columns


def write(tmp_path, ascii, precision="float32", n=600, attributes="normal,color,face,orient", name="t.pcd", **kw):
    run = api.prepare(SAMPLES / "boxvertexcolors.glb", n, attributes=attributes, seed=3, precision=precision, **kw)
    out = tmp_path / name
    write_samples(run.chunks(), out, "pcd", run.layout, run.count, ascii)
    return out, run.collect()


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("ascii", [False, True])
def test_a_pcd_reader_reads_every_field(tmp_path, ascii, precision):
    pytest.importorskip("pypcd4")
    out, s = write(tmp_path, ascii, precision=precision)
    got = read_pcd(out)
    assert got["x"].dtype == s.points.dtype
    np.testing.assert_array_equal(np.stack([got["x"], got["y"], got["z"]], axis=1), s.points)
    np.testing.assert_array_equal(np.stack([got[f"normal_{a}"] for a in "xyz"], axis=1), s.normal)
    np.testing.assert_array_equal(np.stack([got[c] for c in ("red", "green", "blue", "alpha")], axis=1), s.color)
    np.testing.assert_array_equal(got["face_index"], s.face)
    np.testing.assert_array_equal(np.stack([got[q] for q in ("qx", "qy", "qz", "qw")], axis=1), s.orient)
    assert len(np.unique(s.color[:, :3], axis=0)) > 1  # the colours tell points apart


def test_header_names_fields_as_pcl_does(tmp_path):
    out, s = write(tmp_path, False)
    head = out.read_bytes().split(b"DATA binary\n")[0].decode()
    assert "FIELDS x y z normal_x normal_y normal_z qx qy qz qw face_index rgb\n" in head
    assert "TYPE F F F F F F F F F F I F\n" in head and "POINTS 600\n" in head
    rec = np.frombuffer(out.read_bytes()[len(head) + len("DATA binary\n"):], dtype=np.uint32).reshape(600, 12)
    np.testing.assert_array_equal(rec[:, 11], pack_rgb(s.color))
    assert pack_rgb(np.array([[1, 2, 3, 4]], np.uint8))[0] == 0x04010203


@pytest.mark.parametrize("ascii", [False, True])
def test_shards_merge_to_the_run(tmp_path, ascii):
    whole, _ = write(tmp_path, ascii, n=1000, name="whole.pcd")
    parts = []
    for k, (a, b) in enumerate([(0, 333), (333, 1000)]):
        run = api.prepare(SAMPLES / "boxvertexcolors.glb", 1000, attributes="normal,color,face,orient", seed=3,
                          precision="float32")
        parts.append(tmp_path / f"p{k}.pcd")
        chunks = (c for c in _range(run, a, b))
        write_samples(chunks, parts[-1], "pcd", run.layout, b - a, ascii)
    merge(parts, tmp_path / "m.pcd")
    assert (tmp_path / "m.pcd").read_bytes() == whole.read_bytes()


def _range(run, a, b):
    from scatter_cli.sampling.plan import chunk_ranges

    for i, j in chunk_ranges(b - a, 128):
        yield run._job(a + i, a + j)


def test_merge_refuses_a_different_layout(tmp_path):
    from scatter_cli.errors import ScatterError

    a, _ = write(tmp_path, False, n=50, name="a.pcd")
    b, _ = write(tmp_path, False, n=50, attributes="normal", name="b.pcd")
    with pytest.raises(ScatterError, match="b.pcd"):
        merge([a, b], tmp_path / "m.pcd")
    assert not (tmp_path / "m.pcd").exists()


@pytest.mark.slow
@pytest.mark.parametrize("ascii", [False, True])
def test_open3d_reads_what_the_docs_say(tmp_path, ascii):
    """docs/outputs.md's promises to Open3D users: its legacy reader takes float32 points,
    normals and colours (TYPE U rgb in ASCII included), its tensor reader float64 and the
    other fields. Open3D is a benchmark peer, not a test extra (its install costs CI over a
    minute): this runs where it is installed, and skips elsewhere."""
    o3d = pytest.importorskip("open3d", exc_type=ImportError)  # (also where its libusb is missing)
    out, s = write(tmp_path, ascii)
    cloud = o3d.io.read_point_cloud(str(out))
    np.testing.assert_array_equal(np.asarray(cloud.points).astype(np.float32), s.points)
    np.testing.assert_array_equal(np.asarray(cloud.normals).astype(np.float32), s.normal)
    np.testing.assert_array_equal(np.rint(np.asarray(cloud.colors) * 255), s.color[:, :3])
    out, s = write(tmp_path, ascii, precision="float64", name="t64.pcd")
    cloud = o3d.t.io.read_point_cloud(str(out)).point
    np.testing.assert_array_equal(cloud.positions.numpy(), s.points)
    np.testing.assert_array_equal(cloud.face_index.numpy()[:, 0], s.face)
    np.testing.assert_array_equal(cloud.qw.numpy()[:, 0], s.orient[:, 3])
