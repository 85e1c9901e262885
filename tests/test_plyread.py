"""The trimesh-free binary PLY reader: the arrays trimesh gives, or None to hand over."""

import sys

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli.loading import ply as plyread
from scatter_cli.loading.ply import read_triangles, read_triangles_from
from scatter_cli.loading.load import load_surface

from .conftest import SAMPLES, run_user, scatter_command


def trimesh_arrays(path):
    mesh = trimesh.load(path, process=False)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def write_ply(path, vertices, faces, order="<", vertex_type="f4", index_type="i4", count_type="u1",
              extra_vertex=(), extra_face="", fmt=None, face_props=()):
    """``face_props``: (name, type, before the index list) scalar face properties, written
    with values; ``extra_face``: a header line only."""
    names = {"f4": "float", "f8": "double", "i4": "int", "u4": "uint", "u1": "uchar", "i2": "short", "u2": "ushort"}
    fmt = fmt or {"<": "binary_little_endian", ">": "binary_big_endian"}[order]
    vprops = [("x", vertex_type), ("y", vertex_type), ("z", vertex_type)] + list(extra_vertex)
    header = ["ply", f"format {fmt} 1.0", "comment made by test_plyread", f"element vertex {len(vertices)}"]
    header += [f"property {names[t]} {n}" for n, t in vprops]
    before = [(n, t) for n, t, first, *_ in face_props if first]
    after = [(n, t) for n, t, first, *_ in face_props if not first]
    header += [f"element face {len(faces)}"] + [f"property {names[t]} {n}" for n, t in before]
    header += [f"property list {names[count_type]} {names[index_type]} vertex_indices"]
    header += [f"property {names[t]} {n}" for n, t in after]
    if extra_face:
        header.append(extra_face)
    header.append("end_header")
    vrec = np.zeros(len(vertices), dtype=[(n, order + t) for n, t in vprops])
    for k, axis in enumerate("xyz"):
        vrec[axis] = vertices[:, k]
    frec = np.zeros(len(faces), dtype=[(f"b_{n}", order + t) for n, t in before]
                    + [("n", order + count_type), ("i", order + index_type, 3)]
                    + [(f"a_{n}", order + t) for n, t in after])
    frec["n"] = 3
    frec["i"] = faces
    for k, (name, _, _, *value) in enumerate(face_props):
        column = ("b_" if f"b_{name}" in frec.dtype.names else "a_") + name
        frec[column] = value[0] if value else np.arange(len(faces)) * (k + 7) % 251
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode())
        f.write(vrec.tobytes())
        f.write(frec.tobytes())
    return path


@pytest.fixture
def ball():
    m = trimesh.creation.icosphere(subdivisions=3)
    v = np.asarray(m.vertices) * [1.0, 2.0, 3.0] + [1e3, -5.0, 0.25]
    return v, np.asarray(m.faces)


@pytest.mark.parametrize("name", ["skull.ply", "moebius-160-10.ply"])
def test_sample_plys_read_as_trimesh_reads_them(name):
    got = read_triangles(SAMPLES / name)
    assert got is not None
    want = trimesh_arrays(SAMPLES / name)
    for a, b in zip(got, want):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("options", [
    dict(),
    dict(order=">"),
    dict(vertex_type="f8", index_type="u4", count_type="i4"),
    dict(extra_vertex=[("red", "u1"), ("confidence", "f4")]),
    # scalar face properties beside the list, as trimesh writes an STL's attribute or face colours
    dict(face_props=[("stl", "u2", False)]),
    dict(order=">", face_props=[("quality", "f4", True), ("red", "u1", False), ("green", "u1", False),
                                ("blue", "u1", False)]),
])
def test_written_variants_read_as_trimesh_reads_them(options, ball, tmp_path):
    path = write_ply(tmp_path / "m.ply", *ball, **options)
    got = read_triangles(path)
    assert got is not None
    for a, b in zip(got, trimesh_arrays(path)):
        assert a.tobytes() == b.tobytes()


@pytest.mark.parametrize("case", ["ascii", "quads", "face property not in the body", "texcoords", "truncated",
                                  "not a ply", "index name twice", "list property type"])
