"""The fast readers give what trimesh gives (process=False), or hand the file to trimesh.

"Gives": per instance, the same triangles with the same corner positions in the same
order, and the same sampled bytes. Each case also checks that the fast path answered,
so a reader that handed everything to trimesh would fail.
"""

import functools
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli.loading.load import load_surface
from testkit.fuzz_inputs import SEEDS, fast_read
from testkit.loadmemory import load_memory

from .conftest import SAMPLES, run_scatter, run_user

SHARED = Path("/work/shared/meshes")
MESHES = sorted({p.name: p for d in (SHARED, SAMPLES) if d.is_dir() for p in d.iterdir()
                 if p.suffix in (".ply", ".obj", ".stl", ".off", ".glb")}.values())
FORMATS = {"obj": ("obj", {}), "off": ("off", {}), "ply-ascii": ("ply", {"encoding": "ascii"}),
           "ply-binary": ("ply", {}), "stl-ascii": ("stl", {"file_type": "stl_ascii"}), "stl-binary": ("stl", {}),
           "glb": ("glb", {})}


def world_corners(surface):
    """Per instance, (F, 3, 3) float64 world corners, in face order."""
    return [surface.world_vertices(i)[surface.geometries[i.geometry].faces] for i in surface.instances]


def assert_same_load(path):
    fast = load_surface(path, plain=True)
    slow = load_surface(path)
    a, b = world_corners(fast), world_corners(slow)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.shape == y.shape and x.tobytes() == y.tobytes()
    assert [i.name for i in fast.instances] == [i.name for i in slow.instances]


def assert_same_samples(path):
    fast = scatter_cli.sample(path, count=3000, seed=5, attributes="face,bary,object")
    slow = scatter_cli.sample(load_surface(path), count=3000, seed=5, attributes="face,bary,object")
    assert fast.points.tobytes() == slow.points.tobytes()
    for k in ("face", "bary", "object"):
        assert fast.attributes[k].tobytes() == slow.attributes[k].tobytes()


@functools.lru_cache(maxsize=None)
def positions_and_faces(mesh_path):
    mesh = trimesh.load(mesh_path, force="mesh", process=False)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def resave(mesh_path, fmt, tmp_path, most_faces=3000):
    """The mesh's first ``most_faces`` faces (positions and faces only) saved in ``fmt``:
    large text files would make the trimesh side of the comparison slow."""
    suffix, options = FORMATS[fmt]
    vertices, faces = positions_and_faces(mesh_path)
    used, faces = np.unique(faces[:most_faces], return_inverse=True)
    mesh = trimesh.Trimesh(vertices[used], faces.reshape(-1, 3), process=False)
    path = tmp_path / f"{mesh_path.stem}.{suffix}"
    mesh.export(path, **options)
    return path


@pytest.mark.parametrize("fmt", sorted(FORMATS))
@pytest.mark.parametrize("mesh", MESHES, ids=[m.name for m in MESHES])
def test_resaved_meshes_load_and_sample_as_with_trimesh(mesh, fmt, tmp_path):
    path = resave(mesh, fmt, tmp_path)
    assert fast_read(path, path.suffix[1:]) is not None
    assert_same_load(path)
    assert_same_samples(path)


@pytest.mark.parametrize("name", sorted(SEEDS))
def test_fuzz_seeds_read_as_with_trimesh(name, tmp_path):
    suffix, data = SEEDS[name]
    path = tmp_path / f"seed.{suffix}"
    path.write_bytes(data)
    assert fast_read(path, suffix) is not None
    assert_same_load(path)
    assert_same_samples(path)


