"""Honest signs: a run whose inside/outside labels rest on winding numbers near 1/2 (an
open terrain) says so once, with the share of such points, naming the mesh (in batch
too); a closed mesh does not; ``scatter info`` says how much of a surface has no clear
inside, and recommends no --sign mode when much of it has none."""

import json

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli.commands import info
from scatter_cli.engines.batch import run_batch
from scatter_cli.run.options import SampleOptions
from scatter_cli.volume import signs, source

from .conftest import SAMPLES, run_scatter, scatter_in_process, terrain

NEAR_HALF = 0.2  # the contract's |w - 0.5| < 0.2


def sign_warnings(said):
    return [w for w in said if "winding number within 0.2 of 0.5" in w]


def share_text(winding):
    """The share of ``winding`` near 1/2 as the warning writes it (a percentage)."""
    return f"{100 * np.mean(np.abs(winding - 0.5) < NEAR_HALF):.3g} %"


def assert_warns_with_its_share(mesh, name, **options):
    """One warning naming ``name``, with the share of the run's own points near 1/2."""
    said = []
    run = scatter_cli.sample(mesh, 6000, attributes=("inside", "winding"), warn=said.append, chunk_size=997, **options)
    found = sign_warnings(said)
    assert len(found) == 1, said
    assert found[0].startswith(f"{name}: {share_text(run.winding)} of the points"), found[0]
    return run


def assert_silent(mesh, **options):
    said = []
    scatter_cli.sample(mesh, 6000, attributes=("sdf", "inside"), warn=said.append, **options)
    assert not sign_warnings(said), said


def test_a_terrain_warns_once_with_the_share_of_its_coin_flips(tmp_path, monkeypatch):
    path = tmp_path / "terrain.ply"
    terrain().export(path)
    run = assert_warns_with_its_share(path, str(path), near=(0.5,))
    assert np.mean(np.abs(run.winding - 0.5) < NEAR_HALF) > 0.3  # the 47 %: far over 1 %
    assert run.info["volume"]["near_half"] == pytest.approx(np.mean(np.abs(run.winding - 0.5) < NEAR_HALF))
    assert_warns_with_its_share(path, str(path), volume=True)
    # the broken variant: labels that keep no count say nothing
    monkeypatch.setattr(source, "SignTally", lambda: None)
    with pytest.raises(AssertionError):
        assert_warns_with_its_share(path, str(path), near=(0.5,))


@pytest.mark.slow
@pytest.mark.parametrize("options", [dict(near=(0.01,)), dict(volume=True), dict(near=(0.05,), box_share=0.5)])
def test_a_closed_mesh_does_not_warn(options, monkeypatch):
    assert_silent(SAMPLES / "skull.ply", **options)
    monkeypatch.setattr(signs, "WARN_SHARE", -1.0)  # the broken variant: a warning whatever the share
    with pytest.raises(AssertionError):
        assert_silent(SAMPLES / "skull.ply", **options)


def assert_no_sign_rests_on_w():
    """--sign parity, and a run that only writes w (no sign), say nothing of w."""
    said = []
    scatter_cli.sample(terrain(), 3000, near=(0.5,), sign="parity", attributes=("inside",), warn=said.append)
    scatter_cli.sample(terrain(), 3000, near=(0.5,), attributes=("winding",), warn=said.append)
    assert not sign_warnings(said), said


def test_signs_that_do_not_rest_on_winding_numbers_do_not_warn(monkeypatch):
    assert_no_sign_rests_on_w()
    original = source.VolumeLabels.__init__

    def counting_every_w(labels, *args, **keywords):
        original(labels, *args, **keywords)
        labels.tally = signs.SignTally() if labels.needs_winding else None

    monkeypatch.setattr(source.VolumeLabels, "__init__", counting_every_w)  # the broken variant
    with pytest.raises(AssertionError):
        assert_no_sign_rests_on_w()


def batch_sign_warnings(folder, out, capfd):
    """The sign warnings of the batch (not quiet, as the command runs it) of ``folder``."""
    options = SampleOptions(count=4000, near="0.5", attributes="inside")
    run_batch([folder], str(out / "{stem}.npy"), jobs=2, options=options)
    return sign_warnings(capfd.readouterr().err.splitlines())


