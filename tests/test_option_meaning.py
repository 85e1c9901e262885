"""Options that mean what they say: an option that a run would ignore is a usage error
naming what it needs, a repeated -a adds up, and the Python API takes values as the
command line takes them. Each check is paired with the variant it must catch."""

from typing import Annotated, Optional

import numpy as np
import pytest
import typer

import scatter_cli
from scatter_cli import api, cli
from scatter_cli.engines import batch
from scatter_cli.errors import ScatterError, ScatterUsageError
from scatter_cli.run import bounds, options
from scatter_cli.run.options import SampleOptions

from .batchtools import command_in_process, sample_in_process
from .conftest import SAMPLES, run_scatter

MESH = SAMPLES / "icosahedron_binary.stl"

# volume-only options given to a surface run: bad values and good ones alike
VOLUME_ONLY = {
    "--box-share 1.5": dict(box_share=1.5),
    "--box-share 0.5": dict(box_share=0.5),
    "--padding -1": dict(padding=-1.0),
    "--padding 0.2": dict(padding=0.2),
    "--sign bogus": dict(sign="bogus"),
    "--sign parity": dict(sign="parity"),
}


@pytest.mark.parametrize("broken", [False, True])
@pytest.mark.parametrize("given", list(VOLUME_ONLY.values()), ids=list(VOLUME_ONLY))
def test_volume_options_without_a_volume_run_are_usage_errors(monkeypatch, given, broken):
    """The error names the option and what it needs; the broken variant (no such check)
    lets the run go on without them."""
    if broken:
        monkeypatch.setattr(options, "_check_surface", lambda o: None)
    o = SampleOptions(count=10, **given)
    if broken:
        assert o.check() is o
        return
    name = "--" + next(iter(given)).replace("_", "-")
    with pytest.raises(ScatterUsageError, match=f"{name} is for volume runs only: add --volume or --near"):
        o.check()


def test_the_volume_options_not_given_are_their_documented_values():
    """Not given, --padding is 0.1 and --sign winding: the same points and labels as
    those values given, and another value given changes them (the check can fail)."""
    def run(**given):  # on an open surface, where parity and winding numbers disagree
        s = scatter_cli.sample(SAMPLES / "hemisphere.off", 300, volume=True, attributes="inside,winding", **given)
        return s.points.tobytes() + s.inside.tobytes() + s.winding.tobytes()

    default = run()
    assert default == run(padding=0.1, sign="winding")
    assert default != run(padding=0.2) and default != run(sign="parity")


@pytest.mark.slow
def test_the_command_refuses_them_in_one_line():
    proc = run_scatter("sample", MESH, "-n", 10, "--box-share", "1.5", "--padding", "-1", "--sign", "bogus")
    assert (proc.returncode, proc.stdout, proc.stderr.decode()) == \
        (2, b"", "error: --box-share and --padding and --sign are for volume runs only: add --volume or --near\n")


def attributes_parsed(args, declaration=None):
    """The attributes that ``scatter sample``'s declaration of -a (or ``declaration``)
    hands to SampleOptions for the arguments ``args``."""
    app = typer.Typer()
    seen = {}

    @app.command()
    @cli.sample_options("attributes", **({} if declaration is None else {"attributes": declaration}))
    def sample(**given):
        seen.update(given)

    typer.main.get_command(app).main(args, standalone_mode=False)
    return SampleOptions.of(seen).attributes


def test_repeated_attributes_add_up():
    """-a normal -a face is -a normal,face; the broken variant, -a declared as one text,
    keeps only the last."""
    assert attributes_parsed(["-a", "normal", "-a", "face,bary"]) == ("normal", "face", "bary")
    assert attributes_parsed(["-a", "normal,face,bary"]) == ("normal", "face", "bary")
    one_text = Annotated[Optional[str], typer.Option("-a", "--attributes")]
    assert attributes_parsed(["-a", "normal", "-a", "face,bary"], one_text) == ("face", "bary")


@pytest.mark.slow
def test_repeated_attributes_write_the_columns_of_one_list(tmp_path):
    one = run_scatter("sample", MESH, "-n", 20, "-a", "normal", "-a", "face", check=True).stdout
    sample_in_process(["sample", str(MESH), "-n", "20", "-a", "normal,face", "-o", str(tmp_path / "listed.csv")])
    assert one == (tmp_path / "listed.csv").read_bytes()
    assert one.startswith(b"x,y,z,nx,ny,nz,face_index\n")


def test_check_with_too_few_points_is_a_usage_error(monkeypatch):
    """-n 0 or 1 is refused before any work; the broken variant (no such check) goes on to
    sample. pymeshlab's sampler is stood in for: given 0 points it fails, and leaves the
    library to crash this process at its next load of a file."""
    pytest.importorskip("pymeshlab")
    from scatter_cli.commands import check

    class Sampled(Exception):
        pass

    def sampler(*args):
        raise Sampled

    monkeypatch.setattr(check, "pymeshlab_sampler", sampler)
    for count in (0, 1):
        with pytest.raises(ScatterUsageError, match=f"-n must be at least 2 .*not {count}"):
            check.run_check(MESH, count=count, out=lambda line: None)
    monkeypatch.setattr(check, "MIN_COUNT", 0)
    with pytest.raises(Sampled):
        check.run_check(MESH, count=0, out=lambda line: None, progress=lambda stage: None)


