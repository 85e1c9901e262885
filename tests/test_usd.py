"""USD stages as input: world transforms, scene-graph instancing and point instancers
(geometry stored once), --object by prim path, primvars for uv / color / smooth-normal.

The stage is written here with usd-core and compared with an equivalent GLB written by
testkit/gltfwrite.py, whose node matrices are worked out by hand from the authored ops:
per-object counts (two-sample chi-square) and each coordinate (two-sample KS), every
test at significance ALPHA, each paired with wrong-transform GLBs that must fail.
"""

import os

import numpy as np
import pytest
import trimesh
from scipy import stats

import scatter_cli
from scatter_cli.errors import ScatterError, ScatterUsageError
from scatter_cli.commands.info import describe
from scatter_cli.loading.load import load_surface
from scatter_cli.stats.chisquare import chi2_two_sample

from .conftest import run_scatter
from testkit.gltfwrite import glb_bytes

pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom, Vt  # noqa: E402

ALPHA = 1e-3
NAMES = ["/W/cube", "/W/rock_a/geo", "/W/rock_b/geo", "/W/trees[0]/cone", "/W/trees[1]/cone", "/W/trees[2]/cone"]


def T(x, y, z):
    m = np.eye(4)
    m[:3, 3] = [x, y, z]
    return m


def S(x, y, z):
    return np.diag([x, y, z, 1.0])


def Rz(deg):
    return trimesh.transformations.rotation_matrix(np.radians(deg), [0, 0, 1])


def fan(counts, holes=()):
    """The documented triangulation, polygon by polygon: positions in faceVertexIndices."""
    tri, s = [], 0
    for k, c in enumerate(counts):
        if k not in holes:
            tri += [(s, s + j + 1, s + j + 2) for j in range(c - 2)]
        s += c
    return np.array(tri, dtype=np.int64).reshape(-1, 3)


def quad_cube():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    quads = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
    return v, quads


def define_mesh(stage, path, vertices, polygons):
    """A Mesh prim; polygons: (P, c) array or list of index lists."""
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(vertices, dtype=np.float32)))
    mesh.CreateFaceVertexCountsAttr([len(p) for p in polygons])
    mesh.CreateFaceVertexIndicesAttr([int(i) for p in polygons for i in p])
    mesh.CreateSubdivisionSchemeAttr("none")
    return mesh


def _meshes():
    cube_v, quads = quad_cube()
    rock = trimesh.creation.icosphere(subdivisions=1)
    cone = trimesh.creation.cone(0.5, 1.5, sections=8)
    return (cube_v, quads), (rock.vertices, rock.faces), (cone.vertices, cone.faces)


POSITIONS = [(0, 0, 0), (3, 0, 0), (6, 0, 0), (9, 0, 0)]
ORIENT = [(1, 0, 0, 0), (0, 0, 0, 1), (0, 1, 0, 0), (1, 0, 0, 0)]  # (w, x, y, z): exact in half floats
SCALES = [(1, 1, 1), (2, 2, 2), (1, 1, 3), (1, 1, 1)]


def write_stage(path):
    """/W (moved) holds a transformed quad cube, two instances of a rock (one mirrored)
    and a point instancer of cones (four instances, the last one hidden by invisibleIds)."""
    (cube_v, quads), (rock_v, rock_f), (cone_v, cone_f) = _meshes()
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Xformable(UsdGeom.Xform.Define(stage, "/W")).AddTranslateOp().Set((1, 2, 3))
    cube = UsdGeom.Xformable(define_mesh(stage, "/W/cube", cube_v, quads))
    cube.AddTranslateOp().Set((5, 0, 0))
    cube.AddRotateZOp().Set(30)
    cube.AddScaleOp().Set((2, 1, 0.5))
    stage.CreateClassPrim("/_lib")
    stage.DefinePrim("/_lib/rock", "Xform")
    UsdGeom.Xformable(define_mesh(stage, "/_lib/rock/geo", rock_v, rock_f)).AddTranslateOp().Set((0, 0, 1))
    for name, ops in (("rock_a", [(0, -5, 0)]), ("rock_b", [(0, -9, 0), (-1, 2, 1)])):
        prim = stage.DefinePrim(f"/W/{name}", "Xform")
        prim.GetReferences().AddInternalReference("/_lib/rock")
        prim.SetInstanceable(True)
        UsdGeom.Xformable(prim).AddTranslateOp().Set(ops[0])
        if len(ops) > 1:
            UsdGeom.Xformable(prim).AddScaleOp().Set(ops[1])
    trees = UsdGeom.PointInstancer.Define(stage, "/W/trees")
    UsdGeom.Xformable(trees).AddTranslateOp().Set((0, 0, -4))
    cone = define_mesh(stage, "/W/trees/protos/cone", cone_v, cone_f)
    UsdGeom.Xformable(cone).AddTranslateOp().Set((0, 0, 0.5))
    trees.CreatePrototypesRel().SetTargets([cone.GetPath()])
    trees.CreateProtoIndicesAttr([0] * 4)
    trees.CreatePositionsAttr(POSITIONS)
    trees.CreateOrientationsAttr([Gf.Quath(*q) for q in ORIENT])
    trees.CreateScalesAttr(SCALES)
    trees.CreateInvisibleIdsAttr([3])
    stage.GetRootLayer().Save()
    return path


