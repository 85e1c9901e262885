"""The fast readers' attribute tables are trimesh's (``process=False``): PLY vertex
normals and colours, OBJ UVs and normals with the vertices split as trimesh splits them.

For files re-saved with these attributes, and for built cases of each rule (PLY colour
types, alpha, float scaling, partial normals, texture coordinates; OBJ ref forms, quads,
polygons, negative refs, materials), a job asking for ``color``, ``uv`` or
``smooth-normal`` gives the same triangles and the same output bytes whether the fast
readers or trimesh loaded the file (for OBJ also the same vertex, face, UV and normal
arrays), and each case checks that the fast path answered (or, for what it does not
cover, that it handed the file over).
"""

import sys

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli.loading import ply as plyread
from scatter_cli.loading.load import load_surface
from scatter_cli.surface.data import VertexTables, uv_table, vertex_normal_table, weighted_vertex_normals
from testkit.fuzz_inputs import fast_read
from testkit.loadmemory import load_memory
from testkit.meshfiles import obj_text, write_ply

from .conftest import run_scatter, run_user
from .test_readers import MESHES, assert_same_load, positions_and_faces, run_user_text

MESHES_BY_NAME = {m.name: m for m in MESHES}
ATTRIBUTES = ("face,bary,color", "face,smooth-normal", "color,smooth-normal")


def sample_bytes(source, attributes):
    s = scatter_cli.sample(source, count=2000, seed=7, attributes=attributes)
    return [s.points.tobytes()] + [s.attributes[k].tobytes() for k in sorted(s.attributes)]


def assert_fast_and_same(path, attributes=ATTRIBUTES):
    """The fast readers answer with their tables, and every job gives trimesh's bytes."""
    color = any("color" in a for a in attributes)
    assert fast_read(path, "ply", smooth=True, color=color) is not None
    fast = load_surface(path, plain=True, smooth=True, color=color)
    assert all(isinstance(g.mesh, VertexTables) for g in fast.geometries)
    assert_same_load(path)
    slow = load_surface(path)
    for a in attributes:
        assert sample_bytes(path, a) == sample_bytes(slow, a), a


def attributed_columns(mesh_path, most_faces=3000, seed=0):
    """A sample mesh's first faces with random RGBA colours and normals that are not the
    ones computed from the faces (so a reader that dropped them would fail)."""
    vertices, faces = positions_and_faces(mesh_path)
    used, faces = np.unique(faces[:most_faces], return_inverse=True)
    vertices, faces = vertices[used], faces.reshape(-1, 3)
    rng = np.random.default_rng(seed)
    normals = np.nan_to_num(weighted_vertex_normals(vertices, faces)) + rng.normal(0, 0.3, (len(vertices), 3))
    colors = rng.integers(0, 256, (len(vertices), 4))
    columns = [(a, "f4", vertices[:, k]) for k, a in enumerate("xyz")]
    columns += [(a, "f4", normals[:, k]) for k, a in enumerate(("nx", "ny", "nz"))]
    columns += [(a, "u1", colors[:, k]) for k, a in enumerate(("red", "green", "blue", "alpha"))]
    return columns, faces


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
@pytest.mark.parametrize("mesh", MESHES, ids=[m.name for m in MESHES])
def test_resaved_meshes_with_normals_and_colours_sample_as_with_trimesh(mesh, fmt, tmp_path):
    columns, faces = attributed_columns(mesh)
    path = write_ply(tmp_path / f"{mesh.stem}.ply", columns, faces.tolist(), fmt)
    assert_fast_and_same(path)


def _tri(n=6):
    """A small strip: n vertices, n - 2 triangles."""
    x = np.arange(n, dtype=float)
    return [("x", "f4", x), ("y", "f4", x % 2 + 0.25 * x), ("z", "f4", np.sin(x))], [[k, k + 1, k + 2] for k in range(n - 2)]


POS, TRI = _tri()
RGB = [("red", "u1", [255, 0, 3, 90, 128, 7]), ("green", "u1", [0, 255, 60, 1, 2, 250]),
       ("blue", "u1", [9, 8, 7, 255, 0, 100])]
