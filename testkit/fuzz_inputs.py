"""Malformed mesh files for fuzzing the loaders: valid seeds and byte-level mutations.

Shared by the CI fuzz test (hypothesis drives the choices) and the longer run in
``benchmarks/fuzz_loaders.py`` (a seeded random loop). The property is the same in both:
loading and planning any byte string either works or raises ScatterError; anything
else would reach the user as an ``internal error`` (or, outside main(), a traceback).
"""

from __future__ import annotations

import json
import struct

import numpy as np

from .gltfwrite import GLB

TRI_V = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]
TRI_F = [(0, 1, 2), (0, 2, 3), (0, 3, 1), (1, 3, 2)]


def _ply_ascii():
    lines = ["ply", "format ascii 1.0", f"element vertex {len(TRI_V)}", "property float x", "property float y",
             "property float z", f"element face {len(TRI_F)}", "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(map(str, v)) for v in TRI_V] + [f"3 {a} {b} {c}" for a, b, c in TRI_F]
    return ("\n".join(lines) + "\n").encode()


def _ply_binary():
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(TRI_V)}", "property float x",
            "property float y", "property float z", f"element face {len(TRI_F)}",
            "property list uchar int vertex_indices", "end_header"]
    body = b"".join(struct.pack("<3f", *v) for v in TRI_V)
    body += b"".join(struct.pack("<B3i", 3, *f) for f in TRI_F)
    return ("\n".join(head) + "\n").encode() + body


def _obj():
    lines = [f"v {x} {y} {z}" for x, y, z in TRI_V] + ["vt 0 0", "vt 1 0", "vt 0 1", "vn 0 0 1"]
    lines += [f"f {a + 1}/1/1 {b + 1}/2/1 {c + 1}/3/1" for a, b, c in TRI_F] + ["f 1 2 3 4"]
    return ("\n".join(lines) + "\n").encode()


def _obj_uv():
    """v/vt/vn refs that split vertices (a vertex with several vt), quads, negative refs
    and two materials: the vertex split's rules."""
    lines = [f"v {x} {y} {z}" for x, y, z in TRI_V + [(1.0, 1.0, 0.5)]]
    lines += ["vt 0 0", "vt 1 0", "vt 0 1", "vt 0.5 0.5", "vn 0 0 1", "vn 0.5 -1 0"]
    lines += ["usemtl a", "f 1/1/1 2/2/1 5/3/2 3/4/2", "f 2/1/2 4/2/1 5/4/1 1/3/1", "usemtl b",
              "f -1/-1/-1 -2/2/-2 -3/-4/2", "usemtl a", "f 1/4/2 3/3/1 4/1/1 2/2/2"]
    return ("\n".join(lines) + "\n").encode()


def _stl_ascii():
    out = ["solid t"]
    for f in TRI_F:
        out += ["facet normal 0 0 0", "outer loop"] + [f"vertex {' '.join(map(str, TRI_V[i]))}" for i in f]
        out += ["endloop", "endfacet"]
    return ("\n".join(out + ["endsolid t"]) + "\n").encode()


def _stl_binary():
    body = b"".join(struct.pack("<12fH", 0, 0, 0, *sum((TRI_V[i] for i in f), ()), 0) for f in TRI_F)
    return b"\0" * 80 + struct.pack("<I", len(TRI_F)) + body


def _off():
    lines = ["OFF", f"{len(TRI_V)} {len(TRI_F)} 0"] + [" ".join(map(str, v)) for v in TRI_V]
    lines += [f"3 {a} {b} {c}" for a, b, c in TRI_F]
    return ("\n".join(lines) + "\n").encode()


def _obj_split():
    """Quads, negative indices, v//vn refs and two materials: the fast reader's harder rules."""
    lines = [f"v {x} {y} {z}" for x, y, z in TRI_V + [(1.0, 1.0, 0.5)]] + ["vn 0 0 1"]
    lines += ["usemtl a", "f 1//1 2//1 3//1 5//1", "usemtl b", "f -1//1 -2//1 -3//1", "usemtl a", "f 1//1 3//1 4//1 2//1"]
    return ("\r\n".join(lines) + "\r\n").encode()


