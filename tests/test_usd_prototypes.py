"""A point instancer's prototypes are sampled wherever they are defined (under a `class`,
an `over` or a `def` container), and what a stage holds that is not sampled is listed by
`scatter info` with why, and warned about by a run when it holds area.

The stages are built here with usd-core from cubes of known sizes, so the expected areas
are the sums of 6 s^2 over the placed cubes."""

import json

import numpy as np
import pytest

from scatter_cli.loading import usd as usdread
from scatter_cli.commands.info import describe
from scatter_cli.loading.load import load_surface

from .conftest import run_scatter, scatter_in_process

pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom  # noqa: E402

ALPHA = 1e-4
TREES = [(3.0, 0, 0), (6.0, 0, 0), (9.0, 0, 0), (12.0, 0, 0)]
HOUSES = 2
SIZES = {"ground": 2.0, "box": 1.0, "house": 0.5}


def cube(stage, path, size):
    m = UsdGeom.Mesh.Define(stage, path)
    h = size / 2
    m.CreatePointsAttr([(-h, -h, -h), (h, -h, -h), (h, h, -h), (-h, h, -h), (-h, -h, h), (h, -h, h), (h, h, h),
                        (-h, h, h)])
    m.CreateFaceVertexCountsAttr([4] * 6)
    m.CreateFaceVertexIndicesAttr([0, 3, 2, 1, 4, 5, 6, 7, 0, 1, 5, 4, 1, 2, 6, 5, 2, 3, 7, 6, 3, 0, 4, 7])
    return m


