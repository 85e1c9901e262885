"""The objects of a scene get the same names, in the same order, on every run: in
`scatter info`, for --object and as object_index, whichever reader loads the file. A glTF
mesh of several primitives is the case that needs it: trimesh names each primitive's frame
with a random suffix, scatter names it NODE_K by its place in the file."""

import numpy as np
import pytest

import scatter_cli
from scatter_cli.commands.info import describe
from scatter_cli.loading import load
from scatter_cli.loading.load import load_surface
from testkit.gltfwrite import GLB

from .batchtools import sample_in_process
from .conftest import SAMPLES, run_scatter

TRUCK = SAMPLES / "cesiummilktruck.glb"  # node 0 places a mesh of three primitives; nodes 2 and 4 are unnamed
TETRA_V = [[0, 0, 0], [1, 0, 0], [0, 1.5, 0], [0.2, 0.1, 2]]
TETRA_F = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]


def clashing_scene(path):
    """Unnamed nodes, a named one, meshes of two and three primitives, and a node named as
    a primitive's frame would be (``a_1``): the fast reader hands it to trimesh."""
    g = GLB()
    prims = [g.primitive(np.array(TETRA_V) + k, TETRA_F) for k in range(3)]
    g.doc["meshes"] = [{"primitives": prims}, {"primitives": prims[:2]}, {"primitives": prims[:1]}]
    g.doc["nodes"] = [{"name": "a", "mesh": 0}, {"mesh": 1, "translation": [4, 0, 0]}, {"name": "a_1", "mesh": 2},
                      {"mesh": 1, "children": [0]}]
    g.doc["scenes"] = [{"nodes": [1, 2, 3]}]
    g.doc["scene"] = 0
    path.write_bytes(g.bytes())
    return path


def names(path, **options):
    return [(i.name, s.geometries[i.geometry].name) for s in [load_surface(path, **options)] for i in s.instances]


@pytest.fixture(params=["truck", "clashing"])
def scene(request, tmp_path):
    return TRUCK if request.param == "truck" else clashing_scene(tmp_path / "scene.glb")


@pytest.mark.parametrize("broken", [False, True])
def test_every_load_names_the_objects_alike(scene, monkeypatch, broken):
    """Two loads through trimesh, and one by the fast reader where it reads the file: the
    same names in the same order. The broken variant keeps trimesh's random names."""
    if broken:
        monkeypatch.setattr("scatter_cli.loading.gltf.primitive_frames", lambda graph: {})
    first, second = names(scene), names(scene)
    assert (first == second) != broken, (first, second)
    if not broken:
        assert len({n for n, _ in first}) == len(first)  # no two objects share a name
        assert names(scene, plain=True) == first  # the fast reader's (the clashing scene: trimesh's again)


def test_the_truck_names_its_primitives_by_their_place():
    assert [n for n, _ in names(TRUCK)] == ["0_0", "0_1", "0_2", "2", "4"]


def test_info_object_and_object_index_agree(scene):
    """Each object `info` lists, asked for by its name, is sampled alone and written with
    the index info gives it."""
    listed = describe(str(scene))["objects"]
    assert [o["index"] for o in listed] == list(range(len(listed)))
    for o in listed:
        s = scatter_cli.sample(scene, 50, objects=[o["name"]], attributes="object")
        assert set(s.object.tolist()) == {o["index"]}, o


@pytest.mark.slow
def test_a_name_listed_by_one_run_selects_in_the_next(tmp_path):
    """What the issue saw: `scatter info` in one process, `--object` in another (this one)."""
    import json

    listed = json.loads(run_scatter("info", TRUCK, "--json", check=True).stdout)["objects"]
    assert [o["name"] for o in listed] == [o["name"] for o in describe(str(TRUCK))["objects"]]
    out = tmp_path / "one.csv"
    sample_in_process(["sample", str(TRUCK), "-n", "20", "--object", listed[1]["name"], "-a", "object", "-o", str(out)])
    rows = out.read_text().splitlines()[1:]
    assert {int(r.rsplit(",", 1)[1]) for r in rows} == {listed[1]["index"]}


def test_only_gltf_files_are_renamed(monkeypatch):
    """The renaming applies to glTF scenes trimesh loads, not to a scene the caller made."""
    import trimesh

    calls = []
    monkeypatch.setattr("scatter_cli.loading.gltf.primitive_frames", lambda graph: calls.append(1) or {})
    scene = trimesh.Scene([trimesh.creation.box(), trimesh.creation.icosphere()])
    load_surface(scene)
    load_surface(SAMPLES / "koala.obj")
    assert not calls
    load_surface(TRUCK)
    assert calls and load.GLTF_FORMATS == ("glb", "gltf")