def _off_quads():
    lines = ["OFF", f"{len(TRI_V) + 1} 3 0"] + [" ".join(map(str, v)) for v in TRI_V + [(1.0, 1.0, 0.5)]]
    lines += ["4 0 1 4 2", "3 0 2 3", "4 0 3 4 1"]
    return "\n".join(lines).encode()  # no final newline


def _ply_ascii_quads():
    return _ply_ascii().replace(b"element face 4", b"element face 3").replace(b"3 0 1 2\n3 0 2 3\n", b"4 0 1 2 3\n")


TRI_N = [(0.1, -0.5, 1.0), (1.0, 0.0, 0.0), (0.0, 2.5, 0.0), (-0.3, 0.2, 0.9)]
TRI_C = [(255, 0, 10, 128), (0, 255, 3, 255), (7, 8, 255, 0), (40, 90, 200, 17)]
_ATTRIBUTE_PROPERTIES = ["property float nx", "property float ny", "property float nz", "property uchar red",
                         "property uchar green", "property uchar blue", "property uchar alpha"]


def _ply_ascii_attributes():
    """Vertex normals and RGBA colours, quads and triangles: the attribute tables' rules."""
    lines = ["ply", "format ascii 1.0", f"element vertex {len(TRI_V)}", "property float x", "property float y",
             "property float z", *_ATTRIBUTE_PROPERTIES, "element face 3", "property list uchar int vertex_indices",
             "end_header"]
    lines += [" ".join(map(str, v + n + c)) for v, n, c in zip(TRI_V, TRI_N, TRI_C)]
    lines += ["4 0 1 2 3", "3 0 3 1", "3 1 3 2"]
    return ("\n".join(lines) + "\n").encode()


def _ply_binary_attributes():
    """Big-endian, double normals, float colours (scaled by trimesh) without alpha."""
    head = ["ply", "format binary_big_endian 1.0", f"element vertex {len(TRI_V)}", "property float x",
            "property float y", "property float z", "property double nx", "property double ny", "property double nz",
            "property float red", "property float green", "property float blue", f"element face {len(TRI_F)}",
            "property list uchar int vertex_indices", "end_header"]
    body = b"".join(struct.pack(">3f3d3f", *v, *n, *(x / 200 for x in c[:3])) for v, n, c in zip(TRI_V, TRI_N, TRI_C))
    body += b"".join(struct.pack(">B3i", 3, *f) for f in TRI_F)
    return ("\n".join(head) + "\n").encode() + body


def _glb():
    """Nested nodes (matrix and TRS), a mesh placed twice, a mesh of two primitives,
    interleaved positions and u16 indices: the fast GLB reader's harder rules."""
    g = GLB()
    quads = [(0, 1, 2), (2, 1, 4)]
    g.doc["meshes"] = [{"name": "tet", "primitives": [g.primitive(TRI_V, TRI_F, 5123, 4)]},
                       {"primitives": [g.primitive(TRI_V, TRI_F[:2]), g.primitive(TRI_V + [(1.0, 1.0, 0.5)], quads)]}]
    g.doc["nodes"] = [{"name": "root", "translation": [1, 0, 0], "rotation": [0, 0, 0.38, 0.92], "children": [1, 2]},
                      {"mesh": 0, "scale": [1, 2, 1]},
                      {"mesh": 1, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 2, 1]}, {"mesh": 0}]
    g.doc["scenes"] = [{"nodes": [0, 3]}]
    return g.bytes()


SEEDS = {
    "ply-ascii": ("ply", _ply_ascii()),
    "ply-ascii-quads": ("ply", _ply_ascii_quads()),
    "obj-split": ("obj", _obj_split()),
    "off-quads": ("off", _off_quads()),
    "ply-binary": ("ply", _ply_binary()),
    "obj": ("obj", _obj()),
    "stl-ascii": ("stl", _stl_ascii()),
    "stl-binary": ("stl", _stl_binary()),
    "off": ("off", _off()),
    "glb": ("glb", _glb()),
    "ply-ascii-attributes": ("ply", _ply_ascii_attributes()),
    "ply-binary-attributes": ("ply", _ply_binary_attributes()),
    "obj-uv": ("obj", _obj_uv()),
}