CASES = {
    "uchar rgb": RGB,
    "uchar rgba": RGB + [("alpha", "u1", [0, 255, 17, 128, 1, 200])],
    "float rgb, clipped and rounded": [(a, "f4", v) for a, v in zip(("red", "green", "blue"), (
        [0.0, 1.0, 0.5, 0.25, 1.3, -0.2], [0.999, 0.001, 0.502, 0.498, 0.7, 0.1], [0.2, 0.4, 0.6, 0.8, 1.0, 0.0]))],
    "double rgba": [(a, "f8", np.linspace(0.05 * k, 1.0, 6)) for k, a in enumerate(("red", "green", "blue", "alpha"))],
    "ushort rgb, wrapped": [(a, "u2", [0, 255, 256, 300, 65535, 1000]) for a in ("red", "green", "blue")],
    "char rgb, negative": [(a, "i1", [-1, -128, 127, 0, 5, -7]) for a in ("red", "green", "blue")],
    "uchar rgb, float alpha": RGB + [("alpha", "f4", [0.0, 1.0, 0.5, 0.25, 0.75, 0.1])],
    "colours between the coordinates": RGB,
    "double normals": [("nx", "f8", [0.1, 0, 0, 1, -1, 0.3]), ("ny", "f8", [0, 1, 0, 0.5, 0, 0.3]),
                       ("nz", "f8", [1, 0, 2.5, 0, 0, -0.9])],
    "int normals": [(a, "i4", [1, 0, -1, 2, 0, 3]) for a in ("nx", "ny", "nz")],
    "two of three normals": [("nx", "f4", [1, 0, 0, 1, 0, 1]), ("ny", "f4", [0, 1, 0, 0, 1, 0])],
    "normals, colours and other properties": [("quality", "f4", np.arange(6.0))] + RGB
    + [(a, "f4", [0.5, -0.5, 0.25, 1, 0, 0.125]) for a in ("nx", "ny", "nz")],
    "none": [],
}


def case_columns(name):
    extra = CASES[name]
    if name == "colours between the coordinates":
        return POS[:1] + extra + POS[1:]
    return POS + extra


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_colour_and_normal_rules_match_trimesh(case, fmt, tmp_path):
    """Every colour type, alpha or none, float scaling, partial and integer normals; a
    file without colours fails ``-a color`` with the same error either way."""
    path = write_ply(tmp_path / "m.ply", case_columns(case), TRI, fmt)
    if not {"red", "green", "blue"} <= {name for name, _, _ in CASES[case]}:
        assert fast_read(path, "ply", smooth=True, color=True) is not None
        for source in (path, load_surface(path)):
            with pytest.raises(scatter_cli.ScatterError, match="no vertex colours"):
                scatter_cli.sample(source, count=10, attributes="color")
        assert_fast_and_same(path, ATTRIBUTES[1:2])
    else:
        assert_fast_and_same(path)


def test_ascii_quads_keep_their_colours(tmp_path):
    path = write_ply(tmp_path / "q.ply", POS + CASES["uchar rgba"], [[0, 1, 2, 3], [1, 2, 3], [2, 3, 4, 5]])
    assert_fast_and_same(path)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
@pytest.mark.parametrize("names", [("u", "v"), ("s", "t"), ("texture_u", "texture_v")])
def test_texture_coordinates_go_to_trimesh(names, fmt, tmp_path):
    """trimesh splits the vertices by UV and then keeps neither the file's normals nor its
    colours: the fast readers hand such a job over (a plain job they still read)."""
    uv = [(n, "f4", np.linspace(0, 1, 6) ** (k + 1)) for k, n in enumerate(names)]
    path = write_ply(tmp_path / "t.ply", POS + CASES["uchar rgb"] + CASES["double normals"] + uv, TRI, fmt)
    assert fast_read(path, "ply") is not None
    assert fast_read(path, "ply", smooth=True) is None and fast_read(path, "ply", color=True) is None


@pytest.mark.parametrize("value", ["256", "-1", "300.5"])
def test_ascii_values_outside_the_declared_type_go_to_trimesh(value, tmp_path):
    """Casting such a value to uchar is undefined in C (trimesh's result is the
    platform's): handed over rather than guessed."""
    path = write_ply(tmp_path / "o.ply", POS + RGB, TRI)
    text = path.read_text().replace(" 255 0 9\n", f" {value} 0 9\n", 1)
    assert f" {value} 0 9\n" in text
    path.write_text(text)
    assert fast_read(path, "ply", color=True) is None
    assert fast_read(path, "ply", smooth=True) is not None  # the colours are not cast for normals
    assert_fast_and_same(path, ATTRIBUTES[1:2])


