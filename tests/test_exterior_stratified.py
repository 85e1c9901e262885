"""--exterior with --method stratified: exactly N points, chosen uniformly among the
exterior points of a stratified run, deterministic; the same points as the plain
stratified run when nothing is hidden."""

import numpy as np
import pytest

from . import exterior_scenes as es
from .conftest import run_scatter, scatter_in_process

pytest.importorskip("embreex")

import scatter_cli  # noqa: E402
from scatter_cli.sampling.exterior import filter as exterior  # noqa: E402
from scatter_cli.loading.load import load_surface  # noqa: E402
from scatter_cli.stats.chisquare import chi2_gof  # noqa: E402

LEVEL = 1e-3


def square_counts(name, n, seed):
    """(counts on exterior squares, their areas, points on hidden squares) of a stratified --exterior run."""
    scene, cells = getattr(es, name)()
    s = scatter_cli.sample(scene, n, seed=seed, exterior=True, method="stratified", attributes=["face", "object"])
    assert len(s.points) == n
    counts, hidden = [], 0
    for k, inst in enumerate(load_surface(scene).instances):
        ext = np.array([e for _, e in cells[inst.name]])
        c = np.bincount(s.attributes["face"][s.attributes["object"] == k] // 2, minlength=len(ext))
        counts.append(c[ext])
        hidden += int(c[~ext].sum())
    return np.concatenate(counts), hidden


@pytest.mark.slow
@pytest.mark.parametrize("name", ["box_in_box", "car", "overlapping_boxes"])
@pytest.mark.parametrize("broken", [False, True])
def test_stratified_exterior_is_uniform_over_the_exterior(name, broken, monkeypatch):
    """Counts per exterior square (every square has the same area) against equal shares,
    chi-square at 1e-3; broken: the first N exterior points of the face-ordered run."""
    if broken:
        real = exterior.ExteriorSubset.__init__

        def prefix(self, *args, **kw):
            real(self, *args, **kw)
            self.chosen = np.arange(self.count)

        monkeypatch.setattr(exterior.ExteriorSubset, "__init__", prefix)
    counts, hidden = square_counts(name, 20000, seed=2)
    p = chi2_gof(counts, np.ones(len(counts)))[2]
    assert hidden == 0
    assert (p < LEVEL) == broken, p


def test_all_exterior_gives_the_plain_stratified_run():
    scene, _ = es.cup()
    plain = scatter_cli.sample(scene, 3000, seed=4, method="stratified", attributes=["face"], precision="float64")
    ext = scatter_cli.sample(scene, 3000, seed=4, method="stratified", exterior=True, attributes=["face"],
                             precision="float64")
    assert np.array_equal(plain.points, ext.points) and np.array_equal(plain.attributes["face"], ext.attributes["face"])


@pytest.mark.slow
def test_same_bytes_whatever_chunk_size_and_threads(tmp_path):
    path = tmp_path / "car.glb"
    es.car()[0].export(path)
    outs = []
    for chunk, threads in [(None, "1"), ("777", "2")]:
        out = tmp_path / f"o{len(outs)}.ply"
        extra = ["--chunk-size", chunk] if chunk else []
        run = run_scatter if not outs else scatter_in_process  # (the first in a real process)
        run("sample", path, "--exterior", "--method", "stratified", "-n", "20000", "--seed", "5",
            "-a", "face,object", "-o", out, *extra, env={"SCATTER_THREADS": threads}, check=True)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