# Tokens that break parsers: special floats, huge and negative counts and indices, odd bytes.
TOKENS = [b"nan", b"-nan", b"inf", b"-inf", b"1e308", b"1e-320", b"-1", b"0", b"4294967295", b"2147483648",
          b"99999999999999999999", b"-2147483649", b"3.5", b"", b" ", b"\n", b"\r\n", b"\0", b"\xff\xfe",
          b"end_header\n", b"element vertex 1000000000\n", b"property list uchar int vertex_indices\n",
          b"property double w\n", b"format binary_big_endian 1.0\n", b"f 1 2\n", b"f -5 -6 -7\n",
          b"f 1/2/3/4 5\n", b"v 1 2\n", b"solid\n", b"facet normal\n", b"OFF\n", b"3 0 0 0\n", b"255 1 2 3\n",
          b"\xff\xff\xff\x7f", b"\xff\xff\xff\xff", b"\x00\x00\xc0\x7f", b"\x00\x00\x80\x7f"]

# 32-bit patterns for binary bodies: NaN, inf, huge, denormal, negative and huge ints.
WORDS = [0x7FC00000, 0x7F800000, 0xFF800000, 0x7F7FFFFF, 0x00000001, 0xFFFFFFFF, 0x7FFFFFFF, 0x80000000, 0]


def mutate(data: bytes, ops) -> bytes:
    """Apply mutation ops (tuples of small ints and chosen tokens) to ``data``."""
    b = bytearray(data)
    for op in ops:
        kind, pos, arg = op
        n = len(b)
        p = pos % (n + 1) if n else 0
        if kind == 0:  # flip a bit
            if n:
                b[p % n] ^= 1 << (arg % 8)
        elif kind == 1:  # truncate
            del b[p:]
        elif kind == 2:  # insert a token
            b[p:p] = TOKENS[arg % len(TOKENS)]
        elif kind == 3:  # overwrite with a token
            t = TOKENS[arg % len(TOKENS)]
            b[p : p + len(t)] = t
        elif kind == 4:  # overwrite 4 bytes with a special 32-bit word
            b[p : p + 4] = struct.pack("<I", WORDS[arg % len(WORDS)])
        elif kind == 5:  # delete a run
            del b[p : p + 1 + arg % 16]
        elif kind == 6:  # duplicate a run
            b[p:p] = b[p : p + 1 + arg % 64]
        elif kind == 7:  # replace a whole line-ish region with random-looking bytes
            b[p : p + 1 + arg % 8] = bytes((arg * 37 + i * 101) % 256 for i in range(1 + arg % 8))
        elif kind == 8:  # a long line: spaces, digits or a run of one token
            filler = (b" ", b"7", b"1/2/3 ", b"0.5 ")[arg % 4]
            b[p:p] = filler * (1000 + 97 * (arg % 1000)) + b"\n"
        elif kind == 9:  # a huge or extreme index where a number was
            b[p:p] = (b" 2147483647", b" -2147483648", b" 2147483648", b" 18446744073709551616", b" -0")[arg % 5]
        elif kind == 10:  # deep backslash continuations
            b[p:p] = (b"\\\n", b"\\\r\n", b"\\")[arg % 3] * (1 + arg % 5000)
        elif kind == 11:  # a number of 10^5 digits
            b[p:p] = (b"1" * 100000, b"0." + b"0" * 100000 + b"1", b"9" * 50000 + b"e-50000")[arg % 3]
        elif kind == 12:  # a GLB's JSON: one field set to an odd value (an offset, length, stride, count, ...)
            b = bytearray(_glb_field(bytes(b), pos, arg))
    return bytes(b)


ODD_VALUES = [-1, 0, 1, 2, 3, 4, 5, 7, 12, 255, 65535, 2**31, 2**32 + 4, 2**63, 1e300, 0.5, float("nan"), None, "x",
              [], {}, True, "world", [0, 0], {"uri": "x.bin"}]


def _glb_field(data, pos, arg):
    """A GLB with one leaf of its JSON replaced by an odd value and the chunk lengths made
    to fit the new JSON; bytes that are not a GLB with a parseable JSON are returned as they are."""
    if len(data) < 20 or data[:4] != b"glTF":
        return data
    size = struct.unpack_from("<I", data, 12)[0]
    try:
        doc = json.loads(data[20 : 20 + size])
    except ValueError:
        return data
    leaves = []

    def walk(node):
        for key in (range(len(node)) if isinstance(node, list) else node.keys() if isinstance(node, dict) else ()):
            leaves.append((node, key))
            walk(node[key])

    walk(doc)
    if not leaves:
        return data
    node, key = leaves[pos % len(leaves)]
    node[key] = ODD_VALUES[arg % len(ODD_VALUES)]
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = data[20 + size :]
    return struct.pack("<4sII", b"glTF", 2, 20 + len(text) + len(rest)) + struct.pack("<I4s", len(text), b"JSON") + text + rest


