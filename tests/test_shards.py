"""Shards of one run (``shard=(K, M)``) and ``merge``: the parts joined are the run's bytes."""

import numpy as np
import pytest

from scatter_cli import api
from scatter_cli.errors import ScatterError, ScatterUsageError
from scatter_cli.commands.merge import merge
from scatter_cli.writers import infer_format, write_samples

from .conftest import SAMPLES

MESH = SAMPLES / "moebius-160-10.ply"
FORMATS = [("ply", False), ("ply", True), ("csv", False), ("xyz", False), ("npy", False)]


def write(path, ascii=False, mesh=MESH, **options):
    run = api.prepare(str(mesh), **options)
    write_samples(run.chunks(), str(path), infer_format(str(path)), run.layout, run.size, ascii)
    return run


def shards_merged(tmp_path, suffix, m, ascii=False, **options):
    parts = []
    for k in range(m):
        parts.append(tmp_path / f"part{k}.{suffix}")
        write(parts[-1], ascii, shard=(k, m), **options)
    merge(parts, tmp_path / f"merged.{suffix}")
    return (tmp_path / f"merged.{suffix}").read_bytes()


@pytest.mark.parametrize("suffix,ascii", FORMATS)
def test_merged_shards_are_the_whole_run(tmp_path, suffix, ascii):
    options = dict(count=1001, attributes="normal,face,bary", chunk_size=97)
    write(tmp_path / f"whole.{suffix}", ascii, **options)
    assert shards_merged(tmp_path, suffix, 3, ascii, **options) == (tmp_path / f"whole.{suffix}").read_bytes()


@pytest.mark.parametrize("method", ["stratified", "sobol"])
def test_merged_shards_other_methods(tmp_path, method):
    options = dict(count=500, method=method)
    write(tmp_path / "whole.ply", **options)
    assert shards_merged(tmp_path, "ply", 4, **options) == (tmp_path / "whole.ply").read_bytes()


def test_merged_shards_with_density_and_a_scene(tmp_path):
    options = dict(density=3.0, attributes="object,color")
    mesh = SAMPLES / "boxvertexcolors.glb"
    run = write(tmp_path / "whole.csv", mesh=mesh, **options)
    assert run.count == round(3.0 * run.info["area"])
    parts = []
    for k in range(5):
        parts.append(tmp_path / f"p{k}.csv")
        write(parts[-1], mesh=mesh, shard=(k, 5), **options)
    merge(parts, tmp_path / "merged.csv")
    assert (tmp_path / "merged.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()


@pytest.mark.parametrize("n", [0, 1, 7, 10, 1001])
@pytest.mark.parametrize("m", [1, 2, 3, 7])
def test_shard_counts_add_up(n, m):
    sizes = [api.prepare(str(MESH), n, shard=(k, m)).size for k in range(m)]
    assert sizes == [(k + 1) * n // m - k * n // m for k in range(m)]
    assert sum(sizes) == n


def test_a_shard_draws_only_its_own_points():
    run = api.prepare(str(MESH), 100_000, shard=(3, 4), chunk_size=4096)
    drawn = []
    job = run._job
    run._job = lambda start, stop: drawn.append((start, stop)) or job(start, stop)
    assert sum(len(c) for c in run.chunks()) == 25_000
    assert min(a for a, _ in drawn) == 75_000 and sum(b - a for a, b in drawn) == 25_000


def test_shard_samples_are_the_slice_of_the_whole():
    whole = api.sample(str(MESH), 300, attributes="normal")
    part = api.sample(str(MESH), 300, attributes="normal", shard=(1, 3))
    np.testing.assert_array_equal(part.points, whole.points[100:200])
    np.testing.assert_array_equal(part.normal, whole.normal[100:200])


@pytest.mark.parametrize("shard", [(3, 3), (-1, 2), "2", "a/b", (1, 0)])
def test_bad_shards_are_usage_errors(shard):
    with pytest.raises(ScatterUsageError):
        api.prepare(str(MESH), 10, shard=shard)


@pytest.mark.parametrize("thinning", [dict(poisson=True), dict(radius=0.1)])
def test_shard_with_thinning_is_a_usage_error(thinning):
    with pytest.raises(ScatterUsageError, match="--shard"):
        api.prepare(str(MESH), 10, shard=(0, 2), **thinning)


def test_merge_refuses_other_columns_naming_the_file(tmp_path):
    write(tmp_path / "a.ply", count=10)
    write(tmp_path / "b.ply", count=10)
    write(tmp_path / "c.ply", count=10, attributes="normal")
    with pytest.raises(ScatterError, match="c.ply"):
        merge([tmp_path / "a.ply", tmp_path / "b.ply", tmp_path / "c.ply"], tmp_path / "out.ply")
    write(tmp_path / "d.ply", ascii=True, count=10)
    with pytest.raises(ScatterError, match="d.ply"):
        merge([tmp_path / "a.ply", tmp_path / "d.ply"], tmp_path / "out.ply")
    assert not (tmp_path / "out.ply").exists()


def test_merge_refuses_other_formats_and_truncated_parts(tmp_path):
    write(tmp_path / "a.csv", count=10)
    write(tmp_path / "b.xyz", count=10)
    with pytest.raises(ScatterError, match="b.xyz"):
        merge([tmp_path / "a.csv", tmp_path / "b.xyz"], tmp_path / "out.csv")
    write(tmp_path / "c.npy", count=10)
    data = (tmp_path / "c.npy").read_bytes()
    (tmp_path / "d.npy").write_bytes(data[:-5])
    with pytest.raises(ScatterError, match="d.npy"):
        merge([tmp_path / "c.npy", tmp_path / "d.npy"], tmp_path / "out.npy")
    assert not (tmp_path / "out.npy").exists()


def test_exterior_shards_are_the_slice_of_the_whole():
    pytest.importorskip("embreex")
    mesh = str(SAMPLES / "boxtextured.glb")
    whole = api.sample(mesh, 500, exterior=True)
    parts = [api.sample(mesh, 500, exterior=True, shard=(k, 3)) for k in range(3)]
    assert [len(p) for p in parts] == [166, 167, 167]
    np.testing.assert_array_equal(np.concatenate([p.points for p in parts]), whole.points)


def test_stable_shards_are_the_slice_of_the_whole():
    whole = api.sample(str(MESH), 1000, stable=True)
    parts = [api.sample(str(MESH), 1000, stable=True, shard=(k, 3)) for k in range(3)]
    np.testing.assert_array_equal(np.concatenate([p.points for p in parts]), whole.points)