def test_anything_else_is_handed_to_trimesh(case, ball, tmp_path):
    v, f = ball
    path = tmp_path / "m.ply"
    if case == "ascii":
        trimesh.Trimesh(v, f, process=False).export(path, encoding="ascii")
    elif case == "quads":
        trimesh.Trimesh(v, f, process=False).export(path)
        data = path.read_bytes()
        at = data.index(b"end_header\n") + len(b"end_header\n") + 12 * len(v)
        path.write_bytes(data[:at] + b"\x04" + data[at + 1:])  # the first face claims four corners
    elif case == "face property not in the body":
        write_ply(path, v, f, extra_face="property uchar red")
    elif case == "index name twice":
        write_ply(path, v, f, face_props=[("vertex_index", "i4", True)])
    elif case == "list property type":
        write_ply(path, v, f, face_props=[("red", "u1", False)])
        data = path.read_bytes()
        path.write_bytes(data.replace(b"property uchar red", b"property list red", 1))
    elif case == "texcoords":
        write_ply(path, v, f, extra_face="property list uchar float texcoord")
    elif case == "truncated":
        write_ply(path, v, f)
        path.write_bytes(path.read_bytes()[:-7])
    else:
        path.write_bytes(b"solid x\nendsolid x\n")
    assert read_triangles(path) is None


def test_face_properties_are_read_only_for_jobs_without_colours(ball, tmp_path):
    path = write_ply(tmp_path / "m.ply", *ball, face_props=[("red", "u1", False), ("green", "u1", False),
                                                             ("blue", "u1", False)])
    data = path.read_bytes()
    assert read_triangles_from(data) is not None
    assert read_triangles_from(data, smooth=True) is not None
    assert read_triangles_from(data, color=True) is None  # face colours: trimesh's visuals


def test_the_face_record_must_keep_the_file_s_order(ball, monkeypatch, tmp_path):
    """A reader placing the list first whatever the file says (the broken variant) reads
    other triangles than trimesh: the comparisons above can fail."""
    # a one-byte property of 3 before the list: the broken reading still sees triangles
    path = write_ply(tmp_path / "m.ply", *ball, face_props=[("quality", "u1", True, 3)])
    want = trimesh_arrays(path)
    real = plyread._face_dtype

    def list_first(fprops):
        dtype = real(fprops)
        extras = [n for n in dtype.names if n not in ("n", "i")]
        return np.dtype([(n, dtype.fields[n][0]) for n in ("n", "i", *extras)])

    assert read_triangles(path)[1].tobytes() == want[1].tobytes()
    monkeypatch.setattr(plyread, "_face_dtype", list_first)
    got = read_triangles(path)
    assert got is not None and got[1].tobytes() != want[1].tobytes()


@pytest.mark.parametrize("face_props", [(), (("quality", "f4", True), ("red", "u1", False), ("green", "u1", False),
                                                ("blue", "u1", False))])
@pytest.mark.parametrize("attributes", ["face,normal", "face,bary,smooth-normal"])
def test_plain_jobs_give_the_same_bytes_either_way(face_props, attributes, ball, tmp_path):
    path = write_ply(tmp_path / "m.ply", *ball, order=">", face_props=face_props)
    assert read_triangles(path) is not None  # the fast path answers
    fast = scatter_cli.sample(path, count=5000, seed=2, attributes=attributes)
    slow = scatter_cli.sample(load_surface(path), count=5000, seed=2, attributes=attributes)  # trimesh's
    assert fast.points.tobytes() == slow.points.tobytes()
    for name in fast.attributes:
        assert fast.attributes[name].tobytes() == slow.attributes[name].tobytes()


@pytest.mark.slow
def test_bad_indices_still_get_the_one_line_error(ball, tmp_path):
    v, f = ball
    f = f.copy()
    f[5, 1] = len(v) + 3
    path = write_ply(tmp_path / "m.ply", v, f)
    proc = run_user(scatter_command("sample", path, "-n", "10", "-o", "-"), text=True)
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines() == [f"error: {path}: face indices out of range in geometry '{path}'"]


@pytest.mark.slow
def test_a_plain_ply_job_never_imports_trimesh(tmp_path):
    args = ["sample", str(SAMPLES / "skull.ply"), "-n", "100", "-a", "face,normal", "-o", str(tmp_path / "o.ply")]
    code = f"import sys\nfrom scatter_cli import cli\nassert cli.main({args!r}) == 0\nprint('trimesh' in sys.modules)"
    proc = run_user([sys.executable, "-c", code], text=True)
    assert proc.stdout.strip() == "False", proc.stderr


def test_counts_larger_than_the_file_are_not_read(ball, tmp_path):
    path = write_ply(tmp_path / "m.ply", *ball)
    data = path.read_bytes().replace(b"element vertex 642", b"element vertex 999999999999", 1)
    path.write_bytes(data)
    assert read_triangles(path) is None
