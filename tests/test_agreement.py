"""``scatter sample MESH OPTIONS -o OUT`` and ``scatter batch MESH OPTIONS -o TEMPLATE`` agree:
the same exit status (0, 1 for a failure of the mesh, 2 for a usage error) and the same
bytes, over option sets that cover every option, the combinations each refuses, and the
failures a mesh causes. Both build one SampleOptions and write through one api.sample_to.

Each set also states the status it must give, so two commands that fail alike on a set
meant to succeed do not pass. The first two sets are the disagreements the house issue
found (``sample`` wrote ASCII PCD where ``batch`` refused it; an unknown ``--object`` was
exit 2 for ``sample``, 1 for ``batch``).
"""

import re

import numpy as np
import pytest

from .conftest import SAMPLES, run_scatter, scatter_in_process

ICO, COLOURS, CUBES = "ico", "colours", "cubes"

# (mesh, options, output suffix, exit status both must give)
SETS = {
    "ascii pcd": (ICO, ["--ascii"], "pcd", 0),
    "unknown --object": (CUBES, ["--object", "Nope"], "ply", 1),
    "plain": (ICO, [], "ply", 0),
    "attributes csv": (ICO, ["-a", "normal,face"], "csv", 0),
    "ascii ply": (ICO, ["--ascii", "-a", "normal"], "ply", 0),
    "ascii csv": (ICO, ["--ascii"], "csv", 2),
    "--object with its index": (CUBES, ["--object", "node0", "-a", "object"], "ply", 0),
    "colour the mesh lacks": (ICO, ["-a", "color"], "ply", 1),
    "texture weight the mesh lacks": (ICO, ["--weight", "texture:r"], "ply", 1),
    "poisson": (ICO, ["--poisson", "-n", "200"], "ply", 0),
    "radius": (ICO, ["--radius", "0.3"], "ply", 0),
    "radius too small for the mesh": (ICO, ["--radius", "1e-5"], "ply", 1),
    "stable": (ICO, ["--stable", "-a", "face"], "ply", 0),
    "stable radius": (ICO, ["--stable", "--radius", "0.3"], "ply", 0),
    "stable radius too small for the mesh": (ICO, ["--stable", "--radius", "1e-5"], "ply", 1),
    "stratified": (ICO, ["--method", "stratified"], "xyz", 0),
    "sobol with bary": (ICO, ["--method", "sobol", "-a", "bary"], "npy", 0),
    "density": (ICO, ["--density", "5"], "ply", 0),
    "count 1e3": (ICO, ["-n", "1e3"], "ply", 0),
    "count 1.5": (ICO, ["-n", "1.5"], "ply", 2),
    "poisson and radius": (ICO, ["--poisson", "--radius", "0.3"], "ply", 2),
    "stable and poisson": (ICO, ["--stable", "--poisson"], "ply", 2),
    "shard": (ICO, ["--shard", "1/3", "-a", "normal"], "ply", 0),
    "shard out of range": (ICO, ["--shard", "3/3"], "ply", 2),
    "shard with poisson": (ICO, ["--shard", "1/3", "--poisson"], "ply", 2),
    "vertex-colour weight": (COLOURS, ["--weight", "vertex-color:g", "-a", "color"], "ply", 0),
    "stratified with poisson": (ICO, ["--method", "stratified", "--poisson"], "ply", 2),
    "both normals": (ICO, ["-a", "normal,smooth-normal"], "ply", 2),
    "unknown attribute": (ICO, ["-a", "curvature"], "ply", 2),
    "volume-only attribute": (ICO, ["-a", "sdf"], "ply", 2),
    "float64 npy": (ICO, ["--precision", "float64"], "npy", 0),
    "exterior scene": (CUBES, ["--exterior", "-a", "object"], "ply", 0),
    "normalize": (ICO, ["--normalize", "unit-sphere", "-a", "normal"], "csv", 0),
    "bad normalize": (ICO, ["--normalize", "unit-ball"], "ply", 2),
    "negative seed": (ICO, ["--seed", "-1"], "ply", 2),
    "chunk size 0": (ICO, ["--chunk-size", "0"], "ply", 2),
    "las": (ICO, ["-a", "face"], "las", 0),
}


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    from .test_selection import three_cubes

    return {ICO: SAMPLES / "icosahedron_binary.stl", COLOURS: SAMPLES / "boxvertexcolors.glb",
            CUBES: three_cubes(tmp_path_factory.mktemp("cubes") / "three_cubes.glb")}


def sized(options):
    """A small count unless the set gives its own (a count, a density or a radius)."""
    return options if {"-n", "--density", "--radius"} & set(options) else [*options, "-n", "300"]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SETS))
def test_sample_and_batch_agree(meshes, tmp_path, name):
    mesh, options, suffix, status = SETS[name]
    options = sized(options)
    run = run_scatter if name == next(iter(SETS)) else scatter_in_process  # one in a real process
    one = run("sample", meshes[mesh], *options, "-o", tmp_path / f"sample.{suffix}")
    many = run_scatter("batch", meshes[mesh], *options, "-o", tmp_path / "batch" / f"{{stem}}.{suffix}", "-j", "1")
    assert (one.returncode, many.returncode) == (status, status), (one.stderr.decode(), many.stderr.decode())
    written = sorted((tmp_path / "batch").glob(f"*.{suffix}")) if (tmp_path / "batch").exists() else []
    if status == 0:
        assert len(written) == 1 and written[0].read_bytes() == (tmp_path / f"sample.{suffix}").read_bytes()
        assert written[0].stat().st_size > 0
    else:
        assert not written and not (tmp_path / f"sample.{suffix}").exists()
        first = one.stderr.decode().splitlines()[0]
        message = re.sub(r" \(see 'scatter sample --help'\)$", "", first)  # the hint names the command
        assert first.startswith("error: ") and message[len("error: "):] in many.stderr.decode(), (first, many.stderr)


def test_the_python_batch_and_sample_agree_too(meshes, tmp_path):
    import scatter_cli

    records = scatter_cli.batch([meshes[CUBES]], str(tmp_path / "{stem}.npy"), count=400, objects=["node1"],
                                attributes=["object", "normal"], seed=5)
    assert records[0]["status"] == "written"
    written = np.load(tmp_path / "three_cubes.npy")
    direct = scatter_cli.sample(meshes[CUBES], 400, objects=["node1"], attributes=["object", "normal"], seed=5)
    np.testing.assert_array_equal(written["x"], direct.points[:, 0])
    np.testing.assert_array_equal(written["object_index"], direct.object)
    failed = scatter_cli.batch([meshes[CUBES]], str(tmp_path / "f-{stem}.npy"), count=10, objects=["Nope"])
    assert failed[0]["status"] == "failed" and "Nope" in failed[0]["error"]


@pytest.mark.slow
@pytest.mark.parametrize("suffix", ["ply", "las"])
def test_api_write_writes_what_the_command_writes(meshes, tmp_path, suffix):
    from scatter_cli import api
    from scatter_cli.writers import run_precision

    run_scatter("sample", meshes[CUBES], "-n", "500", "-a", "normal,object", "-o", tmp_path / f"cli.{suffix}",
                check=True)
    run = api.prepare(meshes[CUBES], 500, attributes="normal,object", precision=run_precision(suffix, "auto"))
    api.write(run, tmp_path / f"api.{suffix}")
    assert (tmp_path / f"api.{suffix}").read_bytes() == (tmp_path / f"cli.{suffix}").read_bytes()