@pytest.mark.slow
def test_batch_names_the_mesh_whose_signs_are_coin_flips(tmp_path, capfd, monkeypatch):
    folder = tmp_path / "in"
    folder.mkdir()
    terrain().export(folder / "terrain.ply")
    trimesh.creation.icosphere(subdivisions=3).export(folder / "ball.ply")
    alone = run_scatter("sample", folder / "terrain.ply", "-n", "4000", "--near", "0.5", "-a", "inside",
                        "-o", tmp_path / "alone.npy", check=True)
    want = sign_warnings(alone.stderr.decode().splitlines())
    assert len(want) == 1
    found = batch_sign_warnings(folder, tmp_path / "out", capfd)
    assert found == want and str(folder / "terrain.ply") in found[0]
    # the broken variant: a worker that keeps the share to itself
    monkeypatch.setattr(scatter_cli.api.Run, "_count_signs", lambda run: None)
    assert batch_sign_warnings(folder, tmp_path / "again", capfd) == []


def sheet():
    return trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], process=False)


def nicked_sphere():
    """A sphere with a small cap cut off: open, but with an inside worth the name."""
    ball = trimesh.creation.icosphere(subdivisions=4)
    keep = ball.triangles_center[:, 2] < 0.98
    return trimesh.Trimesh(ball.vertices, ball.faces[keep], process=False)


def assert_inside_verdict(mesh, much_open):
    """``info`` gives the share of the points of a half-box, half-near run (sigma 1 % of
    the diagonal) whose w is near 1/2, and recommends --sign winding only when it is small."""
    report = info.describe(mesh)
    lo, hi = np.array(report["bounds"])
    run = scatter_cli.sample(mesh, info.SIGN_PROBES, near=(0.01 * np.linalg.norm(hi - lo),), box_share=0.5,
                             attributes=("winding",), precision="float64")
    assert report["unclear_inside"] == np.mean(np.abs(run.winding - 0.5) < NEAR_HALF)
    line = [s for s in info.format_text(report).splitlines() if s.startswith("inside")]
    assert len(line) == 1 and share_text(run.winding) in line[0]
    assert ("no --sign mode gives inside a meaning" in line[0]) == much_open
    assert ("--sign winding is the one to trust" in line[0]) == (not much_open)


@pytest.mark.parametrize("mesh,much_open", [(terrain, True), (sheet, True), (lambda: SAMPLES / "hemisphere.off", True),
                                            (nicked_sphere, False)])
def test_info_says_how_much_of_an_open_surface_has_no_inside(mesh, much_open, monkeypatch):
    assert_inside_verdict(mesh(), much_open)
    # the broken variant: a threshold no surface reaches recommends winding for a terrain
    monkeypatch.setattr(info, "OPEN_SHARE", 1.0)
    if much_open:
        with pytest.raises(AssertionError):
            assert_inside_verdict(mesh(), much_open)


def assert_no_inside_line(mesh):
    report = info.describe(mesh)
    assert report["closed"] and report["unclear_inside"] is None
    text = info.format_text(report)
    assert "both --sign modes hold" in text and not [s for s in text.splitlines() if s.startswith("inside")]


def test_info_of_a_closed_surface_has_no_inside_line(monkeypatch):
    assert_no_inside_line(SAMPLES / "icosahedron_binary.stl")
    closedness = info.closedness
    monkeypatch.setattr(info, "closedness", lambda *a: dict(closedness(*a), closed=False))  # the broken variant
    with pytest.raises(AssertionError):
        assert_no_inside_line(SAMPLES / "icosahedron_binary.stl")


def assert_terrain_verdict(path):
    """``scatter info PATH`` (JSON and text) finds much of it open and recommends no --sign mode."""
    report = json.loads(run_scatter("info", path, "--json", check=True).stdout)
    assert not report["closed"] and report["unclear_inside"] > info.OPEN_SHARE
    text = scatter_in_process("info", path, check=True).stdout.decode()  # (the text in this process)
    assert "no --sign mode gives inside a meaning" in text and "the one to trust" not in text


@pytest.mark.slow
def test_info_json_and_text_of_a_terrain(tmp_path):
    terrain().export(tmp_path / "terrain.ply")
    assert_terrain_verdict(tmp_path / "terrain.ply")
    with pytest.raises(AssertionError):  # the broken variant: a nicked sphere is not much open
        nicked_sphere().export(tmp_path / "nicked.ply")
        assert_terrain_verdict(tmp_path / "nicked.ply")
