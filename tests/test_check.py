"""`scatter check` passes this tool on real meshes and fails a sampler that drops area weights."""

import numpy as np
import pytest

pytest.importorskip("pymeshlab")

from scatter_cli.commands.check import ALPHA, run_check  # noqa: E402
from scatter_cli.sampling.plan import SamplePlan  # noqa: E402
from scatter_cli.loading.load import load_surface  # noqa: E402

from .conftest import run_scatter  # noqa: E402
from .doubles import UnweightedSource  # noqa: E402

MESHES = ["skull.ply", "koala.obj", "spot_triangulated.obj", "cesiummilktruck.glb"]


def unweighted_sampler(surface, count, seed):
    return UnweightedSource(SamplePlan(surface), count, seed).draw(0, count).points


@pytest.mark.slow
@pytest.mark.parametrize("name", MESHES)
def test_check_passes_on_real_meshes(sample_mesh, name):
    lines = []
    assert run_check(sample_mesh(name), count=50_000, seed=1, out=lines.append) == 0, "\n".join(lines)
    assert lines[-1].startswith("PASS")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["skull.ply", "koala.obj", "cesiummilktruck.glb"])
def test_check_fails_when_area_weights_are_dropped(sample_mesh, name):
    lines = []
    code = run_check(load_surface(sample_mesh(name)), count=50_000, seed=1, sampler=unweighted_sampler, out=lines.append)
    assert code == 1, "\n".join(lines)
    assert lines[-1].startswith("FAIL")


@pytest.mark.slow
def test_check_command_exit_code_and_table(sample_mesh):
    proc = run_scatter("check", sample_mesh("hemisphere.off"), "-n", 20000)
    out = proc.stdout.decode()
    assert proc.returncode == 0, out + proc.stderr.decode()
    assert "pymeshlab" in out and "two-sample" in out and f"alpha = {ALPHA:g}" in out


def _rotation_z(angle, shift):
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = shift
    return m


@pytest.fixture
def three_cubes(tmp_path):
    """A GLB of one cube placed three times (identity, two turned about z and moved): the
    cubes' tops are flat faces at the highest heights, where pymeshlab's points lie an
    ulp above the highest vertex."""
    import trimesh

    from testkit.gltfwrite import glb_bytes

    box = trimesh.creation.box()
    nodes = [(0, None), (0, _rotation_z(0.3, [2.1, 0.3, 0.7])), (0, _rotation_z(1.1, [-1.7, 0.9, 1.3]))]
    path = tmp_path / "three_cubes.glb"
    path.write_bytes(glb_bytes([(box.vertices, box.faces)], nodes))
    return path


@pytest.mark.slow
def test_check_counts_points_an_ulp_off_in_the_region_they_are_on(three_cubes):
    """pymeshlab's points on the top face sit an ulp above the highest vertex (checked
    here, so the case is exercised); they must count in the top face's slab, not in a
    slab of probability 0 that makes the two sets 'differ' (p 1e-26 before the fix)."""
    from scatter_cli.commands.check import pymeshlab_sampler, world_mesh

    vertices, faces, _ = world_mesh(load_surface(three_cubes))
    tri = vertices[faces]
    theirs = pymeshlab_sampler(vertices, faces, 50_000)
    assert (theirs[:, 2] > tri[..., 2].max()).sum() > 100
    lines = []
    assert run_check(three_cubes, count=50_000, seed=1, out=lines.append) == 0, "\n".join(lines)
    text = "\n".join(lines)
    assert "the sets differ" not in text and lines[-1].startswith("PASS"), text


@pytest.mark.slow
def test_check_says_which_sampler_fits_when_the_sets_differ(three_cubes, monkeypatch):
    """With pymeshlab replaced by a sampler that ignores the areas, the sets differ:
    check names the slab, each sampler's count there against the exact area, and that
    pymeshlab is the one that does not fit; scatter still passes."""
    from scatter_cli.commands import check

    def unweighted(vertices, faces, count, poisson=False, radius=None):
        tri = vertices[faces]
        rng = np.random.default_rng(3)
        f = rng.integers(0, len(tri), count)
        u = rng.random((count, 2))
        fold = u.sum(axis=1) > 1
        u[fold] = 1 - u[fold]
        return tri[f, 0] + u[:, :1] * (tri[f, 1] - tri[f, 0]) + u[:, 1:] * (tri[f, 2] - tri[f, 0])

    monkeypatch.setattr(check, "pymeshlab_sampler", unweighted)
    tall = load_surface(three_cubes)
    tall.geometries[0].vertices[:, 2] *= 3.0  # unequal face areas, so ignoring them shows
    lines = []
    assert run_check(tall, count=50_000, seed=1, out=lines.append) == 0, "\n".join(lines)
    text = "\n".join(lines)
    assert "the sets differ" in text, text
    assert "scatter fits the exact area there; pymeshlab does not" in text, text
    assert lines[-1].startswith("PASS") and "pymeshlab's count is off" in lines[-1], text


@pytest.mark.slow
def test_check_fails_a_sampler_a_hair_off_the_surface(three_cubes):
    """The broken variant for the rounding allowance: points moved 1e-7 of the size
    above the surface (far more than rounding, far less than any slab) must FAIL, as
    points off the surface; the moments do not notice them."""
    def lifted(surface, count, seed):
        from scatter_cli.commands.check import scatter_sampler

        p = scatter_sampler(surface, count, seed)
        p[:, 2] += 4e-7 * (p[:, 2] >= p[:, 2].max() - 1e-9)  # the tops' points
        return p

    lines = []
    assert run_check(three_cubes, count=50_000, seed=1, sampler=lifted, out=lines.append) == 1, "\n".join(lines)
    assert lines[-1].startswith("FAIL")
    row = next(line for line in lines if line.startswith("points off the surface"))
    assert int(row.split()[-2].replace(",", "")) > 100


