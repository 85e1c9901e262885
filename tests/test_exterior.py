"""--exterior: only the surface seen from outside (scenes with known answers, real meshes,
an independent winding-number check, determinism, the missing extra)."""

import json

import numpy as np
import pytest

from . import exterior_scenes as es
from .conftest import SAMPLES, run_scatter, triangles_mesh

pytest.importorskip("embreex")

import scatter_cli  # noqa: E402
from scatter_cli.sampling.exterior import rays as exterior_rays  # noqa: E402
from scatter_cli.sampling.exterior.filter import classify  # noqa: E402
from scatter_cli.sampling.plan import SamplePlan  # noqa: E402
from scatter_cli.loading.load import load_surface  # noqa: E402
from scatter_cli.stats.chisquare import chi2_gof  # noqa: E402

LEVEL = 1e-3


class FromTheFace(exterior_rays.Occluder):
    """Broken: rays start on the face itself (no offset)."""

    def __init__(self, surface):
        super().__init__(surface, offset_roundings=0)


class OneDirection(exterior_rays.Occluder):
    """Broken: one random direction a point."""

    def __init__(self, surface):
        super().__init__(surface, design_size=1, normal_rays=False)


class TooFar(exterior_rays.Occluder):
    """Broken: rays start about the radius of the scene off the face (through walls)."""

    def __init__(self, surface):
        super().__init__(surface, offset_roundings=2.0**24)


BROKEN = {"from_face": FromTheFace, "one_direction": OneDirection, "too_far": TooFar}