def quat_matrix(w, x, y, z):
    return trimesh.transformations.quaternion_matrix([w, x, y, z])


def world_matrices(skip_cube_scale=False, skip_proto_xform=False):
    """Hand-composed column-vector matrices of NAMES, in that order."""
    w = T(1, 2, 3)
    cube = w @ T(5, 0, 0) @ Rz(30) @ (np.eye(4) if skip_cube_scale else S(2, 1, 0.5))
    rock_a = w @ T(0, -5, 0) @ T(0, 0, 1)
    rock_b = w @ T(0, -9, 0) @ S(-1, 2, 1) @ T(0, 0, 1)
    proto = np.eye(4) if skip_proto_xform else T(0, 0, 0.5)
    trees = [w @ T(0, 0, -4) @ T(*POSITIONS[i]) @ quat_matrix(*ORIENT[i]) @ S(*SCALES[i]) @ proto for i in range(3)]
    return [cube, rock_a, rock_b, *trees]


def write_glb(path, **wrong):
    (cube_v, quads), rock, cone = _meshes()
    cube = (cube_v, quads.ravel()[fan([4] * 6)])
    nodes = list(zip([0, 1, 1, 2, 2, 2], world_matrices(**wrong)))
    path.write_bytes(glb_bytes([cube, rock, cone], nodes))
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("usd")
    return {"usd": write_stage(d / "scene.usda"), "glb": write_glb(d / "scene.glb"),
            "glb_no_scale": write_glb(d / "no_scale.glb", skip_cube_scale=True),
            "glb_no_proto_xform": write_glb(d / "no_proto.glb", skip_proto_xform=True), "dir": d}


def test_instances_names_and_shared_geometry(files):
    surface = load_surface(files["usd"])
    assert [i.name for i in surface.instances] == NAMES
    assert [i.geometry for i in surface.instances] == [0, 1, 1, 2, 2, 2]  # stored once each
    assert [len(g.faces) for g in surface.geometries] == [12, 80, len(_meshes()[2][1])]
    for inst, m in zip(surface.instances, world_matrices()):
        np.testing.assert_allclose(inst.matrix, m, atol=1e-6)  # float32 ops


def _agreement(usd_path, glb_path, n=20_000):
    """min p-value of: per-object counts (chi-square), and KS on each coordinate."""
    a = scatter_cli.sample(usd_path, n, seed=1, attributes=["object"], precision="float64")
    b = scatter_cli.sample(glb_path, n, seed=2, attributes=["object"], precision="float64")
    glb_names = [i.name for i in load_surface(glb_path).instances]
    order = [glb_names.index(f"node{k}") for k in range(len(NAMES))]  # node k is NAMES[k]
    ca = np.bincount(a.object, minlength=len(NAMES))
    cb = np.bincount(b.object, minlength=len(NAMES))[order]
    p = [chi2_two_sample(ca, cb)[2]]
    p += [stats.ks_2samp(a.points[:, c], b.points[:, c]).pvalue for c in range(3)]
    return min(p)


def test_stage_samples_like_the_equivalent_glb(files):
    assert _agreement(files["usd"], files["glb"]) > ALPHA


@pytest.mark.parametrize("wrong", ["glb_no_scale", "glb_no_proto_xform"])
def test_must_fail_stage_against_a_wrongly_placed_glb(files, wrong):
    assert _agreement(files["usd"], files[wrong]) < ALPHA