V8 = "".join(f"v {i * 0.5} {(i * i) % 7 - 2.25} {i % 3}e-1\n" for i in range(9))
OBJ_CASES = {
    "triangles": V8 + "f 1 2 3\nf 4 5 6\nf 7 8 9\n",
    "all quads": V8 + "f 1 2 3 4\nf 5 6 7 8\nf 2 4 6 8\n",
    "all pentagons": V8 + "f 1 2 3 4 5\nf 5 6 7 8 9\n",
    "mixed sizes": V8 + "f 1 2 3 4\nf 5 6 7\nf 1 2 3 4 5 6\nf 9 8 7 6\n",
    "quads read line by line": V8 + "vt 0 0\nf 1/1 2/1 3/1 4/1\nf 5 6 7 8\nf 9 8 7 6\n",
    "negative": V8 + "f -1 -2 -3\nf 1 -4 2\n",
    "negative before later vertices": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nv 6 5 5\n",
    "v/vt": V8 + "vt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\nf 4/3 5/2 6/1 7/1\nf 7/1 8/2 9/3\n",
    "v//vn": V8 + "vn 0 0 1\nf 1//1 2//1 3//1\nf 3//1 4//1 5//1\n",
    "v/vt/vn": V8 + "vt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf 5/1/1 6/1/1 7/1/1 8/1/1\n",
    "vertex colours": "".join(f"v {i} {i % 2} {i % 3} 0.5 0.5 0.5\n" for i in range(5)) + "f 1 2 3\nf 3 4 5\n",
    "groups and objects": V8 + "o a\ng one\nf 1 2 3\ng two\ns 1\nf 4 5 6\no b\nf 7 8 9\n",
    "materials": V8 + "mtllib none.mtl\nusemtl red\nf 1 2 3\nusemtl blue\nf 2 3 4 5\nusemtl red\nf 4 5 6\n"
                      "f 6 7 8 9\nusemtl green\nf 7 8 9\n",
    "faces before the first material": V8 + "f 1 2 3\nf 3 4 5\nusemtl a\nf 4 5 6 7\nf 1 2 3 4\n",
    "crlf": (V8 + "f 1 2 3\nf 4 5 6 7\n").replace("\n", "\r\n"),
    "comments and blank lines": "# made by hand\n\n" + V8 + "\n# faces\nf 1 2 3\n  \nf 4 5 6\n",
    "continuations": V8 + "f 1 2 \\\n3\nf 4 \\\n5 \\\n6\n",
    "continuation inside a number": V8.replace("v 1.0", "v 1\\\n.0") + "f 1 2 3\nf 4 5 6\n",
    "no final newline": V8 + "f 1 2 3\nf 4 5 6",
    "exponents and signs": "v +1e0 -2.5E-3 .5\nv 1. 0 -0\nv 3 4 1e-310\nv 0.1234567890123456789012 1e22 1e23\n"
                           "f 1 2 3\nf 2 3 4\n",
}
OFF_CASES = {
    "triangles": "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 2 3\n",
    "triangles and quads": "OFF\n6 3 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n4 0 1 2 3\n3 0 1 4\n4 1 5 4 0\n",
    "pentagons": "OFF\n6 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n5 0 1 2 3 4\n5 1 2 3 4 5\n",
    "counts on the keyword line": "OFF 4 1 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 1 2 3\n",
    "no newline after the keyword": "OFF4 1 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 1 2 3",
    "colours and blank lines": "COFF\n\n4 1 0\n0 0 0 255 0 0\n1 0 0 0 0 0\n\n0 1 0 1 1 1\n0 0 1 9 9 9\n3 1 2 3 1 2 3\n",
    "crlf": "OFF\r\n4 2 0\r\n0 0 0\r\n1 0 0\r\n0 1 0\r\n0 0 1\r\n3 0 1 2\r\n4 0 1 2 3\r\n",
}
PLY_HEAD = ("ply\nformat ascii 1.0\ncomment hand made\nelement vertex 6\nproperty {t} x\nproperty {t} y\n"
            "property {t} z\nproperty uchar red\nelement face {n}\nproperty list uchar int vertex_indices\nend_header\n")
PLY_V = "0 0 0 1\n1 0.1 0 2\n1 1 0.3 3\n0 1 0 4\n0 0 1.7 5\n1 0 1 6\n"
PLY_CASES = {
    "float": PLY_HEAD.format(t="float", n=2) + PLY_V + "3 0 1 2\n3 2 3 4\n",
    "double": PLY_HEAD.format(t="double", n=2) + PLY_V + "3 0 1 2\n3 2 3 4\n",
    "triangles and quads": PLY_HEAD.format(t="float", n=3) + PLY_V + "4 0 1 2 3\n3 0 1 4\n4 1 5 4 0\n",
    "all quads": PLY_HEAD.format(t="float", n=2) + PLY_V + "4 0 1 2 3\n4 1 5 4 0\n",
    "crlf body": PLY_HEAD.format(t="float", n=2) + (PLY_V + "3 0 1 2\n3 2 3 4\n").replace("\n", "\r\n"),
}
STL_FACET = "facet normal 0 0 1\n outer loop\n  vertex {0}\n  vertex {1}\n  vertex {2}\n endloop\nendfacet\n"
STL_CASES = {
    "named": "solid part\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1.5 0") + STL_FACET.format("0 0 0", "1 0 0", "0 0 2")
             + "endsolid part\n",
    "upper case, crlf": ("SOLID\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1 0").upper() + "ENDSOLID\n").replace("\n", "\r\n"),
    "no final newline": "solid\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1 0") + "endsolid",
}
CASES = ([("obj", k, v) for k, v in OBJ_CASES.items()] + [("off", k, v) for k, v in OFF_CASES.items()]
         + [("ply", k, v) for k, v in PLY_CASES.items()] + [("stl", k, v) for k, v in STL_CASES.items()])


