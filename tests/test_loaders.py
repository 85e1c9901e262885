"""The loader table: every input format read through it, standard input, and what a loader
says about a file (warnings, a missing material library) instead of a puzzle."""

import numpy as np
import pytest
import trimesh

from scatter_cli.loading import formats as inputs, load as loaders

from .conftest import SAMPLES, run_scatter
from .test_cli import assert_one_line_error


def test_the_table_names_every_input_format():
    assert set(loaders.LOADERS) == set(inputs.INPUT_FORMATS)
    assert {k for k, v in loaders.LOADERS.items() if v.fast is not None} == {"ply", "obj", "stl", "off", "glb"}

# -- standard input ------------------------------------------------------------------------


@pytest.mark.slow
def test_glb_bytes_on_stdin_read_as_gltf_are_the_glb(tmp_path):
    """`--input-format gltf` with binary glTF bytes: the same points as the file itself."""
    path = SAMPLES / "boxtextured.glb"
    by_path = run_scatter("sample", path, "-n", 200, "--seed", 3, check=True)
    for kind in ("gltf", "glb"):
        piped = run_scatter("sample", "-", "--input-format", kind, "-n", 200, "--seed", 3, input=path.read_bytes())
        assert piped.returncode == 0, piped.stderr.decode()
        assert piped.stdout == by_path.stdout


@pytest.mark.slow
def test_gltf_json_on_stdin_read_as_glb_is_the_gltf(tmp_path):
    """The other way round: JSON glTF (buffers embedded) with `--input-format glb`."""
    data = trimesh.Scene(trimesh.creation.box()).export(file_type="gltf", embed_buffers=True)["model.gltf"]
    (tmp_path / "box.gltf").write_bytes(data)
    by_path = run_scatter("sample", tmp_path / "box.gltf", "-n", 100, check=True)
    piped = run_scatter("sample", "-", "--input-format", "glb", "-n", 100, input=data)
    assert piped.returncode == 0, piped.stderr.decode()
    assert piped.stdout == by_path.stdout


@pytest.mark.slow
def test_stdin_without_a_format_lists_every_format_it_can_carry():
    proc = run_scatter("sample", "-", "-n", 5, input=(SAMPLES / "hemisphere.off").read_bytes())
    assert_one_line_error(proc, 2, "--input-format", *(f" {k}" for k in inputs.STDIN_FORMATS[1:]))
    assert "(" + inputs.STDIN_FORMATS[0] in proc.stderr.decode()


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["usda", "obj"])
def test_stdin_carries_the_formats_the_error_lists(kind, tmp_path):
    """Two of the listed formats, one through trimesh and one through a temporary USD file:
    the same points as the file read by its path."""
    if kind == "usda":
        pytest.importorskip("pxr")
        path = tmp_path / "tri.usda"
        path.write_text('#usda 1.0\ndef Mesh "m" {\n int[] faceVertexCounts = [3]\n int[] faceVertexIndices = [0, 1, 2]\n'
                        ' point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]\n}\n')
    else:
        path = SAMPLES / "spot_triangulated.obj"
    by_path = run_scatter("sample", path, "-n", 100, check=True)
    piped = run_scatter("sample", "-", "--input-format", kind, "-n", 100, input=path.read_bytes())
    assert piped.returncode == 0, piped.stderr.decode()
    assert piped.stdout.splitlines()[1:] == by_path.stdout.splitlines()[1:]


@pytest.mark.slow
def test_a_gltf_with_buffer_files_on_stdin_says_why_it_cannot_be_read(tmp_path):
    files = trimesh.Scene(trimesh.creation.box()).export(file_type="gltf")
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    gltf = tmp_path / "model.gltf"
    assert run_scatter("sample", gltf, "-n", 10).returncode == 0  # by its path, the buffers are found
    proc = run_scatter("sample", "-", "--input-format", "gltf", "-n", 10, input=gltf.read_bytes())
    buffer = sorted(n for n in files if n.endswith(".bin"))[0]
    assert_one_line_error(proc, 1, "<stdin>", buffer, ".glb")


# -- OBJ material libraries ----------------------------------------------------------------

OBJ = "mtllib paint.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n"


@pytest.mark.slow
def test_a_missing_material_library_is_named_when_colours_are_asked_for(tmp_path):
    (tmp_path / "m.obj").write_text(OBJ)
    proc = run_scatter("sample", tmp_path / "m.obj", "-n", 5, "-a", "color")
    assert_one_line_error(proc, 1, "m.obj", "'paint.mtl'", "color")
    # without colours the mesh samples as before
    assert run_scatter("sample", tmp_path / "m.obj", "-n", 5).returncode == 0


@pytest.mark.slow
def test_the_same_obj_with_its_material_library_gives_its_colour(tmp_path):
    """The paired case: the library there, the colour comes from it (so the error above is
    about the missing file, not about OBJ colours)."""
    (tmp_path / "m.obj").write_text(OBJ)
    (tmp_path / "paint.mtl").write_text("newmtl red\nKd 1 0 0\n")
    proc = run_scatter("sample", tmp_path / "m.obj", "-n", 5, "-a", "color", "-f", "csv")
    assert proc.returncode == 0, proc.stderr.decode()
    rows = proc.stdout.decode().splitlines()
    header = rows[0].split(",")
    colours = {tuple(r.split(",")[header.index(c)] for c in ("red", "green", "blue")) for r in rows[1:]}
    assert colours == {("255", "0", "0")}


@pytest.mark.slow
def test_vertex_colours_need_no_material_library(tmp_path):
    (tmp_path / "m.obj").write_text(OBJ.replace("v 0 0 0", "v 0 0 0 0 1 0").replace("v 1 0 0", "v 1 0 0 0 1 0")
                                    .replace("v 0 1 0", "v 0 1 0 0 1 0"))
    proc = run_scatter("sample", tmp_path / "m.obj", "-n", 5, "-a", "color")
    assert proc.returncode == 0, proc.stderr.decode()


# -- warnings ------------------------------------------------------------------------------


def test_a_loader_hands_its_warnings_out_on_the_surface(tmp_path):
    pytest.importorskip("pxr")
    path = tmp_path / "ref.usda"
    path.write_text('#usda 1.0\ndef Xform "gone" (references = @missing.usda@) {}\n'
                    'def Mesh "m" {\n int[] faceVertexCounts = [3]\n int[] faceVertexIndices = [0, 1, 2]\n'
                    ' point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]\n}\n')
    surface = loaders.load_surface(str(path))
    assert any("missing.usda" in w and str(path) in w for w in surface.warnings)
    assert surface.keeping(surface.instances).warnings == surface.warnings
    clean = loaders.load_surface(str(SAMPLES / "hemisphere.off"))
    assert clean.warnings == []


def test_a_scene_s_geometry_without_faces_is_listed_as_not_sampled(tmp_path):
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box(), node_name="box")
    alone = tmp_path / "box.glb"
    alone.write_bytes(scene.export(file_type="glb"))
    scene.add_geometry(trimesh.PointCloud(np.arange(30.0).reshape(10, 3)), node_name="cloud")
    mixed = tmp_path / "mixed.glb"
    mixed.write_bytes(scene.export(file_type="glb"))
    assert [(u.path, u.reason) for u in loaders.load_surface(str(mixed)).unsampled] == [
        ("cloud", "a PointCloud, not a mesh")]
    assert loaders.load_surface(str(alone)).unsampled == []
