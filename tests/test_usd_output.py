"""USD output read back by usd-core: points and primvars, instancer orientations, and the
stage passing usd-core's validators (what usdchecker runs)."""

import numpy as np
import pytest

import scatter_cli.api as api
from scatter_cli.errors import ScatterError
from scatter_cli.writers import write_samples

from .conftest import SAMPLES, run_scatter

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom  # noqa: E402


def write(path, attributes, n=400, precision="auto", mesh=SAMPLES / "boxtextured.glb", **options):
    run = api.prepare(mesh, n, attributes=attributes, seed=9, precision=precision, **options)
    report = write_samples(run.chunks(), path, "usd", run.layout, run.count, spacing=0.05)
    return run.collect(), report


def validation_errors(stage):
    """What usdchecker finds: UsdValidation's validators, or the older ComplianceChecker."""
    try:
        from pxr import UsdValidation
    except ImportError:
        from pxr import UsdUtils

        checker = UsdUtils.ComplianceChecker()
        checker.CheckCompliance(stage.GetRootLayer().realPath)
        return checker.GetErrors() + checker.GetFailedChecks()
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    return [e.GetMessage() for e in context.Validate(stage)]


def primvar(prim, name):
    return np.asarray(UsdGeom.PrimvarsAPI(prim).GetPrimvar(name).Get())


@pytest.mark.parametrize("suffix", ["usda", "usdc"])
def test_points_and_primvars_read_back(tmp_path, suffix):
    s, report = write(tmp_path / f"t.{suffix}", "normal,color,uv,face")
    stage = Usd.Stage.Open(str(tmp_path / f"t.{suffix}"))
    prim = stage.GetPrimAtPath("/Scatter/Points")
    np.testing.assert_array_equal(np.asarray(UsdGeom.Points(prim).GetPointsAttr().Get()), s.points)
    np.testing.assert_array_equal(primvar(prim, "normals"), s.normal)
    np.testing.assert_array_equal(primvar(prim, "st"), s.uv)
    np.testing.assert_array_equal(primvar(prim, "face_index"), s.face)
    np.testing.assert_allclose(primvar(prim, "displayColor"), s.color[:, :3] / 255.0, atol=1e-7)
    np.testing.assert_allclose(primvar(prim, "displayOpacity"), s.color[:, 3] / 255.0, atol=1e-7)
    assert UsdGeom.GetStageUpAxis(stage) == "Y" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert report["usd"]["from_input"] is False
    assert stage.GetDefaultPrim().GetPath() == "/Scatter"
    assert validation_errors(stage) == []


def test_validators_can_fail(tmp_path):
    write(tmp_path / "t.usda", "normal")
    stage = Usd.Stage.Open(str(tmp_path / "t.usda"))
    stage.ClearDefaultPrim()
    stage.Save()
    assert validation_errors(Usd.Stage.Open(str(tmp_path / "t.usda")))


@pytest.mark.slow
def test_instancer_orientations(tmp_path):
    s, _ = write(tmp_path / "t.usdc", "normal,orient")
    stage = Usd.Stage.Open(str(tmp_path / "t.usdc"))
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/Scatter/Instancer"))
    np.testing.assert_array_equal(np.asarray(inst.GetPositionsAttr().Get()), s.points)
    quatf = inst.GetOrientationsfAttr().Get()
    q = np.array([list(x.GetImaginary()) + [x.GetReal()] for x in quatf])
    np.testing.assert_array_equal(q, s.orient)
    quath = inst.GetOrientationsAttr().Get()
    np.testing.assert_allclose([list(x.GetImaginary()) + [x.GetReal()] for x in quath], s.orient, atol=1e-3)
    assert set(np.asarray(inst.GetProtoIndicesAttr().Get())) == {0}
    target = inst.GetPrototypesRel().GetTargets()
    assert len(target) == 1 and stage.GetPrimAtPath(target[0]).IsValid()
    xf = np.array(inst.ComputeInstanceTransformsAtTime(Usd.TimeCode.Default(), Usd.TimeCode.Default(),
                                                       UsdGeom.PointInstancer.ExcludeProtoXform))
    np.testing.assert_allclose(xf[:, 2, :3], s.normal, atol=1e-3)  # row 2: the image of +Z
    np.testing.assert_allclose(xf[:, 3, :3], s.points, atol=1e-6)
    assert validation_errors(stage) == []


def test_float64_points_sit_under_a_double_translate(tmp_path):
    from .test_las import terrain

    s, _ = write(tmp_path / "t.usda", "", mesh=terrain(), precision="float64")
    stage = Usd.Stage.Open(str(tmp_path / "t.usda"))
    world = np.array(UsdGeom.Xformable(stage.GetPrimAtPath("/Scatter")).ComputeLocalToWorldTransform(0))
    local = np.asarray(UsdGeom.Points(stage.GetPrimAtPath("/Scatter/Points")).GetPointsAttr().Get(), np.float64)
    error = np.abs(local + world[3, :3] - s.points).max()
    assert error < 1e-3 < np.abs(s.points.astype(np.float32) - s.points).max()


# the labels of volume runs and sharp: key -> (primvar, its USD type)
LABELS = {"sdf": ("sdf", "double[]"), "inside": ("inside", "uchar[]"), "winding": ("winding", "double[]"),
          "closest": ("closest", "point3f[]"), "face": ("face_index", "int[]"), "object": ("object_index", "int[]"),
          "sharp": ("sharp", "uchar[]")}