def write_stage(path, container, hidden=True):
    """/World: a ground cube, a point instancer of 4 boxes whose prototype is under
    /Protos (a ``container`` prim), 2 instanceable references to /Library (a house cube);
    with ``hidden``: an invisible cube, a guide cube, a proxy cube and a Sphere too."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.Xform.Define(stage, "/World")
    cube(stage, "/World/ground", SIZES["ground"])
    if container == "class":
        stage.CreateClassPrim("/Protos")
    elif container == "over":
        stage.OverridePrim("/Protos")
    else:
        UsdGeom.Scope.Define(stage, "/Protos")
    cube(stage, "/Protos/box", SIZES["box"])
    pi = UsdGeom.PointInstancer.Define(stage, "/World/trees")
    pi.CreatePrototypesRel().SetTargets(["/Protos/box"])
    pi.CreateProtoIndicesAttr([0] * len(TREES))
    pi.CreatePositionsAttr(TREES)
    library = stage.CreateClassPrim("/Library")
    cube(stage, "/Library/house", SIZES["house"])
    for k in range(HOUSES):
        x = UsdGeom.Xform.Define(stage, f"/World/house_{k}")
        x.GetPrim().GetReferences().AddInternalReference(library.GetPath())
        x.GetPrim().SetInstanceable(True)
        x.AddTranslateOp().Set(Gf.Vec3d(0, 5 * (k + 1), 0))
    if hidden:
        UsdGeom.Imageable(cube(stage, "/World/hidden", 1.0)).MakeInvisible()
        cube(stage, "/World/guide", 2.0).CreatePurposeAttr(UsdGeom.Tokens.guide)
        cube(stage, "/World/proxy", 3.0).CreatePurposeAttr(UsdGeom.Tokens.proxy)
        UsdGeom.Sphere.Define(stage, "/World/ball").CreateRadiusAttr(0.5)
        UsdGeom.Points.Define(stage, "/World/dust").CreatePointsAttr([(0, 0, 0)])
    stage.GetRootLayer().Save()
    return path


def drawn_area(container):
    """The area the stage draws: the ground, 4 boxes, 2 houses, and the prototype box
    itself where its container is drawn (a `def` or an `over`, not a class)."""
    area = 6 * SIZES["ground"] ** 2 + len(TREES) * 6 * SIZES["box"] ** 2 + HOUSES * 6 * SIZES["house"] ** 2
    return area + (6 * SIZES["box"] ** 2 if container != "class" else 0.0)


@pytest.mark.parametrize("container", ["class", "over", "def"])
def test_info_reports_the_full_area_wherever_the_prototypes_are(container, tmp_path):
    report = describe(str(write_stage(tmp_path / f"{container}.usda", container)))
    assert report["area"] == pytest.approx(drawn_area(container), rel=1e-12)
    trees = [o for o in report["objects"] if o["name"].startswith("/World/trees[")]
    assert len(trees) == len(TREES)


def test_the_area_check_fails_prototypes_walked_with_the_default_predicate(tmp_path, monkeypatch):
    """The broken variant: prototypes walked as the stage is (abstract prims skipped)
    lose the class-held instances, and the same check sees it."""
    path = write_stage(tmp_path / "class.usda", "class")
    real = usdread._StageReader.__init__

    def default_walk(self, *args):
        real(self, *args)
        self.anywhere = None

    monkeypatch.setattr(usdread._StageReader, "__init__", default_walk)
    assert describe(str(path))["area"] != pytest.approx(drawn_area("class"), rel=1e-12)


@pytest.mark.slow
def test_the_class_held_instances_get_their_share_of_the_points(tmp_path):
    """Points per object: the 4 instancer boxes get the share of their area (binomial,
    two-sided at ALPHA)."""
    path = write_stage(tmp_path / "class.usda", "class", hidden=False)
    n = 20_000
    proc = run_scatter("sample", path, "-n", n, "-a", "object", "-f", "csv", "--seed", 4, check=True)
    rows = np.loadtxt(proc.stdout.decode().splitlines()[1:], delimiter=",")
    names = [o["name"] for o in describe(str(path))["objects"]]
    index = [k for k, name in enumerate(names) if name.startswith("/World/trees[")]
    hits = int(np.isin(rows[:, 3], index).sum())
    p = len(TREES) * 6 * SIZES["box"] ** 2 / drawn_area("class")
    z = (hits - n * p) / np.sqrt(n * p * (1 - p))
    assert abs(z) < 3.9, (hits, n * p)  # |z| >= 3.9 has probability < 1e-4


@pytest.mark.slow
def test_info_lists_what_is_not_sampled_and_why(tmp_path):
    path = write_stage(tmp_path / "def.usda", "def")
    report = json.loads(run_scatter("info", path, "--json", check=True).stdout)
    got = {u["path"]: (u["reason"], u["area"]) for u in report["unsampled"]}
    assert got["/World/hidden"] == ("invisible", pytest.approx(6.0))
    assert got["/World/guide"] == ("guide purpose", pytest.approx(24.0))
    assert got["/World/proxy"] == ("proxy purpose", pytest.approx(54.0))
    assert got["/World/ball"] == ("a Sphere prim, not a mesh", pytest.approx(np.pi))
    assert got["/World/dust"] == ("a Points prim, not a mesh", 0.0)
    assert set(got) == {"/World/hidden", "/World/guide", "/World/proxy", "/World/ball", "/World/dust"}
    text = scatter_in_process("info", path, check=True).stdout.decode()  # (the text in this process)
    assert sum(line.startswith("not sampled") for line in text.splitlines()) == 5


@pytest.mark.slow
def test_a_run_warns_when_what_is_not_sampled_holds_area(tmp_path):
    hidden = run_scatter("sample", write_stage(tmp_path / "a.usda", "def"), "-n", 10, check=True)
    lines = [s for s in hidden.stderr.decode().splitlines() if s.strip()]
    assert len(lines) == 1 and "4 prim(s)" in lines[0] and "not sampled" in lines[0], lines
    clean = run_scatter("sample", write_stage(tmp_path / "b.usda", "def", hidden=False), "-n", 10, check=True)
    assert clean.stderr.decode().strip() == ""


def test_hidden_area_is_in_world_space(tmp_path):
    """An invisible cube under a scaled parent: its listed area is the scaled one."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "s.usda"))
    UsdGeom.Xform.Define(stage, "/W").AddScaleOp().Set(Gf.Vec3f(2, 3, 4))
    cube(stage, "/W/shown", 1.0)
    UsdGeom.Imageable(cube(stage, "/W/hidden", 1.0)).MakeInvisible()
    stage.GetRootLayer().Save()
    surface = load_surface(str(tmp_path / "s.usda"))
    (u,) = surface.unsampled
    assert u.area == pytest.approx(2 * (2 * 3 + 3 * 4 + 2 * 4))
