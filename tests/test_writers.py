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


@pytest.mark.slow
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


@pytest.mark.slow
def test_ascii_ply_read_by_trimesh(sample_mesh, tmp_path, reference):
    import trimesh

    out = tmp_path / "a.ply"
    run_scatter(*command(sample_mesh, "-o", out, "--ascii"), check=True)
    assert b"format ascii 1.0" in out.read_bytes()[:100]
    cloud = trimesh.load(out, process=False)
    np.testing.assert_array_equal(np.asarray(cloud.vertices, np.float32), reference.points)


@pytest.mark.slow
def test_binary_ply_read_by_pymeshlab(sample_mesh, tmp_path, reference):
    pymeshlab = pytest.importorskip("pymeshlab")
    out = tmp_path / "m.ply"
    run_scatter("sample", sample_mesh("koala.obj"), "-n", N, "--seed", 4, "-o", out, check=True)
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(out))
    got = ms.current_mesh().vertex_matrix()
    assert got.shape == (N, 3)
    np.testing.assert_array_equal(got.astype(np.float32), reference.points)


@pytest.mark.slow
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


@pytest.mark.slow
def test_npy_structured_array(sample_mesh, tmp_path, reference):
    out = tmp_path / "n.npy"
    run_scatter(*command(sample_mesh, "-o", out), check=True)
    arr = np.load(out)
    assert arr.dtype.names == ("x", "y", "z", "face_index", "bary0", "bary1", "bary2")
    np.testing.assert_array_equal(np.stack([arr["x"], arr["y"], arr["z"]], 1), reference.points)
    np.testing.assert_array_equal(arr["face_index"], reference.face)


@pytest.mark.slow
def test_float64_text_round_trips_exactly(sample_mesh, tmp_path):
    out = tmp_path / "d.csv"
    run_scatter("sample", sample_mesh("koala.obj"), "-n", 500, "--precision", "float64", "-o", out, check=True)
    ref = scatter_cli.sample(sample_mesh("koala.obj"), 500, precision="float64").points
    assert ref.dtype == np.float64
    np.testing.assert_array_equal(np.loadtxt(out, delimiter=",", skiprows=1), ref)


@pytest.mark.slow
def test_standard_output_is_csv(sample_mesh, reference):
    proc = run_scatter(*command(sample_mesh), check=True)
    lines = proc.stdout.decode().splitlines()
    assert lines[0].startswith("x,y,z,")
    assert len(lines) == N + 1
    np.testing.assert_array_equal(np.loadtxt(lines[1:], delimiter=",")[:, :3].astype(np.float32), reference.points)


@pytest.mark.slow
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


def make_keywords_the_row_does_not_say(spec, module):
    """The keywords of a format module's ``make`` beyond every writer's, against what its
    row says the writer takes: the run's facts (``takes``), the output's name (``named``)
    and the WKT of --crs (``crs``). Empty when they agree."""
    import inspect

    from scatter_cli import api

    common = {"fmt", "stream", "layout", "count", "ascii", "options"}
    made = set(inspect.signature(module.make).parameters) - common
    said = set(spec.takes) | {name for name, on in [("path", spec.named), ("wkt", spec.crs)] if on}
    return made ^ said | (set(spec.takes) - set(api.RUN_FACTS))


def test_each_row_says_what_its_writer_takes_from_the_run():
    from scatter_cli.writers import formats

    for spec in formats.TABLE:
        assert make_keywords_the_row_does_not_say(spec, formats.load(spec.name)) == set(), spec.name
    las, usd = formats.BY_NAME["las"], formats.BY_NAME["usd"]
    for broken in [las._replace(takes=()), las._replace(crs=False), usd._replace(named=False),
                   usd._replace(takes=usd.takes + ("colour",))]:
        assert make_keywords_the_row_does_not_say(broken, formats.load(broken.name)), broken