def test_object_by_prim_path(files):
    def names(*paths):
        s = load_surface(files["usd"], objects=list(paths))
        return [i.name for i in s.instances]

    assert names("/W/trees") == NAMES[3:]
    assert names("/W/trees/protos/cone") == NAMES[3:]  # the prototype: all its instances
    assert names("/W/trees[1]") == [NAMES[4]]
    assert names("/W/rock_b", "/W/cube") == [NAMES[0], NAMES[2]]  # instance order kept
    assert names("/W/") == NAMES
    with pytest.raises(ScatterError, match="/W/nothing") as refused:  # a failure of this mesh, not a usage error
        load_surface(files["usd"], objects=["/W/nothing"])
    assert not isinstance(refused.value, ScatterUsageError)
    with pytest.raises(ScatterError):
        load_surface(files["usd"], objects=["/W/cub"])  # a prefix of a name is not a path
    s = scatter_cli.sample(files["usd"], 2_000, objects=["/W/rock_a"], attributes=["object"])
    assert set(s.object.tolist()) == {NAMES.index("/W/rock_a/geo")}  # the index `scatter info` lists
    box = np.array(world_matrices()[1])[:3, 3]
    assert np.abs(s.points - box).max() <= 1.0 + 1e-6  # on the unit icosphere at rock_a


@pytest.mark.slow
def test_info_lists_the_stage_objects(files):
    report = describe(files["usd"])
    assert report["instances"] == 6 and report["geometries"] == 3
    assert [o["name"] for o in report["objects"]] == NAMES
    proc = run_scatter("info", files["usd"])
    assert proc.returncode == 0 and "/W/trees[2]/cone" in proc.stdout.decode()


# -- primvars ---------------------------------------------------------------------------

COUNTS = [5, 2, 4, 3]  # a pentagon, a two-corner face (no triangle), a quad, a triangle
INDICES = [0, 1, 2, 3, 4, 4, 5, 1, 5, 6, 2, 6, 7, 2]
INTERP_SIZE = {"constant": 1, "uniform": 4, "vertex": 8, "faceVarying": 14}


def write_primvar_stage(path, color="vertex", st=True, normals=True, left=False, holes=()):
    rng = np.random.default_rng(5)
    points = rng.uniform(-1, 1, (8, 3))
    stage = Usd.Stage.CreateNew(str(path))
    polys = np.split(np.array(INDICES), np.cumsum(COUNTS)[:-1])
    mesh = define_mesh(stage, "/M", points, polys)
    if left:
        mesh.CreateOrientationAttr("leftHanded")
    if holes:
        mesh.CreateHoleIndicesAttr(list(holes))
    api = UsdGeom.PrimvarsAPI(mesh)
    values = {}
    if st:
        values["st"] = rng.uniform(0, 1, (14, 2))
        pv = api.CreatePrimvar("st", Sdf_type("TexCoord2fArray"), "faceVarying")
        pv.Set(Vt.Vec2fArray.FromNumpy(values["st"].astype(np.float32)))
    if color:
        values["color"] = rng.uniform(0, 1, (INTERP_SIZE[color], 3))
        mesh.CreateDisplayColorPrimvar(color).Set(Vt.Vec3fArray.FromNumpy(values["color"].astype(np.float32)))
    if normals:
        n = np.array([0, 0, 1.0]) + rng.uniform(-0.3, 0.3, (14, 3))
        values["normals"] = n / np.linalg.norm(n, axis=1, keepdims=True)
        mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(values["normals"].astype(np.float32)))
        mesh.SetNormalsInterpolation("faceVarying")
    stage.GetRootLayer().Save()
    values = {k: v.astype(np.float32).astype(np.float64) for k, v in values.items()}
    return points.astype(np.float32).astype(np.float64), values


def Sdf_type(name):
    from pxr import Sdf

    return getattr(Sdf.ValueTypeNames, name)


def _corner_rows(face, holes=()):
    """(n, 3) positions in faceVertexIndices of the corners of each sampled face."""
    return fan(COUNTS, holes)[face]