@pytest.mark.slow
def test_the_check_command_refuses_0():
    proc = run_scatter("check", MESH, "-n", 0)
    assert proc.returncode == 2 and proc.stderr.decode().startswith("error: -n must be at least 2"), proc.stderr


def test_the_check_command_takes_counts_as_sample_does(monkeypatch):
    """-n 1e3 is 1000 points, as for sample (the command's parser, run_check not run)."""
    from scatter_cli.commands import check

    asked = []
    monkeypatch.setattr(check, "run_check", lambda mesh, count, **rest: asked.append(count) or 0)
    assert command_in_process(["check", str(MESH), "-n", "1e3"]) == 0 and asked == [1000]
    assert command_in_process(["check", str(MESH), "-n", "1.5"]) == 2 and asked == [1000]


def old_numbers(values):
    """The sigmas as the API took them before: a text or a sequence only."""
    items = values.split(",") if isinstance(values, str) else values
    try:
        return tuple(float(v) for v in items)
    except (TypeError, ValueError):
        return values if isinstance(values, str) else str(values)


@pytest.mark.parametrize("broken", [False, True])
def test_one_sigma_is_a_number_in_the_api(monkeypatch, broken):
    if broken:
        monkeypatch.setattr(options, "_numbers", old_numbers)
    if broken:
        with pytest.raises(ScatterUsageError, match="--near"):
            scatter_cli.sample(MESH, 50, near=0.01)
        return
    one = scatter_cli.sample(MESH, 50, near=0.01, attributes="sdf")
    listed = scatter_cli.sample(MESH, 50, near=[0.01], attributes="sdf")
    assert one.points.tobytes() == listed.points.tobytes() and one.sdf.tobytes() == listed.sdf.tobytes()
    assert one.info["volume"]["near"] == [0.01]


@pytest.mark.parametrize("broken", [False, True])
def test_a_whole_float_is_a_count_in_the_api(monkeypatch, broken):
    """count=1e3 is 1000 points, as -n 1e3 is; 1.5 and infinity are still refused. The
    broken variant takes the float as it comes, and the check refuses it."""
    if broken:
        monkeypatch.setattr(options, "whole_count", lambda value: value)
        with pytest.raises(ScatterUsageError, match="count"):
            scatter_cli.sample(MESH, 1e3)
        return
    assert scatter_cli.sample(MESH, 1e3).points.tobytes() == scatter_cli.sample(MESH, 1000).points.tobytes()
    assert type(SampleOptions(count=1e3).count) is int
    for count in (1.5, float("inf"), float("nan")):
        with pytest.raises(ScatterUsageError, match="count"):
            scatter_cli.sample(MESH, count)


@pytest.mark.parametrize("broken", [False, True])
def test_a_count_too_large_to_hold_is_a_scatter_error(monkeypatch, broken):
    """The points of 10^15 (24 PB of float64) cannot be held, whatever the machine; the
    broken variant allocates as NumPy does and raises its MemoryError."""
    if broken:
        monkeypatch.setattr(api, "_hold", lambda count, shape, dtype: np.empty(shape, dtype))
    with pytest.raises((ScatterError, MemoryError)) as caught:
        scatter_cli.sample(MESH, 10**15, precision="float64")
    assert isinstance(caught.value, ScatterError) != broken
    assert broken or "1,000,000,000,000,000 points do not fit in memory" in str(caught.value)


@pytest.mark.parametrize("broken", [False, True])
def test_a_scheduler_without_the_dask_engine_is_a_usage_error(tmp_path, monkeypatch, broken):
    """The broken variant (the scheduler not checked) runs the batch locally and ignores it."""
    if broken:
        check = batch._check_batch_options
        monkeypatch.setattr(batch, "_check_batch_options", lambda *a: check(*a[:-1], None))
    run = lambda: batch.run_batch([MESH], str(tmp_path / "{stem}.csv"), scheduler="tcp://head:8786", jobs=1,  # noqa: E731
                                  options=SampleOptions(count=5), quiet=True)
    if broken:
        assert run()["written"] == 1
        return
    with pytest.raises(ScatterUsageError, match="--scheduler needs --engine dask"):
        run()
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("broken", [False, True])
def test_the_stats_volume_box_is_in_the_frame_of_the_points(monkeypatch, broken):
    """With --normalize, the box that --stats reports is the one the written points fill
    (box points uniform in it: their extremes lie within a few thousandths of its
    sides); the broken variant reports the world box."""
    if broken:
        monkeypatch.setattr(bounds, "in_frame", lambda box, frame: box)
    mesh = SAMPLES / "skull.ply"
    s = scatter_cli.sample(mesh, 4000, volume=True, normalize="unit-cube", precision="float64")
    box = np.array(s.info["volume"]["box"])
    side = (box[1] - box[0]).max()
    near = np.allclose(s.points.min(0), box[0], atol=0.01 * side) and np.allclose(s.points.max(0), box[1],
                                                                                    atol=0.01 * side)
    assert near != broken, (box, s.points.min(0), s.points.max(0))