@pytest.mark.parametrize("suffix,case,text", CASES, ids=[f"{s}-{c}" for s, c, _ in CASES])
def test_format_rules_match_trimesh(suffix, case, text, tmp_path):
    path = tmp_path / f"m.{suffix}"
    path.write_bytes(text.encode())
    assert fast_read(path, suffix) is not None
    assert_same_load(path)
    assert_same_samples(path)


HANDED_OFF = {
    "obj": ["v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",  # index 0
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",  # out of range
            "v 0 0 0\rv 1 0 0\rv 0 1 0\rf 1 2 3\r",  # lone CR
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nf 1 2 3\n",  # a line element
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2 3\n",  # mixed reference forms
            "v 0 0 0\nv 1 0 0\nv 0 1 0\n  f 1 2 3\n",  # indented: trimesh does not see it
            "v 0 0 0\nv 1 0 0\nv 0 1 0 1 1 1\nf 1 2 3\n",  # vertex rows of different lengths
            "v 0 0 0\nv 1 0 0\nv 0 1 nan\nf 1 2 3\n",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 # comment\n",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\n# usemtl x\nf 1 2 3\n"],
    "off": ["OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "OFF\n# c\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
            "OFF\n5 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n2 2 0\n3 0 1 2\n5 0 1 2 3 4\n", "NOFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"],
    "stl": ["solid a\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1 0") + "endsolid a\nsolid b\n"
            + STL_FACET.format("0 0 0", "1 0 0", "0 0 1") + "endsolid b\n",
            "solid vertex\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1 0") + "endsolid\n",
            "solid\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1 0") + "\n",
            # bytes other than printable ASCII, tab, CR and LF anywhere (trimesh decodes the whole file):
            # in the header, the rest of a keyword line, a vertex line, after endsolid
            "solid caf\xe9\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1 0") + "endsolid\n",
            "solid\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1 0").replace("0 0 1", "0 0 1\x00") + "endsolid\n",
            "solid\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1 0").replace("outer loop", "outer\x0cloop") + "endsolid\n",
            "solid\n" + STL_FACET.format("0 0 0", "1 0 0\x7f", "0 1 0") + "endsolid\n",
            "solid\n" + STL_FACET.format("0 0 0", "1 0 0", "0 1 0") + "endsolid\n\x80"],
    "ply": [PLY_HEAD.format(t="float", n=2) + PLY_V + "3 0 1 2\n\n3 2 3 4\n",
            PLY_HEAD.format(t="float", n=2) + PLY_V + "3 0 1 2\n5 0 1 2 3 4\n"],
}
HANDED = [(s, t) for s, ts in HANDED_OFF.items() for t in ts]


@pytest.mark.parametrize("suffix,text", HANDED, ids=[f"{s}-{k}" for s, ts in HANDED_OFF.items() for k in range(len(ts))])
def test_constructs_outside_the_subset_go_to_trimesh(suffix, text, tmp_path):
    path = tmp_path / f"m.{suffix}"
    path.write_bytes(text.encode())
    assert fast_read(path, suffix) is None


@pytest.mark.slow
def test_the_command_writes_the_same_bytes_either_way(tmp_path):
    path = tmp_path / "m.obj"
    path.write_bytes(OBJ_CASES["materials"].encode())
    outs = []
    for env in ({}, {"SCATTER_NUMPY": "1"}):  # without the compiled readers: trimesh loads it
        out = tmp_path / f"out{len(outs)}.ply"
        run_scatter("sample", path, "-n", "2000", "-a", "face,bary,object", "-o", out, env=env, check=True)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