def test_the_comparison_fails_readers_that_drop_normals_or_alpha(tmp_path, monkeypatch):
    """The broken variants: a reader that ignored the file's normals, or gave every
    colour an opaque alpha, answers but gives other bytes than trimesh."""
    columns, faces = attributed_columns(MESHES[0], most_faces=400)
    path = write_ply(tmp_path / "b.ply", columns, faces.tolist(), "binary_little_endian")
    slow = load_surface(path)
    real = plyread.vertex_tables

    def no_normals(columns, smooth, color):
        return {k: v for k, v in real(columns, smooth, color).items() if k != "normals"}

    def opaque(columns, smooth, color):
        got = real(columns, smooth, color)
        got["vertex_colors"][:, 3] = 255
        return got

    for broken, attributes in ((no_normals, "smooth-normal"), (opaque, "color")):
        monkeypatch.setattr(plyread, "vertex_tables", broken)
        assert isinstance(load_surface(path, plain=True, smooth=True, color=True).geometries[0].mesh, VertexTables)
        assert sample_bytes(path, attributes) != sample_bytes(slow, attributes)


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_a_load_with_normals_and_colours_takes_at_most_the_file_size_beyond_what_it_returns(fmt, tmp_path):
    """As the plain loads' bound (test_readers.py), the tables counted among the returned
    arrays: the icosphere(7) with float normals and RGBA colours."""
    mesh = trimesh.creation.icosphere(subdivisions=7)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    columns = [(a, "f4", v[:, k]) for k, a in enumerate("xyz")] + [(a, "f4", v[:, k]) for k, a in enumerate(("nx", "ny", "nz"))]
    columns += [(a, "u1", (np.arange(len(v)) * (k + 3)) % 256) for k, a in enumerate(("red", "green", "blue", "alpha"))]
    path = write_ply(tmp_path / "ico.ply", columns, f, fmt)
    got = load_memory(path, run_user_text, tables=True)
    assert got["extra"] <= got["file"], got


# -- OBJ: vt and vn refs, the vertices split as trimesh splits them -------------------

OBJ_ATTRIBUTES = ("face,bary,uv", "face,smooth-normal", "uv,smooth-normal")


def assert_obj_as_trimesh(path, attributes=OBJ_ATTRIBUTES):
    """The fast reader answers; each geometry's vertices, faces, UVs and normals are
    trimesh's, bit for bit (so the split and its vertex order are); and every job gives
    trimesh's bytes."""
    assert fast_read(path, "obj", smooth=True, uv=True) is not None
    fast = load_surface(path, plain=True, smooth=True, uv=True)
    slow = load_surface(path)
    assert [g.name for g in fast.geometries] == [g.name for g in slow.geometries]
    for f, s in zip(fast.geometries, slow.geometries):
        assert isinstance(f.mesh, VertexTables)
        if f.mesh.uv is None and f.mesh.normals is None:
            continue  # a group of plain refs: the file's vertices (trimesh keeps the used ones)
        assert f.vertices.tobytes() == s.vertices.tobytes() and f.faces.tobytes() == s.faces.tobytes()
        a, b = uv_table(f.mesh), uv_table(s.mesh)
        assert (a is None) == (b is None) and (a is None or a.tobytes() == b.tobytes())
        assert vertex_normal_table(f).tobytes() == vertex_normal_table(s).tobytes()
    assert_same_load(path)
    for a in attributes:
        got = []
        for source in (path, slow):
            try:
                got.append(sample_bytes(source, a))
            except scatter_cli.ScatterError as exc:
                got.append(str(exc))
        assert got[0] == got[1], a


@pytest.mark.slow
@pytest.mark.parametrize("form", ["v/vt/vn", "v/vt", "v//vn"])
@pytest.mark.parametrize("mesh", MESHES, ids=[m.name for m in MESHES])
def test_resaved_meshes_with_uvs_and_normals_sample_as_with_trimesh(mesh, form, tmp_path):
    vertices, faces = positions_and_faces(mesh)
    used, faces = np.unique(faces[:3000], return_inverse=True)
    path = tmp_path / f"{mesh.stem}.obj"
    path.write_text(obj_text(vertices[used], faces.reshape(-1, 3).tolist(), form))
    assert_obj_as_trimesh(path)


def test_the_sample_obj_with_uvs_samples_as_with_trimesh():
    assert_obj_as_trimesh(MESHES_BY_NAME["spot_triangulated.obj"])