@pytest.mark.parametrize("color", ["constant", "uniform", "vertex", "faceVarying"])
def test_primvars_interpolate_at_the_points(tmp_path, color):
    path = tmp_path / "m.usda"
    points, values = write_primvar_stage(path, color=color)
    s = scatter_cli.sample(path, 3_000, seed=4, attributes=["face", "bary", "uv", "color", "smooth-normal"],
                           precision="float64")
    corners = _corner_rows(s.face)
    b = s.bary[:, :, None]
    np.testing.assert_allclose(s.points, (points[np.array(INDICES)[corners]] * b).sum(1), atol=1e-12)
    np.testing.assert_allclose(s.uv, (values["st"][corners] * b).sum(1), atol=1e-12)
    n = (values["normals"][corners] * b).sum(1)
    np.testing.assert_allclose(s.normal, n / np.linalg.norm(n, axis=1, keepdims=True), atol=1e-9)
    polygon = np.repeat(np.arange(4), COUNTS)[corners[:, 0]]
    rgb = {"constant": lambda: np.broadcast_to(values["color"][0], (len(s.face), 3)),
           "uniform": lambda: values["color"][polygon],
           "vertex": lambda: (values["color"][np.array(INDICES)[corners]] * b).sum(1),
           "faceVarying": lambda: (values["color"][corners] * b).sum(1)}[color]()
    assert np.abs(s.color[:, :3].astype(float) - rgb * 255).max() <= 0.5 + 1e-6
    assert (s.color[:, 3] == 255).all()
    assert len(load_surface(path).geometries[0].faces) == 6  # pentagon 3, two-corner face 0, quad 2, triangle 1


def test_holes_and_degenerate_faces_give_no_triangles(tmp_path):
    path = tmp_path / "m.usda"
    points, _ = write_primvar_stage(path, holes=(0,))
    g = load_surface(path).geometries[0]
    np.testing.assert_array_equal(g.vertices[g.faces], points[np.array(INDICES)[fan(COUNTS, holes=(0,))]])
    assert len(g.faces) == 3  # quad 2 + triangle 1; the pentagon is a hole, the two-corner face none


