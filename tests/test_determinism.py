"""Same input, options and seed -> the same bytes, whatever the chunk size or threads."""

import hashlib

import numpy as np
import pytest

import scatter_cli
from scatter_cli.api import prepare
from scatter_cli.sampling.plan import uniforms

from .conftest import run_scatter, scatter_in_process


def test_stream_positions_do_not_depend_on_chunking():
    whole = uniforms(7, 0, 10_000)
    parts = np.concatenate([uniforms(7, a, min(a + 333, 10_000)) for a in range(0, 10_000, 333)])
    np.testing.assert_array_equal(whole, parts)


@pytest.mark.slow
@pytest.mark.parametrize("chunk_size", [1, 7, 1000, 4096, 1 << 20])
def test_api_identical_for_any_chunk_size(sample_mesh, chunk_size):
    n = 2_000 if chunk_size == 1 else 20_000  # (a chunk a point: fewer points, as many chunks)
    ref = scatter_cli.sample(sample_mesh("koala.obj"), n, attributes=("face", "bary"), seed=3)
    got = scatter_cli.sample(sample_mesh("koala.obj"), n, attributes=("face", "bary"), seed=3, chunk_size=chunk_size)
    for key in ("points", "face", "bary"):
        assert getattr(ref, key).tobytes() == getattr(got, key).tobytes()


def _bytes(run, threads):
    """The run's points, faces and objects, each field whole: the same bytes in any chunking."""
    chunks = list(run.chunks(threads=threads))
    return b"".join(np.concatenate([getattr(c, key) for c in chunks]).tobytes() for key in ("points", "face", "object"))


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_api_identical_for_any_thread_count(sample_mesh, threads):
    # the reference differs in both thread count and chunking from every case
    args = (sample_mesh("cesiummilktruck.glb"), 30_000)
    options = dict(attributes=("face", "object"), seed=5)
    ref = _bytes(prepare(*args, **options, chunk_size=4096), threads=4)
    assert _bytes(prepare(*args, **options, chunk_size=1000), threads=threads) == ref


@pytest.mark.slow
@pytest.mark.parametrize("method", ["stratified", "sobol"])
@pytest.mark.parametrize("chunk_size", [1, 7, 1000, 1 << 20])
def test_methods_identical_for_any_chunk_size(sample_mesh, method, chunk_size):
    mesh = sample_mesh("koala.obj")
    ref = scatter_cli.sample(mesh, 2_000, method=method, attributes=("face", "bary"), seed=3)
    got = scatter_cli.sample(mesh, 2_000, method=method, attributes=("face", "bary"), seed=3, chunk_size=chunk_size)
    for key in ("points", "face", "bary"):
        assert getattr(ref, key).tobytes() == getattr(got, key).tobytes()


@pytest.mark.parametrize("method", ["stratified", "sobol"])
@pytest.mark.parametrize("threads", [1, 2, 3])
def test_methods_identical_for_any_thread_count(sample_mesh, method, threads):
    args = (sample_mesh("cesiummilktruck.glb"), 30_000)
    options = dict(method=method, attributes=("face", "object"), seed=5)
    ref = _bytes(prepare(*args, **options, chunk_size=4096), threads=4)
    assert _bytes(prepare(*args, **options, chunk_size=997), threads=threads) == ref


@pytest.mark.parametrize("method", ["stratified", "sobol"])
def test_methods_depend_on_the_seed(sample_mesh, method):
    a = scatter_cli.sample(sample_mesh("skull.ply"), 100, seed=1, method=method).points
    b = scatter_cli.sample(sample_mesh("skull.ply"), 100, seed=2, method=method).points
    assert not np.array_equal(a, b)


def test_prefix_of_a_larger_run_is_the_smaller_run(sample_mesh):
    small = scatter_cli.sample(sample_mesh("skull.ply"), 1000, seed=11)
    large = scatter_cli.sample(sample_mesh("skull.ply"), 50_000, seed=11)
    assert small.points.tobytes() == large.points[:1000].tobytes()


def test_seeds_give_different_points(sample_mesh):
    a = scatter_cli.sample(sample_mesh("skull.ply"), 100, seed=1).points
    b = scatter_cli.sample(sample_mesh("skull.ply"), 100, seed=2).points
    assert not np.array_equal(a, b)


@pytest.mark.slow
@pytest.mark.parametrize("fmt,method", [("ply", "random"), ("csv", "random"), ("npy", "random"),
                                        ("ply", "stratified"), ("ply", "sobol")])
def test_command_output_bytes_identical_across_chunk_sizes_and_threads(sample_mesh, tmp_path, fmt, method):
    """The first run in a real process, the others through the command's entry point in
    this process (SCATTER_THREADS is read at each run)."""
    mesh = sample_mesh("spot_triangulated.obj")
    digests = set()
    for k, (chunk, threads) in enumerate([(None, "1"), ("999", "2"), ("65536", "2"), ("1", "1")]):
        out = tmp_path / f"out-{chunk}-{threads}.{fmt}"
        args = ["sample", mesh, "-n", "3000", "-a", "face,bary", "--seed", "9", "--method", method, "-o", out]
        if chunk:
            args += ["--chunk-size", chunk]
        (run_scatter if k == 0 else scatter_in_process)(*args, check=True, env={"SCATTER_THREADS": threads})
        digests.add(hashlib.sha256(out.read_bytes()).hexdigest())
    assert len(digests) == 1


@pytest.mark.slow
@pytest.mark.parametrize("attrs", [("normal",), ("smooth-normal", "bary", "object")])
def test_transformed_instances_identical_across_chunk_sizes(sample_mesh, attrs):
    """Rotated and instanced nodes: matrices are applied element-wise, so rounding does
    not depend on how many rows a chunk holds."""
    mesh = sample_mesh("cesiummilktruck.glb")
    ref = scatter_cli.sample(mesh, 5000, attributes=attrs, seed=8, chunk_size=5000)
    for chunk in (1, 333):
        got = scatter_cli.sample(mesh, 5000, attributes=attrs, seed=8, chunk_size=chunk)
        assert ref.points.tobytes() == got.points.tobytes()
        for key in got.attributes:
            assert ref.attributes[key].tobytes() == got.attributes[key].tobytes()