@pytest.mark.slow
@pytest.mark.parametrize("attributes", ["face", "face,smooth-normal"])
@pytest.mark.parametrize("suffix", ["obj", "off", "stl"])
def test_a_plain_text_job_never_imports_trimesh(suffix, attributes, tmp_path):
    path = tmp_path / f"m.{suffix}"
    path.write_bytes((OBJ_CASES["materials"] if suffix == "obj" else OFF_CASES["triangles and quads"] if suffix == "off"
                      else STL_CASES["named"]).encode())
    args = ["sample", str(path), "-n", "100", "-a", attributes, "-o", str(tmp_path / "o.ply")]
    code = f"import sys\nfrom scatter_cli import cli\nassert cli.main({args!r}) == 0\nprint('trimesh' in sys.modules)"
    proc = run_user([sys.executable, "-c", code], text=True)
    assert proc.stdout.strip() == "False", proc.stderr


def test_numbers_convert_as_python_floats_do():
    """Every path of the number parser (exact small, exact 128-bit, strtod) rounds correctly."""
    from scatter_cli.loading import _creaders

    rng = np.random.default_rng(1)
    x = rng.standard_normal(6000) * 10.0 ** rng.integers(-30, 30, 6000)
    toks = ["9007199254740993", "9007199254740993e-19", "0.1", "1" * 19, "1" * 19 + "e-19", "18446744073709551615",
            "2.2250738585072011e-308", "4.9e-324", "1" * 300, "-0", "0.000", "1e22", "1e23", "123456789012345678901e-40"]
    toks += [repr(float(v)) for v in x] + ["%.17g" % v for v in x] + ["%.19f" % v for v in x[:2000]]
    toks += ["%.3e" % v for v in x[:2000]] + ["%.20g" % v for v in x[:2000]]
    toks = toks[: len(toks) // 9 * 9]
    text = "solid\n" + "".join(f"vertex {toks[i]} {toks[i + 1]} {toks[i + 2]}\n" for i in range(0, len(toks), 3))
    got = _creaders.read_stl_ascii((text + "endsolid\n").encode()).ravel()
    want = np.array([float(t) for t in toks])
    assert got.view(np.int64).tolist() == want.view(np.int64).tolist()


def big_ascii_stl(facets=56000, seed=0):
    """About 13.5 MB of ASCII STL: large enough for the reader to split it into 3 parts."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((facets, 3, 3))
    rows = ["facet normal 0 0 1\n outer loop\n" + "".join("  vertex %r %r %r\n" % tuple(v) for v in f.tolist())
            + " endloop\nendfacet\n" for f in x]
    return rows


@pytest.mark.slow
@pytest.mark.parametrize("case", ["plain", "crlf", "endsolid early", "endsolid early, then other bytes",
                                  "a second solid late", "a bad line late"])
def test_ascii_stl_read_in_parts_is_read_as_in_one(case):
    """The reader splits a large file at line breaks and reads the parts on threads; the
    parts decide in file order, so the result is the one-part result in every case."""
    from scatter_cli.loading import _creaders

    rows = big_ascii_stl()
    k = len(rows) // 5
    if case == "endsolid early":
        rows[k] = "endsolid\n"
    elif case == "endsolid early, then other bytes":
        rows[k] = "endsolid\n"
        rows[-k] = rows[-k].replace("outer", "\x80uter")
    elif case == "a second solid late":
        rows[-k] = "endsolid\nsolid b\n"
    elif case == "a bad line late":
        rows[-k] = rows[-k].replace("outer loop", "outer loop 1")
        rows[-k] = rows[-k].replace("vertex", "vertexx", 1)
    text = "solid a\n" + "".join(rows) + ("" if "endsolid early" in case else "endsolid a\n")
    data = (text.replace("\n", "\r\n") if case == "crlf" else text).encode()
    one = _creaders.read_stl_ascii(data, 1)
    want = {"endsolid early": 3 * k, "plain": 3 * len(rows), "crlf": 3 * len(rows)}.get(case)
    assert (one is None) if want is None else len(one) == want
    for threads in (2, 3, 7):  # (7: still 3 parts, of 4 MB at least)
        parts = _creaders.read_stl_ascii(data, threads)
        assert (parts is None) == (one is None)
        assert one is None or parts.tobytes() == one.tobytes()


@functools.lru_cache(maxsize=None)
def body_lines(count=70000, seed=2):
    """About 3.5 MB of vertex and triangle lines (OFF and ASCII PLY alike): large enough
    for the readers to cut into 3 parts on 3 threads."""
    rng = np.random.default_rng(seed)
    vertices = ["%.6f %.6f %.6f\n" % tuple(r) for r in rng.standard_normal((count, 3)).tolist()]
    faces = ["3 %d %d %d\n" % tuple(f) for f in rng.integers(0, count, (count, 3)).tolist()]
    return tuple(vertices), tuple(faces)


def body_case(case, vertices, faces):
    """The lines of a body with ``case`` worked in (late ones in a part after the first)."""
    v, f = list(vertices), list(faces)
    late = len(f) - len(f) // 7
    if case == "quads and triangles":
        f[::3] = ["4 %d 1 2 3\n" % k for k in range(0, len(f), 3)]
    elif case == "pentagons":
        f = ["5 %d 1 2 3 4\n" % (k % len(v)) for k in range(len(f))]
    elif case == "blank lines":
        v[::97] = [line + "  \n\r\n" for line in v[::97]]
        f[::89] = ["\n \t\n" + line for line in f[::89]]
    elif case == "extra columns":
        v = [line[:-1] + " 0.5 7\n" for line in v]
        f = [line[:-1] + " 255 0 0\n" for line in f]
    elif case == "too few faces":
        f = f[:-1]
    elif case == "a bad vertex late":
        v[-len(v) // 9] = "1.0 2.0 x\n"
    elif case == "an index out of range late":
        f[late] = "3 0 1 %d\n" % len(v)
    elif case == "junk after the faces":
        f.append("what\n")
    elif case == "white space after the faces":
        f.append("\n  \n\t")
    elif case == "a blank line among the vertices":
        v[len(v) // 2] = "\n" + v[len(v) // 2]
    return v, f


def breaks(text, case):
    return {"crlf": text.replace("\n", "\r\n"), "lone cr": text.replace("\n", "\r")}.get(case, text)


def same_in_parts(read, one):
    """read(threads) on 2, 3 and 7 threads gives what one thread gives (None included)."""
    for threads in (2, 3, 7):
        parts = read(threads)
        assert (parts is None) == (one is None), threads
        if one is not None:
            assert [a.tobytes() for a in parts] == [a.tobytes() for a in one], threads


OFF_PART_CASES = {"plain": True, "crlf": True, "lone cr": False, "quads and triangles": True, "pentagons": True,
             "blank lines": True, "extra columns": True, "junk after the faces": True, "too few faces": False,
             "a bad vertex late": False, "an index out of range late": False}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(OFF_PART_CASES))
def test_off_read_in_parts_is_read_as_in_one(case):
    """An OFF is cut at line breaks and its parts read on threads; the parts' records are
    numbered from the counts before them, so the result is the one-part result (and None
    where the file goes to trimesh)."""
    from scatter_cli.loading import _creaders

    v, f = body_case(case, *body_lines())
    data = breaks(f"OFF\n{len(body_lines()[0])} {len(body_lines()[1])} 0\n" + "".join(v + f), case).encode()
    one = _creaders.read_off(data, 1)
    assert (one is not None) == OFF_PART_CASES[case]
    if case == "plain":
        mesh = trimesh.load(trimesh.util.wrap_as_stream(data), file_type="off", process=False)
        assert one[0].tobytes() == np.asarray(mesh.vertices, float).tobytes()
        assert one[1].tobytes() == np.asarray(mesh.faces, np.int64).tobytes()
    same_in_parts(lambda threads: _creaders.read_off(data, threads), one)


PLY_PART_CASES = {"plain": True, "crlf": True, "lone cr": True, "quads and triangles": True,
             "white space after the faces": True, "junk after the faces": False, "too few faces": False,
             "a blank line among the vertices": False, "a bad vertex late": False, "an index out of range late": False}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(PLY_PART_CASES))
def test_ascii_ply_read_in_parts_is_read_as_in_one(case):
    """The same for the body of an ASCII PLY (whose records are lines, whatever their
    break, and which must end in white space)."""
    from scatter_cli.loading import _creaders
    from scatter_cli.loading.fast import _ascii_layout

    v, f = body_case(case, *body_lines())
    header = (f"ply\nformat ascii 1.0\nelement vertex {len(body_lines()[0])}\nproperty double x\n"
              f"property double y\nproperty double z\nelement face {len(body_lines()[1])}\n"
              "property list uchar int vertex_indices\nend_header\n")
    data = (header + breaks("".join(v + f), case)).encode()
    layout = _ascii_layout(data)[0]
    one = _creaders.read_ply_ascii(data, *layout, b"", 1)
    assert (one is not None) == PLY_PART_CASES[case]
    if case == "plain":
        mesh = trimesh.load(trimesh.util.wrap_as_stream(data), file_type="ply", process=False)
        assert one[0].tobytes() == np.asarray(mesh.vertices, float).tobytes()
        assert one[1].tobytes() == np.asarray(mesh.faces, np.int64).tobytes()
    same_in_parts(lambda threads: _creaders.read_ply_ascii(data, *layout, b"", threads), one)


@functools.lru_cache(maxsize=None)
def obj_lines(count=60000, seed=3):
    """About 3.5 MB of OBJ: blocks of vertices (with vt and vn) and faces in turn, the faces
    under materials that change within and across the blocks, those of m1 with UV refs."""
    rng = np.random.default_rng(seed)
    lines = []
    for block in range(6):
        n = count // 6
        lines += ["v %.6f %.6f %.6f\n" % tuple(r) for r in rng.standard_normal((n, 3)).tolist()]
        lines += ["vt %.4f %.4f\n" % tuple(r) for r in rng.random((n // 4, 2)).tolist()]
        lines += ["vn 0 0 1\n"] * (n // 8)
        made = (block + 1) * n
        material = None
        for k, f in enumerate(rng.integers(1, made + 1, (n, 3)).tolist()):
            if k % 1500 == 700:
                material = k // 1500 % 3
                lines.append("usemtl m%d\n" % material)
            # one ref form a material (a group of mixed forms goes to trimesh when UVs are asked for)
            lines.append("f %d/1 %d/2 %d/3\n" % tuple(f) if material == 1 else "f %d %d %d\n" % tuple(f))
    return tuple(lines)


def obj_case(case, lines):
    """The lines of an OBJ with ``case`` worked in (late ones in a part after the first)."""
    lines = list(lines)
    late = len(lines) - len(lines) // 9
    if case == "quads, pentagons and negative refs":
        more = np.random.default_rng(4).integers(0, 3, len(lines))  # corners to add, no period to the pattern
        lines = [line[:-1] + " -1 -2"[: 3 * m] + "\n" if line.startswith("f ") and "/" not in line else line
                 for m, line in zip(more.tolist(), lines)]
    elif case == "objects, groups, smoothing and comments":
        lines = [("o part%d\ng g%d\ns 1\n# a comment\n" % (i, i) if i % 4000 == 17 else "") + line
                 for i, line in enumerate(lines)]
    elif case == "crlf and continued lines":
        lines = [line.replace("\n", "\r\n") if i % 2 else line.replace(" ", " \\\n", 1) if i % 7 == 0 and
                 line.startswith("v ") else line for i, line in enumerate(lines)]
    elif case == "one material only late":
        lines = [line for line in lines if not line.startswith("usemtl")]
        lines.insert(late, "usemtl late\n")
    elif case == "a vertex with four numbers late":
        at = next(i for i in range(late, len(lines)) if lines[i].startswith("v "))
        lines[at] = lines[at][:-1] + " 1\n"
    elif case == "a vt with three numbers late":
        at = next(i for i in range(late, len(lines)) if lines[i].startswith("vt "))
        lines[at] = lines[at][:-1] + " 0\n"
    elif case == "a line trimesh decides late":
        lines[late] = "l 1 2\n"
    elif case == "a ref out of range late":
        at = next(i for i in range(late, len(lines)) if lines[i].startswith("f "))
        lines[at] = "f 1 2 %d\n" % (10**7)
    return lines


# case -> whether the reader answers (without UVs and normals asked for, with them: a group
# of mixed ref forms goes to trimesh then)
OBJ_PART_CASES = {"plain": (True, True), "quads, pentagons and negative refs": (True, True),
                  "objects, groups, smoothing and comments": (True, True), "crlf and continued lines": (True, True),
                  "one material only late": (True, False), "a vertex with four numbers late": (False, False),
                  "a vt with three numbers late": (False, False), "a line trimesh decides late": (False, False),
                  "a ref out of range late": (False, False)}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(OBJ_PART_CASES))
def test_obj_read_in_parts_is_read_as_in_one(case, tmp_path):
    """An OBJ is cut at line breaks and its parts read on threads, each with its own
    materials, groups and runs, joined in file order: the one-part result every time, its
    UVs and normals too, and the face-vertex arrays trimesh gives for the plain case."""
    from scatter_cli.loading import _creaders

    data = "".join(obj_case(case, obj_lines())).encode()
    for tables in (False, True):
        one = _creaders.read_obj(data, tables, 1)
        assert (one is not None) == OBJ_PART_CASES[case][tables]
        for threads in (2, 3, 7):
            parts = _creaders.read_obj(data, tables, threads)
            assert (parts is None) == (one is None), threads
            if one is not None:
                assert len(parts) == len(one)
                for a, b in zip(parts, one):
                    assert (a.tobytes() == b.tobytes()) if isinstance(a, np.ndarray) else a == b, threads
    if case == "plain":
        (tmp_path / "m.obj").write_bytes(data)
        assert_same_load(tmp_path / "m.obj")


@functools.lru_cache(maxsize=None)
def icosphere_file(folder, subdivisions, fmt):
    """The icosphere in format ``fmt`` (a key of FORMATS) in ``folder``, written at the first
    call for it (each format only where a test reads it: ASCII STL alone takes seconds)."""
    suffix, options = FORMATS[fmt]
    path = Path(folder) / f"ico{subdivisions}-{fmt}.{suffix}"
    if fmt in TEXT_FORMATS:
        path.write_text(TEXT_FORMATS[fmt](icosphere(subdivisions)))
    else:
        icosphere(subdivisions).export(path, **options)
    return path


def lines(pattern, rows):
    """``pattern`` filled with each row of ``rows`` (n, k) in turn, in one formatting step."""
    return (pattern * len(rows)) % tuple(np.asarray(rows).ravel().tolist())


# The text files of the memory tests, each formatted in one step (trimesh's exports take
# two to three times as long).
TEXT_FORMATS = {
    "obj": lambda m: lines("v %.9g %.9g %.9g\n", m.vertices) + lines("f %d %d %d\n", m.faces + 1),
    "off": lambda m: f"OFF\n{len(m.vertices)} {len(m.faces)} 0\n" + lines("%.9g %.9g %.9g\n", m.vertices)
    + lines("3 %d %d %d\n", m.faces),
    "ply-ascii": lambda m: (f"ply\nformat ascii 1.0\nelement vertex {len(m.vertices)}\nproperty float x\n"
                           f"property float y\nproperty float z\nelement face {len(m.faces)}\n"
                           "property list uchar int vertex_indices\nend_header\n")
    + lines("%.9g %.9g %.9g\n", m.vertices) + lines("3 %d %d %d\n", m.faces),
    "stl-ascii": lambda m: "solid mesh\n" + lines("facet normal %.8e %.8e %.8e\n outer loop\n"
                                                  + "  vertex %.8e %.8e %.8e\n" * 3 + " endloop\nendfacet\n",
                                                  np.concatenate([m.face_normals, m.triangles.reshape(-1, 9)], axis=1))
    + "endsolid mesh\n",
}


@functools.lru_cache(maxsize=None)
def icosphere(subdivisions):
    return trimesh.creation.icosphere(subdivisions=subdivisions)


@pytest.mark.slow
@pytest.mark.parametrize("fmt", sorted(FORMATS))
def test_a_load_takes_at_most_the_file_size_beyond_what_it_returns(fmt, tmp_path_factory):
    """Peak resident memory of a load in a fresh process, less the returned arrays and
    the (mapped) file itself, is at most the file size; the icosphere(7) (327,680 faces)
    in each format, 6 to 84 MB."""
    got = load_memory(icosphere_file(str(tmp_path_factory.getbasetemp()), 7, fmt), run_user_text)
    assert got["extra"] <= got["file"], got


@pytest.mark.slow
def test_the_memory_check_fails_a_loader_that_makes_objects_per_face(tmp_path_factory):
    """The broken variant: the OFF through trimesh (compiled readers off), which parses
    with Python objects per line, exceeds the same bound."""
    got = load_memory(icosphere_file(str(tmp_path_factory.getbasetemp()), 7, "off"), run_user_text,
                      env={"SCATTER_NUMPY": "1"})
    assert got["extra"] > got["file"], got


def run_user_text(cmd, env=None):
    return run_user(cmd, env=env, text=True, timeout=600)


def assert_same_smooth_normals(path):
    fast = scatter_cli.sample(path, count=2000, seed=4, attributes="face,smooth-normal")
    slow = scatter_cli.sample(load_surface(path), count=2000, seed=4, attributes="face,smooth-normal")
    assert fast.points.tobytes() == slow.points.tobytes()
    assert fast.attributes["normal"].tobytes() == slow.attributes["normal"].tobytes()


def carries_normals_or_uv(path):
    """Whether the fast readers hand a smooth-normal job on this file to trimesh: PLY
    texture coordinates, GLB normals; an OBJ whose face refs mix forms (``1/2`` and
    ``3``: the reader splits vertices by their vt and vn refs one form at a time)."""
    data = path.read_bytes()
    if path.suffix == ".obj":
        refs = [w for line in data.decode().splitlines() if line.startswith("f ") for w in line.split()[1:]]
        return len({(w.count("/"), "//" in w) for w in refs}) > 1
    if path.suffix == ".ply":
        head = data[: data.find(b"end_header")]
        return any(w in head.split() for w in (b"u", b"s", b"texture_u"))
    return path.suffix == ".glb" and b'"NORMAL"' in data


@pytest.mark.parametrize("fmt", sorted(FORMATS))
@pytest.mark.parametrize("mesh", MESHES, ids=[m.name for m in MESHES])
def test_smooth_normals_from_the_fast_path_are_trimesh_s(mesh, fmt, tmp_path):
    """A job asking for smooth normals reads a file without normals or UVs of its own with
    the fast readers (the normals are computed from the faces, as for trimesh's mesh), and
    hands the others to trimesh."""
    path = resave(mesh, fmt, tmp_path)
    assert (fast_read(path, path.suffix[1:], smooth=True) is None) == carries_normals_or_uv(path)
    assert_same_smooth_normals(path)


@pytest.mark.parametrize("suffix,case,text", CASES, ids=[f"{s}-{c}" for s, c, _ in CASES])
def test_format_rules_hold_for_smooth_normals(suffix, case, text, tmp_path):
    path = tmp_path / f"m.{suffix}"
    path.write_bytes(text.encode())
    assert (fast_read(path, suffix, smooth=True) is None) == carries_normals_or_uv(path)
    assert_same_smooth_normals(path)


def binary_stl(corners):
    """The bytes of a binary STL of ``corners`` (n, 3, 3) float32, zero normals."""
    records = np.zeros(len(corners), dtype=[("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    records["corners"] = corners
    return b"\0" * 80 + np.uint32(len(corners)).tobytes() + records.tobytes()


@pytest.mark.parametrize("threads", ["1", "2", "3"])
def test_binary_stl_read_in_blocks_on_threads_is_trimeshs(threads, monkeypatch, tmp_path):
    """200,003 faces: blocks of 65,536 records at least, on the worker threads, the last
    one short; every corner and face as trimesh reads them (process=False)."""
    from scatter_cli.loading import fast

    corners = np.random.default_rng(4).standard_normal((200003, 3, 3)).astype(np.float32)
    path = tmp_path / "soup.stl"
    path.write_bytes(binary_stl(corners))
    monkeypatch.setenv("SCATTER_THREADS", threads)
    [(vertices, faces)] = fast._stl(path.read_bytes())
    mesh = trimesh.load(path, process=False)
    assert vertices.dtype == np.float64 and faces.dtype == np.int64
    assert vertices.tobytes() == np.asarray(mesh.vertices, dtype=np.float64).tobytes()
    assert faces.tobytes() == np.asarray(mesh.faces, dtype=np.int64).tobytes()


def test_a_copy_that_drops_the_short_last_block_is_not_trimeshs():
    """The paired failure: whole blocks only leave the last rows of a 200,003-face file unset."""
    corners = np.random.default_rng(4).standard_normal((200003, 3, 3)).astype(np.float32)
    rows = np.zeros((200003, 3, 3))
    for i in range(0, 200003 - 65536 + 1, 65536):
        rows[i : i + 65536] = corners[i : i + 65536]
    assert rows.tobytes() != corners.astype(np.float64).tobytes()
