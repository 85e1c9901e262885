"""Every option, and every combination, that is wrong whatever the mesh is refused before
the file is read (a large mesh is not loaded and planned only to be refused)."""

import pytest

from scatter_cli import api
from scatter_cli.run.options import SampleOptions
from scatter_cli.errors import ScatterUsageError

from .conftest import run_scatter

WRONG_FOR_ANY_MESH = {
    "--poisson with --radius": dict(poisson=True, radius=0.5),
    "--radius with --density": dict(radius=0.5, density=10.0),
    "--method with --poisson": dict(method="stratified", poisson=True),
    "--method with --radius": dict(method="sobol", radius=0.5),
    "--method with --weight": dict(method="stratified", weight="vertex-color:r"),
    "sobol past 2^32": dict(count=2**32 + 1, method="sobol"),
    "an unknown weight": dict(weight="curvature:r"),
    "too many --poisson points": dict(count=10**8, poisson=True),
    "oversampling below 0": dict(poisson=True, oversampling=-2),
    "count and density": dict(count=10, density=1.0),
    "a shard out of range": dict(shard="3/3"),
    "a shard that is no K/M": dict(shard="half"),
    "a shard with thinning": dict(shard=(0, 2), poisson=True),
    "a bad normalization": dict(normalize="unit-ball"),
    "--volume with --poisson": dict(volume=True, poisson=True),
    "--volume with --radius": dict(volume=True, radius=0.1),
    "--volume with --stable": dict(volume=True, stable=True),
    "--volume with --exterior": dict(volume=True, exterior=True),
    "--volume with --method sobol": dict(volume=True, method="sobol"),
    "--volume with normals": dict(volume=True, attributes="sdf,normal"),
    "--near with uv (it implies --volume)": dict(near="0.1", attributes=["uv"]),
    "--near with --stable": dict(near=(0.1, 0.02), stable=True),
    "a sigma of 0": dict(near="0.1,0"),
    "a sigma that is no number": dict(near="wide"),
    "a box share above 1": dict(volume=True, box_share=1.5),
    "a negative padding": dict(volume=True, padding=-0.1),
    "an unknown sign": dict(volume=True, sign="majority"),
    "a volume attribute on a surface run": dict(attributes="inside"),
}


def refuse_to_load(*args, **kwargs):
    raise AssertionError("the file was read before the options were checked")


@pytest.mark.parametrize("options", list(WRONG_FOR_ANY_MESH.values()), ids=list(WRONG_FOR_ANY_MESH))
def test_wrong_options_are_refused_before_the_file_is_read(monkeypatch, options):
    monkeypatch.setattr(api, "load_surface", refuse_to_load)
    with pytest.raises(ScatterUsageError):
        api.prepare("never-read.ply", **options)


def test_right_options_do_read_the_file(monkeypatch):
    # the same check with options that are fine: the loader is reached (the test can fail)
    monkeypatch.setattr(api, "load_surface", refuse_to_load)
    with pytest.raises(AssertionError, match="was read"):
        api.prepare("never-read.ply", 10, poisson=True)


@pytest.mark.slow
def test_the_command_names_the_option_not_the_missing_file(tmp_path):
    proc = run_scatter("sample", tmp_path / "missing.ply", "--poisson", "--radius", 0.5)
    err = proc.stderr.decode()
    assert proc.returncode == 2 and err.startswith("error: give either --poisson") and len(err.splitlines()) == 1


@pytest.mark.parametrize("options", list(WRONG_FOR_ANY_MESH.values()), ids=list(WRONG_FOR_ANY_MESH))
def test_the_options_object_refuses_them_itself(options):
    with pytest.raises(ScatterUsageError):
        SampleOptions(**options).check()


RIGHT = {
    "defaults": {},
    "volume with its settings": dict(volume=True, box_share=0.5, padding=0.0, sign="parity", attributes="sdf,inside"),
    "near sigmas": dict(near="0.0707,0.0224", box_share=0.06, normalize="unit-sphere", attributes=["sdf"]),
    "box share at its ends": dict(volume=True, box_share=0),
    "shard as a pair": dict(shard=(1, 4), attributes=("normal", "face")),
    "stable radius": dict(stable=True, radius=0.2, weight="texture:r"),
}


@pytest.mark.parametrize("options", list(RIGHT.values()), ids=list(RIGHT))
def test_right_option_sets_pass_the_check(options):
    assert SampleOptions(**options).check() == SampleOptions(**options)


def test_options_travel_as_json_and_come_back_equal():
    import json

    o = SampleOptions(count=5, attributes="Normal, face", objects=["a", "b"], shard="1/3", near="0.1,0.02")
    assert o.attributes == ("normal", "face") and o.shard == (1, 3) and o.near == (0.1, 0.02)
    assert SampleOptions(**json.loads(json.dumps(o.as_dict()))) == o
    assert SampleOptions(objects="Cube.001").objects == ("Cube.001",)  # one name is not its letters
    assert SampleOptions.of({"count": 5, "quiet": True, "output": "x.ply"}) == SampleOptions(count=5)
    with pytest.raises(TypeError):
        SampleOptions(colour=True)  # an unknown keyword is a programming error, not an option


def test_near_implies_volume_and_its_rules():
    o = SampleOptions(near="0.1")
    assert o.volume_run and not o.volume
    with pytest.raises(ScatterUsageError, match="--poisson"):
        SampleOptions(near="0.1", poisson=True).check()


def test_the_command_line_and_the_options_share_their_defaults():
    import inspect

    from scatter_cli import cli

    fields = {f: getattr(SampleOptions(), f) for f in SampleOptions.__dataclass_fields__}
    shared = {}
    for command in (cli.sample, cli.batch):
        params = inspect.signature(command).parameters
        shared[command.__name__] = {n for n in params if n in fields}
        for name in shared[command.__name__]:
            default = params[name].default
            assert default is None or default == fields[name], (command.__name__, name, default)
    assert shared["sample"] - {"input_format"} == shared["batch"]  # batch reads no standard input
    # what the command line does not offer: the API's oversampling
    assert set(fields) - shared["sample"] == {"oversampling"}


def test_whole_numbers_as_users_type_them():
    from scatter_cli.run.options import whole_number

    assert [whole_number(t) for t in ("100", "1e6", "2.5e3", "1E3", "1_000", "100000000000000000001")] == \
        [100, 10**6, 2500, 1000, 1000, 10**20 + 1]  # exact, not through a float
    for text in ("1.5", "1e-3", "inf", "nan", "ten", ""):
        with pytest.raises(ValueError):
            whole_number(text)
