"""The fast GLB reader (scatter_cli/loading/gltf.py) gives what trimesh's scene load gives.

Per placed geometry: the same world-space triangles, corners in the same order, the
instances in the same order, and the same sampled bytes (face, bary, object); or it
hands the file to trimesh. The files are built field by field (testkit/gltfwrite.py), so
that the reader is checked on layouts trimesh's exporter never writes.
"""

import numpy as np
import pytest

import scatter_cli
from scatter_cli.loading.load import load_surface
from testkit.fuzz_inputs import fast_read
from testkit.gltfwrite import GLB

from .conftest import run_scatter
from .test_readers import world_corners

TETRA_V = [[0, 0, 0], [1, 0, 0], [0, 1.5, 0], [0.2, 0.1, 2]]
TETRA_F = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]
PRISM_V = [[0, 0, 0], [2, 0, 0], [0, 1, 0], [0, 0, 1], [2, 0, 1], [0, 1, 1]]
PRISM_F = [[0, 2, 1], [3, 4, 5], [0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [0, 3, 5], [0, 5, 2]]
ROT = [0.2, -0.4, 0.1, 0.8]  # x, y, z, w: not of unit length, as trimesh allows


def rotation_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def column_major(m):
    return np.asarray(m, dtype=np.float64).T.ravel().tolist()


def build(meshes, nodes, roots, **extra):
    """meshes: lists of primitive arguments for GLB.primitive; nodes: node dicts."""
    g = GLB()
    g.doc["meshes"] = [{"primitives": [g.primitive(*p) if isinstance(p, tuple) else g.primitive(**p) for p in m]}
                       for m in meshes]
    g.doc["nodes"] = nodes
    g.doc["scenes"] = [{"nodes": roots}]
    g.doc["scene"] = 0
    g.doc.update(extra)
    return g


def case_nested_trs():
    nodes = [{"name": "root", "translation": [1, 2, 3], "rotation": ROT, "scale": [2, 1, 0.5], "children": [1, 2]},
             {"name": "arm", "matrix": column_major(rotation_z(0.3) @ np.diag([1, 3, 1, 1])), "children": [2 + 1]},
             {"name": "leaf", "mesh": 0, "translation": [0, 0, 1]},
             {"name": "hand", "mesh": 1, "matrix": column_major(rotation_z(-1.1)), "translation": [5, 0, 0],
              "rotation": [0, 0, 0.3826834, 0.9238795]}]
    return build([[(TETRA_V, TETRA_F)], [(PRISM_V, PRISM_F)]], nodes, [0])


def case_instanced():
    nodes = [{"mesh": 0}, {"mesh": 0, "translation": [3, 0, 0]}, {"mesh": 1, "scale": [1, 1, -1], "children": [3]},
             {"mesh": 0, "rotation": [0, 0.7071068, 0, 0.7071068]}]
    return build([[(TETRA_V, TETRA_F)], [(PRISM_V, PRISM_F)]], nodes, [0, 1, 2])


def case_primitives():
    nodes = [{"name": "a", "mesh": 0, "rotation": ROT}, {"name": "b", "mesh": 0}, {"name": "c", "mesh": 1}]
    prims = [(TETRA_V, TETRA_F), (PRISM_V, PRISM_F), (np.array(TETRA_V) + 5, TETRA_F[::-1])]
    return build([prims, [(PRISM_V, PRISM_F)]], nodes, [0, 1, 2])


def case_layouts():
    """Interleaved positions (byteStride), u8 and u16 indices, no indices at all."""
    unindexed = np.array(PRISM_V, dtype=float)[np.array(PRISM_F).ravel()]
    meshes = [[{"vertices": TETRA_V, "faces": TETRA_F, "index_component": 5121, "pad": 12}],
              [{"vertices": PRISM_V, "faces": PRISM_F, "index_component": 5123, "pad": 4}],
              [{"vertices": unindexed}]]
    nodes = [{"mesh": k, "translation": [2.0 * k, 0, 0]} for k in range(3)]
    return build(meshes, nodes, [0, 1, 2])


def case_near_identity():
    """Matrices within 1e-8 of identity: trimesh keeps a root's, drops them down a path."""
    tiny = np.eye(4)
    tiny[0, 3] = 3e-9
    nodes = [{"matrix": column_major(tiny), "children": [1, 2]}, {"mesh": 0, "matrix": column_major(tiny)},
             {"mesh": 1, "translation": [1e-9, 0, 0]}, {"mesh": 0, "matrix": column_major(tiny)}]
    return build([[(TETRA_V, TETRA_F)], [(PRISM_V, PRISM_F)]], nodes, [0, 3])


def case_nearly_rigid():
    """A rotation off by 1e-7: trimesh repairs such a matrix by SVD."""
    m = rotation_z(0.7)
    m[:3, :3] *= 1 + 1e-7
    m[:3, 3] = [1, 2, 3]
    nodes = [{"matrix": column_major(m), "mesh": 0}, {"children": [2], "translation": [0, 1, 0]},
             {"matrix": column_major(m), "mesh": 1}]
    return build([[(TETRA_V, TETRA_F)], [(PRISM_V, PRISM_F)]], nodes, [0, 1])


def case_names_and_scenes():
    """Repeated and suffixed names; the second of two scenes, its roots out of order."""
    g = build([[(TETRA_V, TETRA_F)], [(PRISM_V, PRISM_F)], [(TETRA_V, TETRA_F[:2])]],
              [{"name": "n", "mesh": 0}, {"name": "n", "mesh": 1}, {"name": "n_1", "mesh": 2},
               {"mesh": 0, "children": [0]}, {"name": "unused", "mesh": 1}], [4])
    for mesh, name in zip(g.doc["meshes"], ["part", "part", "part_1"]):
        mesh["name"] = name
    g.doc["scenes"] = [{"nodes": [4]}, {"nodes": [2, 1, 3]}]
    g.doc["scene"] = 1
    return g


CASES = {f.__name__[5:]: f for f in [case_nested_trs, case_instanced, case_primitives, case_layouts,
                                      case_near_identity, case_nearly_rigid, case_names_and_scenes]}


@pytest.mark.parametrize("case", sorted(CASES))
def test_scenes_load_and_sample_as_with_trimesh(case, tmp_path):
    path = tmp_path / "scene.glb"
    path.write_bytes(CASES[case]().bytes())
    assert fast_read(path, "glb") is not None
    fast, slow = load_surface(path, plain=True), load_surface(path)
    a, b = world_corners(fast), world_corners(slow)
    assert len(a) == len(b) and all(x.tobytes() == y.tobytes() for x, y in zip(a, b))
    assert [i.name for i in fast.instances] == [i.name for i in slow.instances]  # trimesh's random ones renamed
    assert [g.name for g in fast.geometries] == [g.name for g in slow.geometries]
    assert [i.geometry for i in fast.instances] == [i.geometry for i in slow.instances]
    x = scatter_cli.sample(path, count=2000, seed=3, attributes="face,bary,object")
    y = scatter_cli.sample(slow, count=2000, seed=3, attributes="face,bary,object")
    assert x.points.tobytes() == y.points.tobytes()
    for k in ("face", "bary", "object"):
        assert x.attributes[k].tobytes() == y.attributes[k].tobytes()


def test_the_fast_path_keeps_each_instance_transform():
    """Not only the same as trimesh: the reader's own matrices place the mesh, one
    geometry for two nodes, the last root first (trimesh's walk pops the last edge)."""
    g = build([[(TETRA_V, TETRA_F)]], [{"mesh": 0}, {"mesh": 0, "translation": [3, 0, 0]}], [0, 1])
    geometries, instances = read_mesh_bytes(g.bytes())
    assert len(geometries) == 1 and [i[1] for i in instances] == [0, 0] and instances[1][2] is None
    assert np.array_equal(instances[0][2], [[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    assert np.array_equal(geometries[0][1], np.array(TETRA_V, dtype=np.float32).astype(np.float64))


def read_mesh_bytes(data):
    from scatter_cli.loading.gltf import read_glb

    return read_glb(data)


def handed(mutate):
    g = case_instanced()
    mutate(g.doc)
    return g.bytes()


def draco(doc):
    doc["meshes"][0]["primitives"][0]["extensions"] = {"KHR_draco_mesh_compression": {"bufferView": 0}}


HANDED_OFF = {
    "draco": lambda d: draco(d),
    "sparse accessor": lambda d: d["accessors"][0].update(sparse={"count": 1}),
    "bufferless accessor": lambda d: d["accessors"][0].pop("bufferView"),
    "triangle strip": lambda d: d["meshes"][0]["primitives"][0].update(mode=5),
    "lines": lambda d: d["meshes"][1]["primitives"][0].update(mode=1),
    "camera": lambda d: d["nodes"][0].update(camera=0),
    "two parents": lambda d: d["nodes"][0].update(children=[3]),
    "cycle": lambda d: d["nodes"][3].update(children=[2]),
    "its own child": lambda d: d["nodes"][2].update(children=[3, 2]),
    "external buffer": lambda d: d["buffers"][0].update(uri="data.bin"),
    "view past the buffer": lambda d: d["bufferViews"][1].update(byteOffset=1 << 20),
    "accessor past its view": lambda d: d["accessors"][1].update(byteOffset=4),
    "stride 0": lambda d: d["bufferViews"][0].update(byteStride=0),
    "float indices": lambda d: d["accessors"][1].update(componentType=5126),
    "index count not a multiple of 3": lambda d: d["accessors"][1].update(count=11),
    "count 0": lambda d: d["accessors"][0].update(count=0),
    "integer positions": lambda d: d["accessors"][0].update(componentType=5123),
    "a node named world": lambda d: d["nodes"][1].update(name="world"),
    "no scenes": lambda d: d.pop("scenes"),
    "child out of range": lambda d: d["nodes"][2].update(children=[9]),
    "negative mesh index": lambda d: d["nodes"][0].update(mesh=-1),
    "short translation": lambda d: d["nodes"][1].update(translation=[3, 0]),
    "material out of range": lambda d: d["meshes"][0]["primitives"][0].update(material=0),
    "mesh without primitives": lambda d: d["meshes"].append({"name": "x"}),
}


@pytest.mark.parametrize("case", sorted(HANDED_OFF))
def test_what_the_reader_is_not_sure_of_goes_to_trimesh(case):
    assert read_mesh_bytes(handed(lambda d: None)) is not None  # the unmutated file is read
    assert read_mesh_bytes(handed(HANDED_OFF[case])) is None


@pytest.mark.parametrize("cut", [0, 12, 20, 60, -8, -1])
def test_cut_files_go_to_trimesh(cut):
    data = case_instanced().bytes()
    assert read_mesh_bytes(data[:cut]) is None



@pytest.mark.slow
def test_a_node_graph_trimesh_cannot_walk_is_a_one_line_error(tmp_path):
    """A fuzz finding: a node among its own children made trimesh's graph walk raise."""
    path = tmp_path / "bad.glb"
    path.write_bytes(handed(HANDED_OFF["its own child"]))
    proc = run_scatter("sample", path, "-n", "100", "-o", tmp_path / "out.ply")
    err = proc.stderr.decode()
    assert proc.returncode == 1 and err.count("\n") == 1 and err.startswith("error: ") and str(path) in err


def test_a_primitive_with_normals_goes_to_trimesh_when_smooth_normals_are_wanted():
    from scatter_cli.loading.gltf import read_glb

    g = case_instanced()
    g.doc["meshes"][1]["primitives"][0]["attributes"]["NORMAL"] = g.add(np.ones((6, 3), dtype="<f4"), 5126, "VEC3")
    data = g.bytes()
    assert read_glb(data) is not None and read_glb(data, without_normals=True) is None
    assert read_glb(case_instanced().bytes(), without_normals=True) is not None