def random_ops(rng: np.random.Generator, max_ops=4):
    k = int(rng.integers(1, max_ops + 1))
    return [(int(rng.integers(0, MUTATIONS)), int(rng.integers(0, 1 << 16)), int(rng.integers(0, 1 << 16)))
            for _ in range(k)]


MUTATIONS = 13  # kinds of op in mutate()


def fast_read(path, suffix, smooth=False, color=False, uv=False):
    """What the fast reader of ``suffix`` (the loader table's) makes of the file at ``path``
    (loading.fast.read_file), or None when it hands the file to trimesh."""
    from scatter_cli.loading import fast
    from scatter_cli.loading.load import LOADERS

    return fast.read_file(path, LOADERS[suffix].fast, smooth, color, uv)


def differential(data: bytes, suffix: str, workdir) -> str:
    """Where the fast reader answers for ``data``, check it against trimesh.

    Returns 'handed' (the fast reader gave the file to trimesh) or 'same' (it answered,
    and trimesh loads the same world-space triangles in the same order); raises
    AssertionError when they differ or when trimesh rejects what the fast reader read.
    """
    import os

    from scatter_cli.errors import ScatterError
    from scatter_cli.loading.load import load_surface

    path = os.path.join(workdir, f"diff.{suffix}")
    with open(path, "wb") as f:
        f.write(data)
    if fast_read(path, suffix) is None:
        return "handed"
    try:
        fast = load_surface(path, plain=True)
    except ScatterError as exc:  # the arrays fail scatter's checks: so must trimesh's
        try:
            load_surface(path)
        except ScatterError:
            return "same"
        raise AssertionError(f"only the fast reader's arrays were rejected: {exc}") from None
    try:
        slow = load_surface(path)
    except ScatterError as exc:
        raise AssertionError(f"the fast reader read a file trimesh rejects: {exc}") from None
    a = [fast.world_vertices(i)[fast.geometries[i.geometry].faces] for i in fast.instances]
    b = [slow.world_vertices(i)[slow.geometries[i.geometry].faces] for i in slow.instances]
    if len(a) != len(b) or any(x.shape != y.shape or x.tobytes() != y.tobytes() for x, y in zip(a, b)):
        raise AssertionError("the fast reader and trimesh give different triangles")
    if suffix in ("ply", "obj"):
        _same_attributes(path, suffix, slow)
    return "same"


def _same_attributes(path, suffix, slow):
    """Where the fast PLY or OBJ reader also answers for its attributes (PLY normals and
    colours, OBJ UVs and normals), the sampled values are trimesh's (or both paths fail
    alike)."""
    import scatter_cli
    from scatter_cli.errors import ScatterError

    other = "color" if suffix == "ply" else "uv"
    if fast_read(path, suffix, smooth=True, **{other: True}) is None:
        return
    for attributes in ("smooth-normal", other, f"face,bary,{other},smooth-normal"):
        got = []
        for source in (path, slow):
            try:
                s = scatter_cli.sample(source, count=200, seed=3, attributes=attributes)
                got.append(s.points.tobytes() + b"".join(v.tobytes() for v in s.attributes.values()))
            except ScatterError as exc:
                got.append(str(exc))
        if got[0] != got[1]:
            raise AssertionError(f"the fast reader and trimesh give different '{attributes}'")


def exercise(data: bytes, suffix: str, workdir) -> str:
    """Load ``data`` as a ``suffix`` file and plan and draw a few points.

    Returns 'ok' or 'error' (a ScatterError); any other exception propagates.
    """
    import os

    from scatter_cli.api import prepare
    from scatter_cli.errors import ScatterError

    path = os.path.join(workdir, f"fuzz.{suffix}")
    with open(path, "wb") as f:
        f.write(data)
    try:
        run = prepare(path, 20, attributes=("face", "bary", "normal"), seed=1)
        s = run.collect()
        if not np.isfinite(s.points).all():
            raise AssertionError("non-finite point from a loaded mesh")
        return "ok"
    except ScatterError:
        return "error"