def test_left_handed_meshes_flip_the_face_normal(tmp_path):
    write_primvar_stage(tmp_path / "r.usda")
    write_primvar_stage(tmp_path / "l.usda", left=True)
    right, left = (load_surface(tmp_path / n).geometries[0] for n in ("r.usda", "l.usda"))
    np.testing.assert_array_equal(left.faces, right.faces[:, [0, 2, 1]])  # same triangles, other winding
    s = scatter_cli.sample(tmp_path / "l.usda", 500, seed=1, attributes=["normal", "face"], precision="float64")
    tri = right.vertices[right.faces[s.face]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    np.testing.assert_allclose(s.normal, -n / np.linalg.norm(n, axis=1, keepdims=True), atol=1e-9)


def test_computed_normals_are_smooth_across_uv_seams(tmp_path):
    # Face-varying st makes one vertex per corner; normals computed without authored ones
    # must still be the welded mesh's (equal to the same stage without st).
    write_primvar_stage(tmp_path / "a.usda", st=True, normals=False, color=None)
    write_primvar_stage(tmp_path / "b.usda", st=False, normals=False, color=None)
    a = scatter_cli.sample(tmp_path / "a.usda", 2_000, seed=1, attributes=["smooth-normal"], precision="float64")
    b = scatter_cli.sample(tmp_path / "b.usda", 2_000, seed=1, attributes=["smooth-normal"], precision="float64")
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_allclose(a.normal, b.normal, atol=1e-12)
    flat = scatter_cli.sample(tmp_path / "b.usda", 2_000, seed=1, attributes=["normal"], precision="float64")
    assert np.abs(a.normal - flat.normal).max() > 0.1  # interpolated, not the face normal


def test_missing_primvar_is_an_attribute_error(tmp_path):
    write_primvar_stage(tmp_path / "m.usda", st=False)
    with pytest.raises(ScatterError, match="cannot write attribute 'uv'"):
        scatter_cli.sample(tmp_path / "m.usda", 10, attributes=["uv"])


def test_chunk_size_and_threads_change_no_byte(files, tmp_path, monkeypatch):
    path = tmp_path / "m.usda"
    write_primvar_stage(path, color="faceVarying")
    for stage, names in ((path, ["uv", "color", "smooth-normal", "face"]), (files["usd"], ["object", "normal"])):
        monkeypatch.setenv("SCATTER_THREADS", "3")
        a = scatter_cli.sample(stage, 5_000, seed=3, attributes=names)
        monkeypatch.setenv("SCATTER_THREADS", "1")
        b = scatter_cli.sample(stage, 5_000, seed=3, attributes=names, chunk_size=333)
        np.testing.assert_array_equal(a.points, b.points)
        assert a.attributes.keys() == b.attributes.keys()
        for key in a.attributes:
            np.testing.assert_array_equal(a.attributes[key], b.attributes[key])


# -- errors -------------------------------------------------------------------------------

@pytest.mark.slow
def test_malformed_stage_is_one_line(tmp_path):
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\ndef Mesh "m" { int[] faceVertexCounts = [3\n')
    proc = run_scatter("sample", bad, "-n", 10, "-o", tmp_path / "o.ply")
    err = proc.stderr.decode().strip().splitlines()
    assert proc.returncode == 1 and len(err) == 1 and err[0].startswith(f"error: {bad}: not a readable USD stage")
    assert not (tmp_path / "o.ply").exists()


def test_bad_topology_is_an_error(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "t.usda"))
    define_mesh(stage, "/M", np.eye(3), [[0, 1, 7]])
    stage.GetRootLayer().Save()
    with pytest.raises(ScatterError, match="index out of range"):
        load_surface(tmp_path / "t.usda")


@pytest.mark.slow
def test_missing_usd_core_gives_one_line(files, tmp_path):
    fake = tmp_path / "nousd" / "pxr"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError(\"No module named 'pxr'\")\n")
    env = {"PYTHONPATH": os.pathsep.join([str(fake.parent), os.environ.get("PYTHONPATH", "")])}
    proc = run_scatter("sample", files["usd"], "-n", 10, "-o", tmp_path / "o.ply", env=env)
    err = proc.stderr.decode().strip().splitlines()
    assert proc.returncode == 1 and len(err) == 1 and "pip install usd-core" in err[0]
    assert err[0].startswith(f"error: {files['usd']}:")


def test_stage_from_standard_input(files, monkeypatch):
    import io
    import sys
    import types

    monkeypatch.setattr(sys, "stdin", types.SimpleNamespace(buffer=io.BytesIO(files["usd"].read_bytes())))
    piped = load_surface("-", input_format="usda")
    assert piped.source == "<stdin>"
    direct = load_surface(files["usd"])
    assert [i.name for i in piped.instances] == [i.name for i in direct.instances]
    for g, h in zip(piped.geometries, direct.geometries):
        np.testing.assert_array_equal(g.vertices[g.faces], h.vertices[h.faces])


def test_usd_warnings_become_the_runs_warnings(tmp_path, capfd):
    path = tmp_path / "ref.usda"
    path.write_text('#usda 1.0\ndef Xform "W" (\n    prepend references = @./missing.usda@\n)\n{\n}\n'
                    'def Mesh "m"\n{\n    point3f[] points = [(0,0,0),(1,0,0),(0,1,0)]\n'
                    '    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0,1,2]\n}\n')
    messages = []
    run = scatter_cli.prepare(path, 10, warn=messages.append)
    assert run.count == 10
    assert len(messages) == 1 and messages[0].startswith(f"{path}: ") and "missing.usda" in messages[0]
    assert "stage.cpp" not in messages[0]  # USD's source location left out
    assert capfd.readouterr().err == ""  # nothing printed by USD itself
    scatter_cli.prepare(path, 10, warn=None)  # quiet: none at all
    assert capfd.readouterr().err == ""


def test_a_mesh_prim_without_arrays_has_no_faces(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "e.usda"))
    UsdGeom.Mesh.Define(stage, "/empty")
    define_mesh(stage, "/tri", np.eye(3), [[0, 1, 2]])
    stage.GetRootLayer().Save()
    s = load_surface(tmp_path / "e.usda")
    assert [(i.name, len(s.geometries[i.geometry].faces)) for i in s.instances] == [("/empty", 0), ("/tri", 1)]


# -- many instances: arrays over all instances at once --------------------------------------

def write_forest(path, k=240):
    """A point instancer of ``k`` instances of two prototypes taken in turn, at random
    positions, orientations and scales (one mirrored, one squashed onto a line), and
    instance 5 hidden."""
    rng = np.random.default_rng(11)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Xform.Define(stage, "/W")
    pi = UsdGeom.PointInstancer.Define(stage, "/W/trees")
    UsdGeom.Xformable(pi).AddRotateXOp().Set(-90)
    for j, (v, f) in enumerate(_meshes()[1:]):
        define_mesh(stage, f"/W/trees/protos/p{j}", v, f)
    pi.CreatePrototypesRel().SetTargets([f"/W/trees/protos/p{j}" for j in range(2)])
    pi.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy((np.arange(k) % 2).astype(np.int32)))
    pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(rng.uniform(-50, 50, (k, 3)).astype(np.float32)))
    q = rng.normal(size=(k, 4))
    pi.CreateOrientationsAttr(Vt.QuathArray.FromNumpy((q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float16)))
    scales = rng.uniform(0.5, 2, (k, 3))
    scales[3] = (-1, 1, 2)
    scales[8] = (0, 0, 1)
    pi.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(scales.astype(np.float32)))
    pi.CreateInvisibleIdsAttr([5])
    stage.GetRootLayer().Save()
    return path