def checks_per_write(fmt, tmp_path, broken=None):
    """(checks of the output options, loads of the writer's module, conversions of --crs)
    in one ``api.sample_to`` writing ``fmt``; ``broken(monkeypatch)`` breaks the writing."""
    from scatter_cli import api, writers
    from scatter_cli.run.options import SampleOptions
    from scatter_cli.writers import crs, formats

    from .conftest import SAMPLES

    calls = {"check_output": [], "load": [], "crs_wkt": []}
    with pytest.MonkeyPatch.context() as monkeypatch:
        for module, name in [(writers, "check_output"), (formats, "check_output"), (writers, "load"),
                             (formats, "load"), (crs, "crs_wkt")]:
            real = getattr(module, name)
            monkeypatch.setattr(module, name, lambda *a, real=real, seen=calls[name], **k: seen.append(a) or real(*a, **k))
        if broken:
            broken(monkeypatch)
        spec = formats.BY_NAME[fmt]
        api.sample_to(str(SAMPLES / "icosahedron_binary.stl"), SampleOptions(count=10), tmp_path / f"p.{fmt}", fmt,
                      crs="EPSG:2056" if spec.crs else None)
    return tuple(len(calls[name]) for name in calls)


def test_the_output_options_are_checked_once_per_write(tmp_path):
    import importlib.util

    from scatter_cli import writers
    from scatter_cli.writers import formats

    for spec in formats.TABLE:
        if all(importlib.util.find_spec(m) for m in spec.extra + ("pyproj",) * spec.crs):
            assert checks_per_write(spec.name, tmp_path) == (1, 1, int(spec.crs)), spec.name
    write_output, file_size = writers.write_output, writers._file_size

    def checked_again(monkeypatch):
        monkeypatch.setattr(writers, "write_output", lambda chunks, out, *a, **k: write_output(
            chunks, writers.output(out.path, out.format, out.ascii), *a, **k))

    def loaded_again(monkeypatch):
        monkeypatch.setattr(writers, "_file_size", lambda module, fmt, *a, **k: file_size(
            writers.load(fmt), fmt, *a, **k))

    assert checks_per_write("ply", tmp_path, checked_again) == (2, 1, 0)
    assert checks_per_write("ply", tmp_path, loaded_again) == (1, 2, 0)


def format_literals(root, skip=("writers", "loading")):
    """[(file, line, text)] of the string literals (docstrings left out) that name an output
    format or one of its suffixes, in the modules under ``root`` outside the folders
    ``skip``: the writers, and the loaders, whose own table names the input formats (PLY
    and USD are both)."""
    import ast
    from pathlib import Path

    from scatter_cli.writers.formats import FORMATS, SUFFIXES

    names = set(FORMATS) | set(SUFFIXES)
    found = []
    for path in sorted(Path(root).rglob("*.py")):
        if path.relative_to(root).parts[0] in skip:
            continue
        tree = ast.parse(path.read_text())
        docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                      if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                      and ast.get_docstring(node, clean=False) is not None}
        found += [(path.relative_to(root).as_posix(), node.lineno, node.value) for node in ast.walk(tree)
                  if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings
                  and node.value.lower().lstrip("*.") in names]
    return sorted(found)


@pytest.mark.slow
def test_no_module_outside_the_writers_names_an_output_format(tmp_path):
    from pathlib import Path

    package = Path(scatter_cli.__file__).parent
    assert format_literals(package) == []
    assert (package / "api.py").exists() and (package / "cli.py").exists()
    (tmp_path / "writers").mkdir()
    (tmp_path / "writers" / "las.py").write_text('FORMAT = "las"\n')
    (tmp_path / "api.py").write_text('"""Writes to out.ply, or "npy"."""\n\ndef options(fmt):\n'
                                     '    """LAS the bounds."""\n    return fmt in ("las", "LAZ") or fmt == f"x.{fmt}.usd"\n')
    assert format_literals(tmp_path) == [("api.py", 5, ".usd"), ("api.py", 5, "LAZ"), ("api.py", 5, "las")]


@pytest.mark.slow
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
