"""--stable --exterior: the stable arrivals that can be seen from outside, in arrival order.

Uniform over the exterior part (per-cell counts against the exact areas, with a broken
classifier that must fail), still local under edits (with a broken variant whose ray
rotations follow the stream index, which must fail), the N earliest exterior arrivals,
and the same bytes whatever the chunk size and thread count. Level LEVEL.
"""

import json

import numpy as np
import pytest

from . import exterior_scenes as es
from .conftest import run_scatter, scatter_in_process, triangles_mesh

pytest.importorskip("embreex")
import scatter_cli  # noqa: E402
from scatter_cli.sampling.exterior import rays as exterior_rays  # noqa: E402
from scatter_cli.sampling.exterior.filter import classify  # noqa: E402
from scatter_cli.sampling.stable.source import StableSource  # noqa: E402
from scatter_cli.loading.load import load_surface  # noqa: E402

from .test_exterior import BROKEN, cell_test  # noqa: E402

LEVEL = 1e-3


@pytest.mark.parametrize("name", ["box_in_box", "double_shell", "car"])
def test_uniform_over_the_exterior_part(name):
    """Per-cell counts on exterior cells against their exact areas (test_exterior's test)."""
    p, hidden = cell_test(name, stable=True)
    assert hidden == 0 and p > LEVEL, (p, hidden)


@pytest.mark.parametrize("name", ["box_in_box", "car"])
def test_uniform_test_catches_a_classifier_that_sees_through_walls(name, monkeypatch):
    p, hidden = cell_test(name, occluder=BROKEN["too_far"], monkeypatch=monkeypatch, stable=True)
    assert hidden > 0 or p < LEVEL


def test_density_count_is_poisson_over_the_exterior_area():
    """box_in_box: exterior area 54 of 60; the count of exterior arrivals before D is
    Poisson with mean 54 D."""
    scene, _ = es.box_in_box()
    d = 300.0
    s = scatter_cli.sample(scene, None, density=d, seed=2, stable=True, exterior=True)
    assert abs(len(s.points) - 54 * d) < 4 * np.sqrt(54 * d)


# -- the N earliest exterior arrivals, and locality ---------------------------------------


def window_box():
    """One mesh: a closed 2 x 2 x 2 box (unit-square cells of 0.5) with one cell of its +x
    wall open, a 1 x 1 x 1 block inside it (seen from outside only through the window, so
    whether a point on it sees out depends on its ray rotation), and a flat patch outside
    on the -x side (the part an edit moves: no ray through the window reaches it).
    Returns (triangles (F, 3, 3), number of triangles before the patch)."""
    window = lambda c: c[0] > 1.99 and 0.5 < c[1] < 1.0 and 0.5 < c[2] < 1.0  # noqa: E731
    box = es.cuboid([0, 0, 0], [2, 2, 2], step=0.5, drop=window)
    block = es.cuboid([0.5, 0.5, 0.5], [1.5, 1.5, 1.5], step=0.25)
    return np.concatenate([box, block, patch(0.0)]), len(box) + len(block)


def patch(lift):
    """A 2 x 2 square of cells at x = -3 .. -1, z = 1 + lift."""
    cells = es.cuboid([-3, 0, 1 + lift], [-1, 2, 1.5 + lift], step=0.5)
    return cells[np.isclose(cells[:, :, 2], 1 + lift).all(axis=1)]


def exterior_run(tri, n, seed=3, **kw):
    return scatter_cli.sample(triangles_mesh(tri), n, seed=seed, stable=True, exterior=True, attributes=["face"],
                              precision="float64", **kw)


@pytest.mark.slow
@pytest.mark.parametrize("broken", [False, True])
def test_an_edit_elsewhere_moves_no_exterior_point_on_unchanged_faces(broken, monkeypatch):
    """Moving the patch changes the arrivals on it and so the place in the stream of every
    later arrival: with rotations drawn from each arrival's own stream, the exterior
    arrivals on unchanged faces are the same, in the same order (one run's are a prefix of
    the other's); with rotations drawn from the stream index (broken), the points on the
    block behind the window get new verdicts."""
    if broken:
        monkeypatch.delattr(StableSource, "ray_uniforms")
    tri, fixed = window_box()
    moved = np.concatenate([tri[:fixed], patch(0.3)])
    n = 6000
    before, after = exterior_run(tri, n), exterior_run(moved, n)
    a = before.points[before.attributes["face"] < fixed]
    b = after.points[after.attributes["face"] < fixed]
    common = min(len(a), len(b))
    assert common > 0.8 * n
    on_block = np.all((before.points > 0.5 - 1e-9) & (before.points < 1.5 + 1e-9), axis=1)
    assert 100 < on_block.sum() < 0.5 * n  # the block gets points, not all of its candidates
    assert (a[:common].tobytes() == b[:common].tobytes()) != broken