def test_instancer_in_instance_order_with_geometry_stored_once(tmp_path):
    s = load_surface(write_forest(tmp_path / "f.usdc"))
    shown = [i for i in range(240) if i != 5]
    assert [i.name for i in s.instances] == [f"/W/trees[{i}]/p{i % 2}" for i in shown]
    assert len(s.geometries) == 2 and [i.geometry for i in s.instances] == [i % 2 for i in shown]


def test_instancer_plan_bounds_and_normals_as_one_instance_at_a_time(tmp_path):
    """The plan (face areas), the sampled box and the normals computed over all instances
    at once are those of each instance on its own, bit for bit (an instance of zero area
    and a mirrored one among them)."""
    from scatter_cli.api import prepare, sampled_bounds
    from scatter_cli.surface.model import apply_matrix, cofactor, corners, doubled_areas

    path = write_forest(tmp_path / "f.usdc")
    run = prepare(path, 5_000, seed=2, attributes=["normal", "object", "face"], precision="float64")
    s, plan = run.surface, run.plan
    areas, lo, hi = [], np.full(3, np.inf), np.full(3, -np.inf)
    for inst in s.instances:
        g = s.geometries[inst.geometry]
        a = doubled_areas(corners(g.vertices, g.faces), inst.matrix)
        used = np.isfinite(a) & (a > 0)
        areas.append(a[used])
        if used.any():
            v = apply_matrix(inst.matrix, g.vertices[np.unique(g.faces[used])])
            lo, hi = np.minimum(lo, v.min(axis=0)), np.maximum(hi, v.max(axis=0))
    assert sum(len(a) == 0 for a in areas) == 1  # the flattened instance gets no points
    cdf = np.cumsum(np.concatenate(areas))
    cdf *= 0.5
    np.testing.assert_array_equal(plan.cdf, cdf)
    np.testing.assert_array_equal(sampled_bounds(plan), np.stack([lo, hi]))
    out = run.collect()
    expected = np.empty_like(out.normal)
    for k in np.unique(out.object):
        rows = np.flatnonzero(out.object == k)
        inst = s.instances[k]
        g = s.geometries[inst.geometry]
        v = g.vertices[g.faces[out.face[rows]]]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        a = inst.matrix[:3, :3]
        n = apply_matrix(cofactor(a) * np.sign(np.linalg.det(a)), n)
        expected[rows] = n / np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
    np.testing.assert_array_equal(out.normal, expected)
    assert (out.object == s.instances.index(next(i for i in s.instances if i.name == "/W/trees[3]/p1"))).any()


@pytest.mark.parametrize("block", [1, 3, 1 << 16])
@pytest.mark.parametrize("sizes", [(3,), (4,), (5,), (0, 1, 2, 3, 4, 5, 7)])
def test_fan_faces_are_the_documented_fans(sizes, block):
    """Uniform polygons (a reshape) and mixed ones (in blocks of polygons) give the fans
    of the documented order, holes dropped, left-handed corners swapped."""
    from scatter_cli.loading.usdmesh import fan_faces

    rng = np.random.default_rng(len(sizes) + block)
    counts = rng.choice(sizes, 50).astype(np.int32)
    corners = rng.integers(0, 1000, counts.sum()).astype(np.int32)
    holes = np.array([4, 17, 17, 60, -1], dtype=np.int32)  # a repeat and out-of-range ones ignored
    for h in (None, holes):
        dropped = () if h is None else (4, 17)
        expected = corners[fan(counts, dropped)]
        np.testing.assert_array_equal(fan_faces(counts, corners, h, block=block), expected)
        np.testing.assert_array_equal(fan_faces(counts, corners, h, True, block=block), expected[:, [0, 2, 1]])