def check_labels(path, s):
    """Every label of ``s`` is a vertex primvar of its own in the stage at ``path``, with
    ``s``'s values (``closest`` as float32 points in the space of ``points``)."""
    stage = Usd.Stage.Open(str(path))
    prim = stage.GetPrimAtPath("/Scatter/Points")
    translate = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(0))[3, :3]
    for key, (name, type_name) in LABELS.items():
        primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
        assert primvar and primvar.GetInterpolation() == "vertex" and str(primvar.GetTypeName()) == type_name, name
        values = np.asarray(primvar.Get())
        if key == "closest":
            local = s.closest - translate
            assert np.abs(values + translate - s.closest).max() <= np.spacing(np.abs(local).max().astype(np.float32))
        else:
            np.testing.assert_array_equal(values, s.attributes[key], err_msg=name)
    assert validation_errors(stage) == []


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_volume_labels_and_sharp_are_primvars(tmp_path, precision):
    s, _ = write(tmp_path / "v.usda", ",".join(LABELS), near=(0.05,), box_share=0.2, edges=0.5, precision=precision)
    assert s.inside.any() and not s.inside.all() and s.sharp.any()  # the values tell points apart
    check_labels(tmp_path / "v.usda", s)


@pytest.mark.parametrize("key", LABELS)
def test_a_stage_without_one_label_fails_that_check(tmp_path, monkeypatch, key):
    import scatter_cli.writers.usd as usdwrite

    monkeypatch.setattr(usdwrite, "PRIMVARS", {k: v for k, v in usdwrite.PRIMVARS.items() if k != key})
    s, _ = write(tmp_path / "v.usda", ",".join(LABELS), near=(0.05,), box_share=0.2, edges=0.5)
    with pytest.raises(AssertionError):
        check_labels(tmp_path / "v.usda", s)


def test_a_count_beyond_memory_is_refused_and_leaves_no_file(tmp_path, monkeypatch):
    import scatter_cli.writers.usd as usdwrite

    monkeypatch.setattr(usdwrite, "available_memory", lambda: 10_000)
    with pytest.raises(ScatterError, match=r"t\.usdc: USD output is built in memory .* 1,000 points"):
        write(tmp_path / "t.usdc", "normal", n=1000)
    assert not list(tmp_path.iterdir())
    monkeypatch.setattr(usdwrite, "available_memory", lambda: 1000 * usdwrite.bytes_per_point(
        api.prepare(SAMPLES / "boxtextured.glb", 1000, attributes="normal").layout))
    write(tmp_path / "t.usdc", "normal", n=1000)  # just enough: written


def test_without_usd_core_one_line_saying_what_to_install(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pxr", None)
    with pytest.raises(ScatterError, match=r"needs usd-core: pip install usd-core$"):
        write(tmp_path / "t.usda", "", n=10)


def stage_with_units(path, up_axis=None, meters_per_unit=None):
    """A one-mesh stage (a quad cube), with upAxis and metersPerUnit authored when given."""
    from .test_usd import define_mesh, quad_cube

    stage = Usd.Stage.CreateNew(str(path))
    define_mesh(stage, "/cube", *quad_cube())
    if up_axis:
        UsdGeom.SetStageUpAxis(stage, up_axis)
    if meters_per_unit:
        UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.GetRootLayer().Save()
    return path


def units_written(tmp_path, mesh, *extra):
    """(upAxis, metersPerUnit, --stats from_input) of the stage `scatter sample MESH` writes."""
    import json

    out, report = tmp_path / "out.usda", tmp_path / "stats.json"
    proc = run_scatter("sample", mesh, "-n", 50, "-o", out, "--stats", report, *extra)
    assert proc.returncode == 0, proc.stderr.decode()
    stats = json.loads(report.read_text())
    stage = Usd.Stage.Open(str(out))
    assert validation_errors(stage) == []
    return UsdGeom.GetStageUpAxis(stage), UsdGeom.GetStageMetersPerUnit(stage), stats["output"]["usd"]["from_input"]


@pytest.mark.slow
@pytest.mark.parametrize("up_axis, meters_per_unit", [("Z", 0.01), ("Z", 0.3048), ("Y", 1000.0)])
def test_up_axis_and_units_carried_from_a_usd_input(tmp_path, up_axis, meters_per_unit):
    mesh = stage_with_units(tmp_path / "in.usda", up_axis, meters_per_unit)
    assert units_written(tmp_path, mesh) == (up_axis, meters_per_unit, True)


@pytest.mark.slow
def test_a_stage_without_units_keeps_usds_fallbacks(tmp_path):
    # Unauthored, a stage is Y up in centimetres (USD's fallbacks): the output says so
    # rather than metres, so the points keep their size in a consumer that converts units.
    mesh = stage_with_units(tmp_path / "in.usda")
    assert units_written(tmp_path, mesh) == ("Y", 0.01, True)


@pytest.mark.slow
def test_gltf_input_is_y_up_metres_and_others_say_nothing(tmp_path):
    assert units_written(tmp_path, SAMPLES / "boxtextured.glb") == ("Y", 1.0, True)
    assert units_written(tmp_path, SAMPLES / "skull.ply") == ("Y", 1.0, False)  # the default, not from the file
    zup = stage_with_units(tmp_path / "in.usda", "Z", 0.01)
    assert units_written(tmp_path, zup, "--object", "/cube") == ("Z", 0.01, True)  # selection keeps them