@pytest.mark.slow
def test_check_fails_a_sampler_that_thins_the_highest_top(three_cubes):
    """A sampler that drops a third of the points of the highest cube's top (the face at
    the rounding-prone end of the z slabs) must FAIL."""
    def thin_top(surface, count, seed):
        from scatter_cli.commands.check import scatter_sampler

        p = scatter_sampler(surface, 2 * count, seed)
        top = p[:, 2] >= p[:, 2].max() - 1e-9
        drop = top & (np.arange(len(p)) % 3 == 0)
        return p[~drop][:count]

    lines = []
    assert run_check(three_cubes, count=50_000, seed=1, sampler=thin_top, out=lines.append) == 1, "\n".join(lines)
    assert lines[-1].startswith("FAIL")


def _terrain(n=120):
    """A height field of (n - 1)^2 2 faces: smooth hills plus noise, many faces crossing
    every level (the worst case for the exact slabs along z)."""
    x, y = np.meshgrid(np.linspace(0, 100, n), np.linspace(0, 100, n))
    z = 5 * np.sin(x / 7) * np.cos(y / 11) + np.random.default_rng(0).normal(0, 0.3, x.shape)
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    faces = np.r_[np.c_[i, i + 1, i + n], np.c_[i + 1, i + n + 1, i + n]]
    return np.c_[x.ravel(), y.ravel(), z.ravel()][faces]


@pytest.mark.slow
def test_exact_slabs_work_is_a_small_multiple_of_the_faces(monkeypatch):
    """The exact regions of a large terrain: the passes over (target, face) pairs over all
    seven directions (evaluations of the area and its derivative, narrowings, the exact
    sums at the edges) stay within 45 per face (Newton steps from a one-pass guess, each
    bracket's faces narrowed to those with a vertex height inside; the bisection this
    replaced evaluated 64 per face, and narrowed 20 more), and their probabilities are
    exact (they sum to one, the area below each edge agrees with a direct evaluation)."""
    from scatter_cli.stats import slabs as slab_heights, uniformity

    tri = _terrain()
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    work = []
    for name in ("area_at", "density_at", "narrow"):
        real = getattr(slab_heights._Pairs, name)
        monkeypatch.setattr(slab_heights._Pairs, name,
                            lambda pairs, *args, real=real: work.append(len(pairs)) or real(pairs, *args))
    exact = slab_heights._Pairs.exact_area_at
    monkeypatch.setattr(slab_heights._Pairs, "exact_area_at", lambda pairs, t: work.append(
        len(pairs) + sum(len(k[0]) for k in pairs.kept)) or exact(pairs, t))
    regions = uniformity.Regions(tri, areas, 32)
    assert sum(work) < 45 * len(tri), sum(work) / len(tri)
    for d, edges, prob in regions.slabs:
        assert len(prob) >= 24 and abs(prob.sum() - 1) < 1e-12
        below = np.array([_area_below(tri, areas, d, e) for e in edges[1:-1]]) / areas.sum()
        assert np.allclose(np.cumsum(prob)[:-1], below, rtol=0, atol=1e-9)


def _area_below(tri, areas, d, t):
    """The area of ``tri`` below height t along d, by the closed form per face."""
    h = np.sort(tri @ d, axis=1)
    from scatter_cli.stats.slabs import below_fraction

    return float(areas @ below_fraction(h[:, 0], h[:, 1], h[:, 2], t))


def test_check_shows_its_stages_on_a_terminal():
    """Progress: each stage on one redrawn line when standard error is a terminal, the
    line cleared at the end; nothing when it is not."""
    import io

    from scatter_cli.commands.check import _Stage

    class Tty(io.StringIO):
        def isatty(self):
            return True

    tty, pipe = Tty(), io.StringIO()
    for stream in (tty, pipe):
        stage = _Stage(stream)
        stage("sampling with scatter")
        stage("exact regions, direction 1/7")
        stage(None)
    assert pipe.getvalue() == ""
    text = tty.getvalue()
    assert "\rcheck: sampling with scatter..." in text and "\rcheck: exact regions, direction 1/7..." in text
    assert text.endswith("\r" + " " * len("check: exact regions, direction 1/7...") + "\r")


def test_check_reads_a_binary_ply_as_sample_does_without_trimesh(monkeypatch, tmp_path):
    """check reads its mesh as ``scatter sample MESH`` does: a binary PLY through the fast
    reader, without importing trimesh (a second or more of its run); reading it through
    trimesh, as check did, fails here."""
    import trimesh

    from scatter_cli.loading import load as loaders

    path = tmp_path / "terrain.ply"
    tri = _terrain(30)
    trimesh.Trimesh(tri.reshape(-1, 3), np.arange(len(tri) * 3).reshape(-1, 3), process=False).export(path)
    monkeypatch.setattr(loaders, "_import_trimesh", lambda: pytest.fail("check imported trimesh"))
    lines = []
    assert run_check(path, count=4000, seed=1, out=lines.append) == 0, "\n".join(lines)
    with pytest.raises(pytest.fail.Exception):
        loaders.load_surface(path)