@pytest.mark.slow
def test_the_n_earliest_exterior_arrivals_in_arrival_order():
    """The output is the stable arrival stream filtered by the classifier, first N kept;
    -n N is the prefix of -n N + k."""
    tri, _ = window_box()
    mesh = triangles_mesh(tri)
    out = exterior_run(tri, 3000)
    surface = load_surface(mesh)
    stream = StableSource(surface, 3, stream=True)
    chunk = stream.draw(0, 8000)
    kept, _ = classify(exterior_rays.Occluder(surface), chunk, 3, stream.ray_uniforms(0, 8000))
    assert 3000 < kept.sum() < 8000
    assert chunk.points[kept][:3000].tobytes() == out.points.tobytes()
    longer = exterior_run(tri, 3500)
    assert longer.points[:3000].tobytes() == out.points.tobytes()


@pytest.mark.slow
def test_density_keeps_the_exterior_arrivals_before_d_and_is_local():
    tri, fixed = window_box()
    d = 400.0
    plain = scatter_cli.sample(triangles_mesh(tri), None, density=d, seed=5, stable=True, precision="float64",
                               attributes=["face"])
    ext = scatter_cli.sample(triangles_mesh(tri), None, density=d, seed=5, stable=True, exterior=True,
                             precision="float64", attributes=["face"])
    assert 0 < len(ext.points) < len(plain.points)
    assert np.isin(ext.points.view("V24"), plain.points.view("V24")).all()  # a subset of the plain run's
    moved = scatter_cli.sample(triangles_mesh(np.concatenate([tri[:fixed], patch(0.3)])), None, density=d, seed=5,
                               stable=True, exterior=True, precision="float64", attributes=["face"])
    keep = lambda s: s.points[s.attributes["face"] < fixed]  # noqa: E731
    assert keep(ext).tobytes() == keep(moved).tobytes()


def test_radius_keeps_exterior_points_spaced():
    scene, cells = es.box_in_box()
    r = scatter_cli.sample(scene, None, radius=0.4, seed=1, stable=True, exterior=True, attributes=["object"])
    inner = [k for k, inst in enumerate(load_surface(scene).instances) if inst.name == "inner"][0]
    assert len(r.points) > 100 and not np.any(r.attributes["object"] == inner)
    d = np.linalg.norm(r.points[:, None] - r.points[None], axis=2)
    assert d[np.triu_indices(len(d), 1)].min() >= 0.4 * (1 - 1e-6)


# -- determinism ------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("options", [["-n", "20000"], ["--density", "200"], ["--radius", "0.3"]])
def test_same_bytes_and_stats_whatever_chunk_size_and_threads(tmp_path, options):
    tri, _ = window_box()
    mesh = tmp_path / "window.ply"
    triangles_mesh(tri).export(mesh)
    outs, found = [], []
    for chunk, threads in [(None, "1"), ("777", "2"), ("5000", "3")]:
        out, st = tmp_path / f"o{len(outs)}.ply", tmp_path / f"s{len(outs)}.json"
        extra = ["--chunk-size", chunk] if chunk else []
        run = run_scatter if not outs else scatter_in_process  # (the first in a real process)
        run("sample", mesh, "--stable", "--exterior", *options, "--seed", "5", "-a", "face", "-o", out,
            "--stats", st, *extra, env={"SCATTER_THREADS": threads}, check=True)
        outs.append(out.read_bytes())
        found.append({k: v for k, v in json.loads(st.read_text())["exterior"].items() if k != "seconds"})
    assert outs[0] == outs[1] == outs[2]
    assert found[0] == found[1] == found[2]
