"""Volume runs through the real command: usage errors, formats, shards, batch, stats."""

import json

import numpy as np
import pytest

from tests.conftest import SAMPLES, run_scatter, scatter_in_process

pytestmark = pytest.mark.slow  # a subprocess a test

ICO = SAMPLES / "icosahedron_binary.stl"
HEMI = SAMPLES / "hemisphere.off"


USAGE_ERRORS = [
    ["--volume", "-a", "normal"],
    ["--volume", "-a", "orient"],
    ["--near", "0.1", "-a", "color"],
    ["--volume", "--poisson"],
    ["--volume", "--radius", "0.1"],
    ["--volume", "--stable"],
    ["--volume", "--exterior"],
    ["--volume", "--method", "sobol"],
    ["-a", "sdf"],
    ["-a", "inside"],
    ["--near", "0"],
    ["--near", "-0.1"],
    ["--near", "0.1,x"],
    ["--volume", "--box-share", "1.5"],
    ["--volume", "--padding", "-1"],
    ["--volume", "--sign", "rays"],
    ["--normalize", "unit-ball"],
]


@pytest.mark.parametrize("args", USAGE_ERRORS)
def test_usage_errors_are_one_line_and_exit_2(args, tmp_path):
    out = tmp_path / "o.ply"
    run = run_scatter if args == USAGE_ERRORS[0] else scatter_in_process  # one in a real process
    proc = run("sample", ICO, "-n", "100", *args, "-o", out)
    lines = proc.stderr.decode().strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), proc.stderr
    assert not out.exists()


def test_csv_columns_in_contract_order(tmp_path):
    proc = run_scatter("sample", ICO, "--volume", "-n", "50", "-a", "object,face,closest,winding,inside,sdf",
                       "-f", "csv", check=True)
    header = proc.stdout.decode().splitlines()[0]
    assert header == "x,y,z,sdf,inside,winding,cx,cy,cz,face_index,object_index"


def test_a_prefix_is_the_shorter_run(tmp_path):
    args = ["--near", "0.05,0.01", "--box-share", "0.2", "-a", "sdf,inside", "-f", "csv", "--seed", "9"]
    long = run_scatter("sample", HEMI, "-n", "3000", *args, check=True).stdout.decode().splitlines()
    short = run_scatter("sample", HEMI, "-n", "1000", *args, check=True).stdout.decode().splitlines()
    assert short == long[:1001]


@pytest.mark.parametrize("suffix", ["ply", "xyz", "las"])  # binary, text, and a header with counts and bounds
def test_shards_merge_to_the_whole_run(suffix, tmp_path):
    args = ["--volume", "-n", "2000", "-a", "sdf,inside,closest", "--seed", "3"]
    whole = tmp_path / f"whole.{suffix}"
    run_scatter("sample", ICO, *args, "-o", whole, check=True)
    parts = []
    for k in range(3):  # (the shards through the command's entry point in this process)
        part = tmp_path / f"part{k}.{suffix}"
        scatter_in_process("sample", ICO, *args, "--shard", f"{k}/3", "-o", part, check=True)
        parts.append(part)
    merged = tmp_path / f"merged.{suffix}"
    run_scatter("merge", *parts, "-o", merged, check=True)
    assert merged.read_bytes() == whole.read_bytes()


def test_labels_read_back_from_ply(tmp_path):
    import trimesh

    out = tmp_path / "v.ply"
    run_scatter("sample", ICO, "--volume", "-n", "500", "-a", "sdf,inside", "-o", out, check=True)
    cloud = trimesh.load(out)
    props = cloud.metadata["_ply_raw"]["vertex"]["data"]
    inside = props["inside"].astype(bool)
    assert ((props["sdf"] < 0) == inside).all() and 0 < inside.mean() < 1


def test_batch_writes_what_sample_writes(tmp_path):
    args = ["--near", "0.02", "--box-share", "0.5", "-n", "400", "-a", "sdf,face", "--normalize", "unit-cube"]
    alone = tmp_path / "alone.ply"
    run_scatter("sample", HEMI, *args, "-o", alone, check=True)
    run_scatter("batch", HEMI, *args, "-o", tmp_path / "b" / "{stem}.ply", "-j", "1", check=True)
    assert (tmp_path / "b" / "hemisphere.ply").read_bytes() == alone.read_bytes()


def test_stats_record_the_frame(tmp_path):
    stats = tmp_path / "s.json"
    run_scatter("sample", ICO, "--volume", "-n", "100", "--normalize", "unit-sphere", "-a", "sdf",
                "-o", tmp_path / "o.npy", "--stats", stats, check=True)
    info = json.loads(stats.read_text())
    frame = info["normalize"]
    assert frame["mode"] == "unit-sphere" and len(frame["offset"]) == 3 and frame["scale"] > 0
    data = np.load(tmp_path / "o.npy")
    assert np.abs(np.stack([data["x"], data["y"], data["z"]], 1)).max() <= 1.0 + 2 * 0.1 * 2