def scene_cells(name):
    """(scene, {part: (face -> cell (F,), cell exterior (C,) bool)})."""
    if name == "bowl":
        scene, bands = es.bowl()
        return scene, {k: (v, np.ones(v.max() + 1, bool)) for k, v in bands.items()}
    scene, cells = getattr(es, name)()
    return scene, {k: (np.arange(2 * len(v)) // 2, np.array([e for _, e in v])) for k, v in cells.items()}


def cell_test(name, n=6000, seed=1, occluder=None, monkeypatch=None, **options):
    """(p-value of the per-cell counts on exterior cells against their areas, points on hidden
    cells); ``options``: more sample options (``stable=True``)."""
    scene, cells = scene_cells(name)
    if occluder is not None:
        monkeypatch.setattr(exterior_rays, "Occluder", occluder)
    s = scatter_cli.sample(scene, n, seed=seed, exterior=True, attributes=["face", "object"], **options)
    surface = load_surface(scene)
    counts, areas, exterior = [], [], []
    for k, inst in enumerate(surface.instances):
        face_cell, ext = cells[inst.name]
        g = surface.geometries[inst.geometry]
        tri = g.vertices[g.faces]
        a = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        mine = s.attributes["object"] == k
        counts.append(np.bincount(face_cell[s.attributes["face"][mine]], minlength=len(ext)))
        areas.append(np.bincount(face_cell, weights=a, minlength=len(ext)))
        exterior.append(ext)
    counts, areas, exterior = map(np.concatenate, (counts, areas, exterior))
    expected = counts[exterior].sum() * areas[exterior] / areas[exterior].sum()
    return chi2_gof(counts[exterior], expected)[2], int(counts[~exterior].sum())


SCENE_NAMES = ["box_in_box", "overlapping_boxes", "double_shell", "cup", "bowl", "car"]


@pytest.mark.parametrize("name", SCENE_NAMES)
def test_scene_counts_match_exterior_areas(name):
    p, hidden = cell_test(name)
    assert hidden == 0 and p > LEVEL, (p, hidden)


@pytest.mark.parametrize("name, broken", [("box_in_box", "too_far"), ("overlapping_boxes", "one_direction"),
                                          ("double_shell", "too_far"), ("cup", "one_direction"),
                                          ("bowl", "one_direction"), ("car", "too_far")])
def test_broken_classifier_fails_scene_counts(name, broken, monkeypatch):
    p, hidden = cell_test(name, occluder=BROKEN[broken], monkeypatch=monkeypatch)
    assert hidden > 0 or p < LEVEL


def classify_cells(name, occluder_class, n=20000, seed=3):
    """(exterior candidates dropped, hidden candidates kept, exterior candidates) for n uniform candidates."""
    scene, cells = scene_cells(name)
    surface = load_surface(scene)
    chunk = SamplePlan(surface).draw(0, n, seed)
    truth = np.concatenate([cells[inst.name][1][cells[inst.name][0]] for inst in surface.instances])
    offsets = np.cumsum([0] + [len(cells[inst.name][0]) for inst in surface.instances])
    exterior = truth[offsets[chunk.instance] + chunk.face]
    kept, _ = classify(occluder_class(surface), chunk, seed)
    return int(np.sum(exterior & ~kept)), int(np.sum(~exterior & kept)), int(exterior.sum())


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENE_NAMES)
def test_classifier_drops_under_1e3_of_exterior_and_keeps_no_hidden(name):
    dropped, kept_hidden, exterior = classify_cells(name, exterior_rays.Occluder)
    assert kept_hidden == 0
    assert dropped <= LEVEL * exterior


@pytest.mark.slow
@pytest.mark.parametrize("broken", [False, True])
def test_normal_rays_cast_together_in_face_order_give_the_same_verdicts(broken):
    """The pass casts the normal rays of a round's candidates together, in face order
    (ExteriorSource._classify_round): the verdicts and ray counts are those of each block
    classified alone, on scenes where some normal rays are blocked; the broken variant
    (the opposite normals cast first) must change them."""
    changed = 0
    for name in ("car", "cup", "bowl"):
        surface = load_surface(getattr(es, name)()[0])
        occluder = exterior_rays.Occluder(surface)
        chunk = SamplePlan(surface).draw(0, 20000, 4)
        alone = classify(occluder, chunk, 4)
        normals = occluder.face_normals(chunk.face, chunk.instance)
        order = np.argsort(occluder.offsets[chunk.instance] + chunk.face, kind="stable")[::-1]
        escaped = np.empty(len(order), bool)
        escaped[order] = occluder.normal_escapes(chunk.points[order], -normals[order] if broken else normals[order])
        together = classify(occluder, chunk, 4, escaped=escaped)
        assert broken or 0 < escaped.sum() < len(escaped)
        changed += not np.array_equal(alone[0], together[0]) or alone[1] != together[1]
    assert (changed > 0) == broken


@pytest.mark.parametrize("name", ["box_in_box", "cup"])
def test_rays_from_the_face_itself_drop_exterior_points(name):
    dropped, _, exterior = classify_cells(name, FromTheFace, n=2000)
    assert dropped > LEVEL * exterior


def test_per_face_verdict_from_a_few_points_is_unsound():
    """Why rays are cast for every candidate: a big triangle through a small sealed box
    looks exterior at its corners and centre, but the part inside the box is hidden."""
    big = np.array([[[-5.0, -5.0, 0.5], [5.0, -5.0, 0.5], [0.0, 5.0, 0.5]]])
    box = es.cuboid([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0])

    surface = load_surface(triangles_mesh(np.concatenate([big, box])))
    occluder = exterior_rays.Occluder(surface)
    bary = np.array([[0.8, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8], [1 / 3, 1 / 3, 1 / 3]])
    probes = bary @ big[0]
    normals = occluder.face_normals(np.zeros(4, np.int64), np.zeros(4, np.int64))
    assert occluder.exterior(probes, normals, np.full((4, 3), 0.5))[0].all()  # a per-face verdict: exterior
    s = scatter_cli.sample(surface, 3000, seed=2, exterior=True, attributes=["face"])
    on_big = s.points[s.attributes["face"] == 0]
    inside = (np.abs(on_big[:, 0]) < 0.5) & (np.abs(on_big[:, 1]) < 0.5)
    assert len(on_big) > 2000 and not inside.any()  # the box holds 1/50 of the face: 40 points expected


def winding_numbers(points, tri):
    """(n,) generalized winding number of the closed triangle set ``tri`` (F, 3, 3) at ``points`` (n, 3)."""
    total = np.zeros(len(points))
    for i in range(0, len(points), 500):
        a, b, c = (tri[None, :, k] - points[i:i + 500, None] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("ijk,ijk->ij", a, b) * lc + np.einsum("ijk,ijk->ij", b, c) * la \
            + np.einsum("ijk,ijk->ij", c, a) * lb
        total[i:i + 500] = 2 * np.arctan2(det, den).sum(axis=1) / (4 * np.pi)
    return total


def two_spheres():
    """One icosphere placed twice (two instances), overlapping: centres 1 apart, radius 1."""
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=2)
    scene = trimesh.Scene()
    scene.add_geometry(ball, geom_name="ball", node_name="left")
    moved = np.eye(4)
    moved[0, 3] = 1.0
    scene.graph.update(frame_to="right", frame_from=scene.graph.base_frame, matrix=moved, geometry="ball")
    return scene, ball, moved


@pytest.mark.slow
@pytest.mark.parametrize("occluder, fails", [(None, False), (TooFar, True)])
def test_no_point_inside_the_other_sphere_by_winding_number(occluder, fails, monkeypatch):
    if occluder is not None:
        monkeypatch.setattr(exterior_rays, "Occluder", occluder)
    scene, ball, moved = two_spheres()
    s = scatter_cli.sample(scene, 10000, seed=4, exterior=True, attributes=["object"], precision="float64")
    tri = ball.vertices[ball.faces]
    shift = np.array([1.0, 0.0, 0.0])
    w = np.where(s.attributes["object"] == 0, winding_numbers(s.points, tri + shift), winding_numbers(s.points, tri))
    inside = int(np.sum(w > 0.5))
    assert (inside > 0) == fails
    if not fails:  # and each sphere keeps about its exterior share (the same for both)
        assert abs(np.mean(s.attributes["object"]) - 0.5) < 4 * 0.5 / np.sqrt(10000)


@pytest.fixture(scope="module")
def box_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("exterior") / "box_in_box.glb"
    es.box_in_box()[0].export(path)
    return path


@pytest.mark.slow
@pytest.mark.parametrize("options", [["-n", "40000"], ["--poisson", "-n", "300"]])
def test_same_bytes_and_stats_whatever_chunk_size_and_threads(box_file, tmp_path, options):
    outs, found = [], []
    for chunk, threads in [(None, "1"), ("777", "2"), ("5000", "3")]:
        out, st = tmp_path / f"o{len(outs)}.ply", tmp_path / f"s{len(outs)}.json"
        extra = ["--chunk-size", chunk] if chunk else []
        run_scatter("sample", box_file, "--exterior", *options, "--seed", "5", "-a", "face,object", "-o", out,
                    "--stats", st, *extra, env={"SCATTER_THREADS": threads}, check=True)
        outs.append(out.read_bytes())
        found.append({k: v for k, v in json.loads(st.read_text())["exterior"].items() if k != "seconds"})
    assert outs[0] == outs[1] == outs[2]
    assert found[0] == found[1] == found[2]


@pytest.mark.slow
def test_ranges_are_a_pure_function_of_start_and_stop():
    scene, _ = es.car()
    run = scatter_cli.prepare(scene, 50000, seed=9, exterior=True, attributes=["face"])
    whole = run.source.draw(0, 50000)
    for a, b in [(0, 1), (123, 40000), (16383, 16385), (49999, 50000)]:
        part = run.source.draw(a, b)
        assert part.start == a and np.array_equal(part.points, whole.points[a:b])
        assert np.array_equal(part.face, whole.face[a:b])


def test_density_keeps_the_exterior_points_of_the_plain_run():
    scene, _ = es.overlapping_boxes()
    plain = scatter_cli.prepare(scene, density=200.0, seed=2, precision="float64")
    ext = scatter_cli.prepare(scene, density=200.0, seed=2, exterior=True, precision="float64")
    candidates = plain.source.draw(0, plain.count)
    kept, _ = classify(ext.source.occluder, candidates, 2)
    assert ext.count == kept.sum() < plain.count
    assert np.array_equal(ext.collect().points, candidates.points[kept])


@pytest.mark.slow
def test_exterior_area_estimate_and_face_counts(box_file):
    """Exact exterior area 54 of 60 (the inner box's 6 is hidden): within 4 standard errors."""
    from scatter_cli.commands.info import describe

    report = describe(box_file, exterior=True)["exterior"]
    assert abs(report["area"] - 54.0) < 4 * report["area_se"]
    assert (report["faces_exterior"], report["faces_mixed"], report["faces_hidden"]) == (108, 0, 12)
    assert report["faces_enclosed"] == 12  # the inner box, whole
    proc = run_scatter("sample", box_file, "--exterior", "-n", "10", "-f", "csv", "-o", "/dev/null", "--stats", "-", check=True)
    stats_ = json.loads(proc.stderr)["exterior"]
    assert abs(stats_["exterior_area"] - 54.0) < 4 * stats_["exterior_area_se"]
    assert stats_["faces_seen_hidden_only"] == 12


def test_poisson_thins_exterior_candidates():
    scene, cells = es.box_in_box()
    s = scatter_cli.sample(scene, 300, seed=1, exterior=True, poisson=True, attributes=["object"])
    inner = [k for k, inst in enumerate(load_surface(scene).instances) if inst.name == "inner"][0]
    assert len(s.points) == 300 and not np.any(s.attributes["object"] == inner)
    r = scatter_cli.sample(scene, seed=1, exterior=True, radius=0.4, attributes=["object"])
    assert len(r.points) > 100 and not np.any(r.attributes["object"] == inner)
    d = np.linalg.norm(r.points[:, None] - r.points[None], axis=2)
    assert d[np.triu_indices(len(d), 1)].min() >= 0.4 * (1 - 1e-6)


def test_sobol_keeps_no_hidden_point():
    scene, _ = es.box_in_box()
    s = scatter_cli.sample(scene, 2000, exterior=True, method="sobol", attributes=["object"])
    inner = [k for k, inst in enumerate(load_surface(scene).instances) if inst.name == "inner"][0]
    assert len(s.points) == 2000 and not np.any(s.attributes["object"] == inner)


@pytest.mark.slow
def test_without_embreex_one_line_and_exit_1(box_file, tmp_path):
    fake = tmp_path / "embreex"
    fake.mkdir()
    (fake / "__init__.py").write_text("raise ImportError('no embree here')\n")
    import os

    env = {"PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    for args in (["sample", box_file, "--exterior", "-n", "5"], ["info", box_file, "--exterior"]):
        proc = run_scatter(*args, env=env)
        lines = proc.stderr.decode().strip().splitlines()
        assert proc.returncode == 1 and len(lines) == 1 and "pip install embreex" in lines[0]
    assert run_scatter("sample", box_file, "-n", "5", env=env).returncode == 0  # only --exterior needs it


@pytest.mark.slow
@pytest.mark.parametrize("name", ["skull.ply", "hemisphere.off"])
def test_real_mesh_all_exterior_and_uniform(name):
    """A scan with holes and an open surface: every point is exterior (checked with 16x more
    directions), the counts over 50 bins of faces follow the face areas."""
    path = SAMPLES / name
    n = 20000
    s = scatter_cli.sample(path, n, seed=3, exterior=True, attributes=["face"], precision="float64")
    surface = load_surface(path)
    g = surface.geometries[0]
    tri = g.vertices[g.faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    bins = np.minimum(np.arange(len(area)) * 50 // len(area), 49)
    counts = np.bincount(bins[s.attributes["face"]], minlength=50)
    expected = n * np.bincount(bins, weights=area, minlength=50) / area.sum()
    assert chi2_gof(counts, expected)[2] > LEVEL
    many = exterior_rays.Occluder(surface, design_size=1024)
    from scatter_cli.sampling.plan import RawChunk

    chunk = RawChunk(0, s.points, s.attributes["face"], np.zeros(n, np.int64), None)
    assert classify(many, chunk, 77)[0].all()


@pytest.mark.slow
def test_cad_part_points_all_exterior_by_many_more_rays():
    """A CAD part whose pieces overlap (2 % of its area is hidden): every point kept is
    exterior for a classifier with 16x more directions."""
    from scatter_cli.sampling.plan import RawChunk

    path = SAMPLES / "pediment_join_plate_12.stl"
    s = scatter_cli.sample(path, 10000, seed=3, exterior=True, attributes=["face"], precision="float64")
    surface = load_surface(path)
    chunk = RawChunk(0, s.points, s.attributes["face"], np.zeros(len(s.points), np.int64), None)
    assert classify(exterior_rays.Occluder(surface, design_size=1024), chunk, 77)[0].all()


def test_bounded_source_short_of_exterior_points_says_so():
    from scatter_cli.sampling.exterior.filter import ExteriorSource, ShortStream

    run = scatter_cli.prepare(es.box_in_box()[0], 10, exterior=True)
    occluder = run.source.occluder
    assert ExteriorSource(run.source.base, occluder, 0, 60.0, count=15000, candidates=20000).count == 15000
    with pytest.raises(ShortStream):  # 90 % of 20,000 candidates are exterior
        ExteriorSource(run.source.base, occluder, 0, 60.0, count=20000, candidates=20000)


@pytest.mark.parametrize("keep", [0, 5000])
def test_kept_candidates_give_the_points_drawn_again(box_file, keep, monkeypatch):
    """The pass keeps the exterior candidates it found for the output while they fit
    KEEP_POINTS; past it (or with none kept) the output draws them again: same points."""
    from scatter_cli.sampling.exterior import filter as exterior

    def run(limit):
        monkeypatch.setattr(exterior, "KEEP_POINTS", limit)
        s = scatter_cli.sample(box_file, 20000, seed=4, exterior=True, attributes=["face", "object", "bary"])
        return s.points, s.attributes

    kept, again = run(1 << 30), run(keep)
    np.testing.assert_array_equal(kept[0], again[0])
    for key in kept[1]:
        np.testing.assert_array_equal(kept[1][key], again[1][key])