GRID_V = [(x, y, 0.1 * x * y) for y in range(4) for x in range(4)]
GRID_QUADS = [[4 * y + x, 4 * y + x + 1, 4 * y + x + 5, 4 * y + x + 4] for y in range(3) for x in range(3)]
FAN_V = [(0.0, 0.0, 0.0)] + [(np.cos(a), np.sin(a), 0.2 * np.sin(3 * a)) for a in np.linspace(0, 2 * np.pi, 41)[:-1]]
FAN = [[0, k, k % 40 + 1] for k in range(1, 41)]
MATERIALS = ("mtllib none.mtl\nusemtl red\nf 1/1/1 2/2/1 3/3/2\nusemtl blue\nf 2/2/2 4/3/1 3/1/1 5/2/2\n"
             "usemtl red\nf 4/1/2 5/3/2 6/2/1\nusemtl green\nf 1/3/1 5/1/2 6/2/2\n")
V6 = "".join(f"v {k * 0.5} {(k * k) % 5 - 1.5} {k % 3}\n" for k in range(6)) + "vt 0 0\nvt 1 0\nvt 0.5 1\nvn 0 0 1\nvn 0 1 0\n"
OBJ_CASES = {
    "all quads, v/vt/vn": obj_text(GRID_V, GRID_QUADS, "v/vt/vn"),
    "all quads, v/vt": obj_text(GRID_V, GRID_QUADS, "v/vt", seed=1),
    "triangles and quads, v/vt/vn": obj_text(GRID_V, GRID_QUADS[:4] + [q[:3] for q in GRID_QUADS[4:]], "v/vt/vn"),
    "pentagons, v//vn": obj_text(GRID_V, [[0, 1, 2, 6, 5], [5, 6, 10, 9, 4]], "v//vn"),
    "negative refs": obj_text(GRID_V, GRID_QUADS, "v/vt/vn", negative=True),
    "a centre meeting 40 uvs": obj_text(FAN_V, FAN, "v/vt", seed=3),
    "materials": V6 + MATERIALS,
    "positive and negative refs to one vertex": V6 + "f 1/1/1 2/2/2 3/3/1\nf -6/-3/-2 -4/1/1 4/2/2\n",
    "vt index 0": V6 + "f 1/0/1 2/2/2 3/3/1\nf 2/1/1 3/0/2 4/1/1\n",
    "uvw texture coordinates": V6.replace("vt 0 0\nvt 1 0\nvt 0.5 1\n", "vt 0 0 0\nvt 1 0 1\nvt 0.5 1 0\n")
    + "f 1/1 2/2 3/3\nf 2/1 3/3 4/2\n",
    "crlf and continuations": (V6 + "f 1/1/1 2/2/2 \\\n3/3/1\nf 2/1/1 3/3/2 4/2/1\n").replace("\n", "\r\n"),
    "a group without refs": V6 + "usemtl a\nf 1/1/1 2/2/2 3/3/1\nusemtl b\nf 2 3 4\n",
    "vertex colours": "".join(f"v {k} {k % 2} {k % 3} 0.5 0.25 1\n" for k in range(5)) + "vt 0 0\nvt 1 1\n"
    + "f 1/1 2/2 3/1\nf 3/2 4/1 5/2\n",
}


@pytest.mark.parametrize("case", sorted(OBJ_CASES))
def test_obj_uv_and_normal_rules_match_trimesh(case, tmp_path):
    path = tmp_path / "m.obj"
    path.write_bytes(OBJ_CASES[case].encode())
    assert_obj_as_trimesh(path)


OBJ_HANDED = {
    "mixed forms in a group": V6 + "f 1/1/1 2/2/2 3/3/1\nf 2/1 3/3 4/2\n",
    "vt out of range": V6 + "f 1/4/1 2/2/2 3/3/1\n",
    "vn out of range": V6 + "f 1/1/3 2/2/2 3/3/1\n",
    "v//vn without vn lines": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//1\n",
    "v/vt without vt lines": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/1 3/1\n",
}


@pytest.mark.parametrize("case", sorted(OBJ_HANDED))
def test_obj_refs_the_split_does_not_cover_go_to_trimesh(case, tmp_path):
    path = tmp_path / "m.obj"
    path.write_bytes(OBJ_HANDED[case].encode())
    assert fast_read(path, "obj") is not None or case == "mixed forms in a group"
    assert fast_read(path, "obj", smooth=True, uv=True) is None


