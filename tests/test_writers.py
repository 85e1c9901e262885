"""Every output format reads back, through an independent reader, to the same values."""

import io

import numpy as np
import pytest

import scatter_cli

from .conftest import run_scatter

N = 2000


@pytest.fixture(scope="module")
def reference(request):
    from .conftest import SAMPLES

    return scatter_cli.sample(SAMPLES / "koala.obj", N, attributes=("face", "bary"), seed=4)


def command(sample_mesh, *extra):
    return ["sample", sample_mesh("koala.obj"), "-n", N, "-a", "bary,face", "--seed", 4, *extra]


def test_binary_ply_read_by_trimesh(sample_mesh, tmp_path, reference):
    import trimesh

    out = tmp_path / "p.ply"
    run_scatter(*command(sample_mesh, "-o", out), check=True)
    cloud = trimesh.load(out, process=False)
    np.testing.assert_array_equal(np.asarray(cloud.vertices, np.float32), reference.points)
    data = cloud.metadata["_ply_raw"]["vertex"]["data"]
    np.testing.assert_array_equal(data["face_index"], reference.face)
    np.testing.assert_array_equal(data["bary1"], reference.bary[:, 1])
    assert out.read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")


def test_ascii_ply_read_by_trimesh(sample_mesh, tmp_path, reference):
    import trimesh

    out = tmp_path / "a.ply"
    run_scatter(*command(sample_mesh, "-o", out, "--ascii"), check=True)
    assert b"format ascii 1.0" in out.read_bytes()[:100]
    cloud = trimesh.load(out, process=False)
    np.testing.assert_array_equal(np.asarray(cloud.vertices, np.float32), reference.points)


def test_binary_ply_read_by_pymeshlab(sample_mesh, tmp_path, reference):
    pymeshlab = pytest.importorskip("pymeshlab")
    out = tmp_path / "m.ply"
    run_scatter("sample", sample_mesh("koala.obj"), "-n", N, "--seed", 4, "-o", out, check=True)
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(out))
    got = ms.current_mesh().vertex_matrix()
    assert got.shape == (N, 3)
    np.testing.assert_array_equal(got.astype(np.float32), reference.points)


@pytest.mark.parametrize("fmt,sep,header", [("csv", ",", True), ("xyz", " ", False)])
def test_text_formats_read_by_numpy(sample_mesh, tmp_path, reference, fmt, sep, header):
    out = tmp_path / f"t.{fmt}"
    run_scatter(*command(sample_mesh, "-o", out), check=True)
    text = out.read_text()
    first = text.splitlines()[0]
    if header:
        assert first == "x,y,z,face_index,bary0,bary1,bary2"
    table = np.loadtxt(io.StringIO(text), delimiter=sep, skiprows=1 if header else 0, dtype=np.float64)
    np.testing.assert_array_equal(table[:, :3].astype(np.float32), reference.points)
    np.testing.assert_array_equal(table[:, 3].astype(np.int64), reference.face)
    np.testing.assert_array_equal(table[:, 4:].astype(np.float32), reference.bary)


def test_npy_structured_array(sample_mesh, tmp_path, reference):
    out = tmp_path / "n.npy"
    run_scatter(*command(sample_mesh, "-o", out), check=True)
    arr = np.load(out)
    assert arr.dtype.names == ("x", "y", "z", "face_index", "bary0", "bary1", "bary2")
    np.testing.assert_array_equal(np.stack([arr["x"], arr["y"], arr["z"]], 1), reference.points)
    np.testing.assert_array_equal(arr["face_index"], reference.face)


def test_float64_text_round_trips_exactly(sample_mesh, tmp_path):
    out = tmp_path / "d.csv"
    run_scatter("sample", sample_mesh("koala.obj"), "-n", 500, "--precision", "float64", "-o", out, check=True)
    ref = scatter_cli.sample(sample_mesh("koala.obj"), 500, precision="float64").points
    assert ref.dtype == np.float64
    np.testing.assert_array_equal(np.loadtxt(out, delimiter=",", skiprows=1), ref)


def test_standard_output_is_csv(sample_mesh, reference):
    proc = run_scatter(*command(sample_mesh), check=True)
    lines = proc.stdout.decode().splitlines()
    assert lines[0].startswith("x,y,z,")
    assert len(lines) == N + 1
    np.testing.assert_array_equal(np.loadtxt(lines[1:], delimiter=",")[:, :3].astype(np.float32), reference.points)


def test_standard_output_binary_formats(sample_mesh, reference):
    proc = run_scatter(*command(sample_mesh, "-f", "npy"), check=True)
    arr = np.load(io.BytesIO(proc.stdout))
    np.testing.assert_array_equal(arr["x"], reference.points[:, 0])


# -- the format table ------------------------------------------------------------------

def test_every_format_module_provides_what_its_row_says():
    from scatter_cli.writers import formats

    for spec in formats.TABLE:
        module = formats.load(spec.name)
        assert callable(module.make), spec.name
        assert hasattr(module, "file_size") or not spec.sized, spec.name
        assert callable(module.read), spec.name  # its reader: merge's and preview's
        for suffix in spec.suffixes:
            assert formats.infer_format(f"a.{suffix.upper()}") == spec.name


def test_precision_ascii_and_crs_rules_come_from_the_table():
    from scatter_cli.errors import ScatterUsageError
    from scatter_cli.writers import formats

    for spec in formats.TABLE:
        assert formats.run_precision(spec.name, "float32") == ("float64" if spec.float64 else "float32")
        for ascii, crs, allowed in [(True, None, spec.ascii), (False, "EPSG:4326", spec.crs)]:
            if allowed:
                formats.check_output(spec.name, ascii, crs)
            else:
                with pytest.raises(ScatterUsageError):
                    formats.check_output(spec.name, ascii, crs)
    assert formats.ASCII_FORMATS == ("ply", "pcd") and formats.CRS_FORMATS == ("las", "laz")


@pytest.mark.parametrize("argv", [["--help"], ["sample", "--help"], ["merge", "--help"]])
def test_help_and_the_table_import_no_numpy(argv):
    import subprocess
    import sys

    from .conftest import run_user

    proc = run_user([sys.executable, "-X", "importtime", "-m", "scatter_cli", *argv])
    assert proc.returncode == 0
    imported = {line.rsplit("|", 1)[-1].strip() for line in proc.stderr.decode().splitlines()}
    assert "scatter_cli.writers.formats" in imported and "numpy" not in imported
    code = "import sys, scatter_cli.writers, scatter_cli.commands.merge; print('numpy' in sys.modules)"
    proc = run_user([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    assert proc.stdout.strip() == b"False"
