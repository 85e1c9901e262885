"""Messages that say what is wrong: a texture without Pillow says to install it (and
``info`` lists it), a truncated PLY says where it ends, a garbage file gets the same words
from sample, batch and preview, and an output where no file can be made is not blamed on
free space."""

import os
import sys

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli import api
from scatter_cli.commands import info, preview
from scatter_cli.errors import ScatterError
from scatter_cli.loading import ply, textures
from scatter_cli.loading.load import load_surface
from scatter_cli.writers import base
from scatter_cli.writers.pointfiles import read_points

from .conftest import ROOT, SAMPLES, run_scatter

TEXTURED = SAMPLES / "boxtextured.glb"  # its image is named CesiumLogoFlat.png


# -- a texture without Pillow --------------------------------------------------------------

def textured_obj(folder):
    """An OBJ whose material library maps a PNG onto it."""
    from PIL import Image

    Image.fromarray(np.full((4, 4, 3), 200, np.uint8)).save(folder / "bark.png")
    (folder / "tree.mtl").write_text("newmtl bark\nKd 1 1 1\nmap_Kd bark.png\n")
    (folder / "tree.obj").write_text("mtllib tree.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                     "usemtl bark\nf 1/1 2/2 3/3\n")
    return folder / "tree.obj"


def error_of(path, **options):
    """What sampling ``path`` fails with (its ScatterError's text), or None."""
    try:
        scatter_cli.sample(path, 10, **options)
    except ScatterError as exc:
        return str(exc)
    return None


def install_pillow(path, texture):
    return f"{path}: reading its texture ({texture}) needs Pillow: pip install pillow"


@pytest.mark.parametrize("options", [dict(attributes=("color",)), dict(weight="texture:r")])
def test_a_texture_without_pillow_says_to_install_it(tmp_path, monkeypatch, options):
    monkeypatch.setattr(textures, "pillow_missing", lambda: True)
    obj = textured_obj(tmp_path)
    assert error_of(TEXTURED, **options) == install_pillow(TEXTURED, "CesiumLogoFlat.png")
    assert error_of(obj, **options) == install_pillow(obj, "bark.png")
    assert error_of(SAMPLES / "boxvertexcolors.glb", attributes=("color",)) is None  # no texture: no Pillow needed
    monkeypatch.setattr(textures, "require_pillow", lambda source: None)  # the broken variant
    assert error_of(TEXTURED, **options) != install_pillow(TEXTURED, "CesiumLogoFlat.png")


def assert_info_lists_the_unread_texture(path):
    report = info.describe(path)
    assert report["needs_pillow"] and report["attributes"]["texture"] is not None
    line = [s for s in info.format_text(report).splitlines() if s.startswith("attributes")]
    assert line and line[0].endswith("texture (reading it needs Pillow: pip install pillow)"), line


def test_info_lists_a_texture_and_that_pillow_is_missing(tmp_path, monkeypatch):
    monkeypatch.setattr(textures, "pillow_missing", lambda: True)
    assert_info_lists_the_unread_texture(TEXTURED)
    assert_info_lists_the_unread_texture(textured_obj(tmp_path))
    assert not info.describe(SAMPLES / "skull.ply")["needs_pillow"]
    monkeypatch.setattr(textures, "pillow_missing", lambda: False)  # the broken variant: Pillow taken as there
    with pytest.raises(AssertionError):
        assert_info_lists_the_unread_texture(TEXTURED)


def without_pillow(folder, broken=False):
    """PYTHONPATH for a Python without Pillow (``import PIL`` fails); ``broken``: also
    without the check that says to install it."""
    blocker = folder / ("no-pillow-unchecked" if broken else "no-pillow")
    (blocker / "PIL").mkdir(parents=True)
    (blocker / "PIL" / "__init__.py").write_text("raise ImportError('No module named PIL')\n")
    if broken:
        (blocker / "sitecustomize.py").write_text(
            "import scatter_cli.loading.textures as t\nt.require_pillow = lambda source: None\n")
    return os.pathsep.join([str(blocker), str(ROOT)])


def assert_pillow_messages(env, tmp_path):
    """What a user without Pillow sees: one line saying to install it, and info's note
    (``--weight texture:`` takes the same check: the in-process test above)."""
    proc = run_scatter("sample", TEXTURED, "-n", "10", "-a", "color", "-o", tmp_path / "out.ply", env=env)
    lines = proc.stderr.decode().splitlines()
    assert proc.returncode == 1 and len(lines) == 1, lines
    assert lines[0].endswith("needs Pillow: pip install pillow"), lines
    text = run_scatter("info", TEXTURED, env=env, check=True).stdout.decode()
    assert "texture (reading it needs Pillow: pip install pillow)" in text
    # a mesh with UVs and no texture: the usual words, not an internal error
    proc = run_scatter("sample", SAMPLES / "spot_triangulated.obj", "-n", "10", "-a", "color", env=env)
    assert proc.returncode == 1 and b"has no vertex colours, face colours, texture" in proc.stderr, proc.stderr


@pytest.mark.slow
def test_without_pillow_installed(tmp_path):
    assert_pillow_messages({"PYTHONPATH": without_pillow(tmp_path)}, tmp_path)
    with pytest.raises(AssertionError):  # the broken variant: the check taken out
        assert_pillow_messages({"PYTHONPATH": without_pillow(tmp_path, broken=True)}, tmp_path)


# -- a truncated PLY -----------------------------------------------------------------------

def header_length(data):
    return data.index(b"end_header\n") + len(b"end_header\n")


def cut(tmp_path, source, keep, name="cut.ply"):
    """The first ``keep`` bytes of ``source`` as a file."""
    path = tmp_path / name
    path.write_bytes(source.read_bytes()[:keep])
    return path


def where_it_ends(path, element, row, of, declared):
    size = os.path.getsize(path)
    return (f"{path}: truncated: the file ends at byte {size:,}, at {element} {row:,} of {of:,} "
            f"(of the {declared} rows its header declares)")


def ascii_icosahedron(tmp_path):
    mesh = trimesh.load(SAMPLES / "icosahedron_binary.stl", process=True)
    path = tmp_path / "ico.ply"
    path.write_bytes(trimesh.exchange.ply.export_ply(mesh, encoding="ascii"))
    return path


def test_a_truncated_ply_says_where_it_ends(tmp_path, monkeypatch):
    skull = SAMPLES / "skull.ply"  # 49,999 vertices of three floats, then 100,002 triangles (1 + 3 x 4 bytes)
    body = header_length(skull.read_bytes())
    declared = "49,999 vertex and 100,002 face"
    for keep, element, row in [(body + 12 * 8300 + 5, "vertex", 8301), (body, "vertex", 1),
                               (body + 12 * 49_999 + 13 * 77, "face", 78)]:
        path = cut(tmp_path, skull, keep)
        of = {"vertex": 49_999, "face": 100_002}[element]
        assert error_of(path) == where_it_ends(path, element, row, of, declared)
    ico = ascii_icosahedron(tmp_path)
    data = ico.read_bytes()
    lines = data[header_length(data):].split(b"\n")
    keep = header_length(data) + sum(len(line) + 1 for line in lines[:12 + 7]) + 3  # 7 faces and a bit of the 8th
    short = cut(tmp_path, ico, keep, "ico-cut.ply")
    assert error_of(short) == where_it_ends(short, "face", 8, 20, "12 vertex and 20 face")
    monkeypatch.setattr(ply, "truncation", lambda data: None)  # the broken variant: trimesh reads 7 faces
    assert error_of(short) is None


def test_a_ply_without_its_last_newline_is_whole(tmp_path):
    """An ASCII PLY may end without a newline after its last row: it is read, by the fast
    reader and by trimesh alike; cut inside that row, it is truncated."""
    data = ascii_icosahedron(tmp_path).read_bytes().rstrip(b"\n")
    whole = tmp_path / "no-newline.ply"
    whole.write_bytes(data)
    assert error_of(whole) is None
    assert len(load_surface(whole, plain=True).geometries[0].faces) == len(load_surface(whole).geometries[0].faces) == 20
    short = tmp_path / "short.ply"
    short.write_bytes(data[: data.rindex(b" ")])  # the last face without its last index
    assert error_of(short) == where_it_ends(short, "face", 20, 20, "12 vertex and 20 face")


def test_a_truncated_point_ply_is_said_alike_by_the_mesh_loader_and_the_point_reader(tmp_path, monkeypatch):
    whole = tmp_path / "points.ply"
    api.write(api.prepare(SAMPLES / "skull.ply", 1000), whole)  # as `scatter sample` writes it
    part = cut(tmp_path, whole, header_length(whole.read_bytes()) + 12 * 738 + 4)

    def both():
        with pytest.raises(ScatterError) as by_loader:
            scatter_cli.sample(part, 10)
        with pytest.raises(ScatterError) as by_reader:
            read_points(part)
        return str(by_loader.value), str(by_reader.value)

    loader, reader = both()
    assert loader == reader and "at vertex 739 of 1,000" in reader
    monkeypatch.setattr("scatter_cli.writers.ply.truncation", lambda data: None)  # the broken variant
    loader, reader = both()
    assert loader != reader


# -- the same words in sample, batch and preview ---------------------------------------------

def garbage_files(folder):
    """Files that are no mesh, with a mesh suffix each (USD needs usd-core)."""
    folder.mkdir()
    rng = np.random.default_rng(5)
    noise = rng.integers(0, 256, 3000, dtype=np.uint8).tobytes()
    files = []
    for suffix in ("ply", "obj", "stl", "off", "glb", "gltf", "usda", "usdc", "usd"):
        for kind, data in (("noise", noise), ("text", b"hello, this is not a mesh\n")):
            files.append(folder / f"{kind}.{suffix}")
            files[-1].write_bytes(data)
    skull = SAMPLES / "skull.ply"
    files.append(cut(folder, skull, 100_000, "short.ply"))
    return files


def words_of_three(path, tmp_path):
    """The error of ``path`` as sample, batch and preview say it."""
    with pytest.raises(ScatterError) as sampled:
        scatter_cli.sample(path, 10)
    record, = scatter_cli.batch([path], str(tmp_path / "out" / "{stem}.ply"), count=10, jobs=1)
    with pytest.raises(ScatterError) as previewed:
        preview.draw_input(str(path), ("iso",), 32, preview.mesh_options({}))
    return str(sampled.value), record["error"], str(previewed.value)


@pytest.mark.slow
def test_a_garbage_file_gets_the_same_words_everywhere(tmp_path, monkeypatch):
    pytest.importorskip("pxr")
    for path in garbage_files(tmp_path / "in"):
        said = words_of_three(path, tmp_path)
        assert said[0] == said[1] == said[2], said
        assert said[0].startswith(f"{path}: ")
    # the broken variant: the USD point reader in words of its own
    import scatter_cli.writers.usd as usd_writer

    def own_words(path, name):
        raise ScatterError(f"{name}: not a USD stage")

    monkeypatch.setattr(usd_writer, "open_stage", own_words)
    said = words_of_three(tmp_path / "in" / "noise.usda", tmp_path)
    assert said[0] != said[2]


# -- an output where no file can be made ---------------------------------------------------

def assert_not_blamed_on_space(path):
    with pytest.raises(ScatterError) as caught:
        with base.open_output(path, size=10_000):
            pass
    text = str(caught.value)
    assert text.startswith(f"{path}: cannot write") and "free" not in text, text
    assert not os.path.exists(path)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and /sys are Linux's")
@pytest.mark.parametrize("path", ["/proc/points.ply", "/proc/self/points.csv", "/sys/points.ply"])
def test_an_output_under_proc_is_not_blamed_on_free_space(path, monkeypatch):
    assert_not_blamed_on_space(path)
    monkeypatch.setattr(base, "room_of", lambda fs: fs.f_bavail * fs.f_frsize)  # the broken variant
    with pytest.raises(AssertionError):
        assert_not_blamed_on_space(path)