@pytest.mark.parametrize("name", ["m.mtl", "/m.mtl", "lib/m.mtl"])
def test_an_obj_whose_material_library_resolves_goes_to_trimesh(name, tmp_path):
    """trimesh then names the geometries by material (three here, not file.obj, _1, _2):
    handed over, for plain jobs too; with the library missing the fast reader answers."""
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\nnewmtl green\nKd 0 1 0\n")
    path = tmp_path / "m.obj"
    path.write_text(OBJ_CASES["materials"].replace("mtllib none.mtl", f"mtllib {name}"))
    assert fast_read(path, "obj") is None and fast_read(path, "obj", smooth=True, uv=True) is None
    assert [g.name for g in load_surface(path).geometries] == ["green", "blue", "red"]
    (tmp_path / "m.mtl").unlink()
    assert fast_read(path, "obj") is not None
    assert_obj_as_trimesh(path)


def test_the_obj_comparison_fails_a_split_in_file_order(tmp_path, monkeypatch):
    """The broken variant: a split that numbers the (v, vt, vn) triples in order of first
    use (a natural guess) instead of trimesh's hash order: the same corners and the same
    sampled UVs (which do not see the order), but other vertex arrays, which the exact
    comparison catches."""
    from scatter_cli.loading import obj as objsplit

    path = tmp_path / "q.obj"
    path.write_bytes(OBJ_CASES["all quads, v/vt/vn"].encode())
    real = objsplit.split_group

    def first_use(vertices, keys, form, vt, vn):
        v, f, t = real(vertices, keys, form, vt, vn)
        _, first, inverse = np.unique(f.reshape(-1), return_index=True, return_inverse=True)
        rank = np.argsort(np.argsort(first))
        order = np.argsort(rank)
        return v[order], rank[inverse].reshape(-1, 3), {k: None if x is None else x[order] for k, x in t.items()}

    monkeypatch.setattr(objsplit, "split_group", first_use)
    assert_same_load(path)
    fast, slow = load_surface(path, plain=True, uv=True), load_surface(path)
    assert fast.geometries[0].vertices.tobytes() != slow.geometries[0].vertices.tobytes()
    with pytest.raises(AssertionError):
        assert_obj_as_trimesh(path)


@pytest.mark.slow
def test_an_obj_load_with_uvs_and_normals_takes_at_most_the_file_size_beyond_what_it_returns(tmp_path):
    """The icosphere(7) with v/vt/vn refs that split its vertices about 3 times: the
    split vertices, UVs, normals and faces counted as returned."""
    mesh = trimesh.creation.icosphere(subdivisions=7)
    path = tmp_path / "ico.obj"
    path.write_text(obj_text(np.asarray(mesh.vertices), np.asarray(mesh.faces).tolist(), "v/vt/vn"))
    got = load_memory(path, run_user_text, tables=True)
    assert got["extra"] <= got["file"], got


def command_case(name, tmp_path):
    """A small file of each kind the attribute tables serve, and the attributes to ask."""
    if name == "ply":
        path = write_ply(tmp_path / "m.ply", POS + CASES["uchar rgba"] + CASES["double normals"], [[0, 1, 2, 3], *TRI])
        return path, "face,bary,color,smooth-normal"
    path = tmp_path / "m.obj"
    path.write_bytes(OBJ_CASES["materials" if name == "obj" else "all quads, v/vt/vn"].encode())
    return path, "face,bary,uv,smooth-normal,object"


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ply", "obj", "obj quads"])
def test_an_attribute_job_never_imports_trimesh(name, tmp_path):
    path, attributes = command_case(name, tmp_path)
    args = ["sample", str(path), "-n", "100", "-a", attributes, "-o", str(tmp_path / "o.ply")]
    code = f"import sys\nfrom scatter_cli import cli\nassert cli.main({args!r}) == 0\nprint('trimesh' in sys.modules)"
    proc = run_user([sys.executable, "-c", code], text=True)
    assert proc.stdout.strip() == "False", proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ply", "obj"])
def test_the_command_writes_the_same_bytes_either_way(name, tmp_path):
    """The whole command, fast and through trimesh (SCATTER_NUMPY=1: no compiled readers;
    the PLY is ASCII, so trimesh reads it)."""
    path, attributes = command_case(name, tmp_path)
    outs = []
    for env in ({}, {"SCATTER_NUMPY": "1"}):
        out = tmp_path / f"out{len(outs)}.ply"
        run_scatter("sample", path, "-n", "2000", "-a", attributes, "-o", out, env=env, check=True)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
