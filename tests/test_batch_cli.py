"""`scatter batch`, `scatter sample --shard` and `scatter merge` as a user's shell runs them."""

import json
import os
import pty
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

import pytest

from .conftest import SAMPLES, popen_user, run_scatter, run_user, scatter_command, scatter_in_process
from .batchtools import (alive, collection, outputs, parent_of, reader_fd, reference, wait_for_reader,
                         warning_meshes)

pytestmark = pytest.mark.slow  # batches of subprocesses

MESHES = ["icosahedron_binary.stl", "moebius-160-10.ply", "hemisphere.off", "narrow_triangles.obj"]


def start_batch(*args):
    """`scatter batch ARGS` in its own session (so the test can kill its whole group)."""
    return popen_user(scatter_command("batch", *args), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                      start_new_session=True)


def folder_with_fifo(tmp_path):
    """a, b, c (a FIFO nobody writes to yet), d, e: with -j 1 the batch stops at c."""
    src = tmp_path / "in"
    src.mkdir()
    for letter, name in zip("abde", MESHES):
        shutil.copy(SAMPLES / name, src / f"{letter}{os.path.splitext(name)[1]}")
    os.mkfifo(src / "c.ply")
    return src


def test_resume_after_sigkill_gives_the_uninterrupted_outputs(tmp_path):
    src = folder_with_fifo(tmp_path)
    out = tmp_path / "out"
    args = [src, "-o", f"{out}/{{stem}}.ply", "-n", "200", "-a", "normal", "-j", "1"]
    proc = start_batch(*args)
    wait_for_reader(src / "c.ply")
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    os.close(reader_fd.pop())
    assert sorted(os.listdir(out)) == ["a.ply", "b.ply"]
    # what a run killed while writing leaves: temporary files beside the outputs
    (out / ".d.ply.k1ll3d_1.part").write_bytes(b"ply\nhalf a file")
    (out / ".a.ply.k1ll3d_2.part").write_bytes(b"ply\nhalf a file")
    os.unlink(src / "c.ply")
    shutil.copy(SAMPLES / "spot_triangulated.obj", src / "c.obj")
    done = run_scatter("batch", *args, "--skip-existing", "--report", tmp_path / "report.jsonl")
    assert done.returncode == 0, done.stderr
    assert done.stderr.decode().strip().splitlines()[-1].startswith("batch: 3 written, 2 skipped, 0 failed in ")
    report = [json.loads(line) for line in (tmp_path / "report.jsonl").read_text().splitlines()]
    assert [r["status"] for r in report] == ["skipped", "skipped", "written", "written", "written"]
    whole = run_scatter("batch", src, "-o", f"{tmp_path}/whole/{{stem}}.ply", "-n", "200", "-a", "normal")
    assert whole.returncode == 0
    assert outputs(out) == outputs(tmp_path / "whole")  # no .part left either


def test_sigterm_stops_the_batch_keeping_finished_outputs(tmp_path):
    src = folder_with_fifo(tmp_path)
    out = tmp_path / "out"
    proc = start_batch(src, "-o", f"{out}/{{stem}}.csv", "-n", "50", "-j", "1", "--report", tmp_path / "r.jsonl")
    wait_for_reader(src / "c.ply")
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    os.close(reader_fd.pop())
    assert proc.returncode == 143, err
    assert err.decode().strip().splitlines()[-1] == "error: terminated"
    assert sorted(os.listdir(out)) == ["a.csv", "b.csv"]
    assert [json.loads(line)["input"][-5:] for line in (tmp_path / "r.jsonl").read_text().splitlines()] == \
        ["a.stl", "b.ply"]


def test_exit_codes_and_error_lines(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(SAMPLES / MESHES[0], src / "good.stl")
    (src / "bad.obj").write_text("this is not a mesh\n")
    failed = run_scatter("batch", src, "-o", f"{tmp_path}/out/{{stem}}.xyz", "-n", "10", "-j", "2")
    assert failed.returncode == 1
    lines = failed.stderr.decode().splitlines()
    assert [line for line in lines if line.startswith("error:")] == [lines[0]] and "bad.obj" in lines[0]
    assert lines[-1].startswith("batch: 1 written, 0 skipped, 1 failed in ")
    assert "Traceback" not in failed.stderr.decode()
    collide = run_scatter("batch", src / "good.stl", src / "bad.obj", "-o", f"{tmp_path}/x.ply")
    assert collide.returncode == 2 and b"would both write" in collide.stderr
    nothing = run_scatter("batch", "--from-list", "-", "-o", f"{tmp_path}/{{stem}}.ply")
    assert nothing.returncode == 2
    no_scheduler = run_scatter("batch", src, "-o", f"{tmp_path}/d/{{stem}}.ply", "--engine", "dask",
                               env={"DASK_SCHEDULER_ADDRESS": ""})
    assert no_scheduler.returncode == 2 and b"--scheduler" in no_scheduler.stderr


PROGRESS = re.compile(r"batch: (\d+)/(\d+) done, (\d+) failed, [\d.]+ meshes/s, \d+ s left *$")


def test_progress_on_a_terminal_only(tmp_path):
    """On a terminal (a pseudo-terminal here) standard error shows meshes done, failed,
    the rate and the time left, erased before error lines and the summary; through a pipe,
    none of it."""
    src = folder_with_fifo(tmp_path)
    (src / "e.obj").write_text("not a mesh\n")  # replaces MESHES[3]: the one failure, last
    os.unlink(src / "d.off")
    os.replace(warning_meshes(tmp_path / "warn")[0], src / "d.obj")  # written, with a warning
    args = [src, "-o", f"{tmp_path}/out/{{stem}}.ply", "-n", "100", "-j", "1"]
    main, terminal = pty.openpty()
    proc = popen_user(scatter_command("batch", *args), stdout=subprocess.PIPE, stderr=terminal)
    os.close(terminal)
    screen = bytearray()
    reader = threading.Thread(target=read_all, args=(main, screen))
    reader.start()
    wait_for_reader(src / "c.ply", over=lambda: proc.poll() is not None)
    time.sleep(0.25)  # a lower bound, not a wait: c ends more than 0.2 s after a and b, so it is drawn
    with os.fdopen(reader_fd.pop(), "wb") as fifo:
        os.set_blocking(fifo.fileno(), True)
        fifo.write((SAMPLES / MESHES[1]).read_bytes())
    proc.communicate(timeout=120)
    reader.join(60)
    os.close(main)
    assert proc.returncode == 1
    text = screen.decode()
    pieces = [p.replace("\x1b[K", "") for p in re.split(r"[\r\n]+", text)]
    drawn = [tuple(map(int, m.groups())) for m in map(PROGRESS.match, pieces) if m]
    assert (3, 5, 0) in drawn and drawn[-1] == (5, 5, 1)
    assert drawn == sorted(drawn)
    assert [p for p in pieces if p.startswith("error:")] == [p for p in pieces if "e.obj" in p]
    assert len([p for p in pieces if p.startswith("error:")]) == 1
    assert [p for p in pieces if "warning:" in p] == [f"warning: {src / 'd.obj'}: skipped 1 faces with non-finite vertices"]
    assert text.rstrip().splitlines()[-1].startswith("\x1b[Kbatch: 4 written, 0 skipped, 1 failed in ")
    os.unlink(src / "c.ply")
    shutil.copy(SAMPLES / MESHES[1], src / "c.ply")
    piped = run_scatter("batch", *args[:-2], "-o", f"{tmp_path}/piped/{{stem}}.ply", "-j", "1")
    assert piped.returncode == 1
    err = piped.stderr.decode()
    assert "meshes/s" not in err and "\r" not in err and "\x1b" not in err
    assert err.splitlines()[-1].startswith("batch: 4 written, 0 skipped, 1 failed in ")


def read_all(fd, into):
    """What the terminal ``fd`` shows, until its other end is closed."""
    while True:
        try:
            block = os.read(fd, 4096)
        except OSError:  # EIO: the command and its workers are gone
            return
        if not block:
            return
        into += block


def test_from_list_on_standard_input(tmp_path):
    paths = [SAMPLES / m for m in MESHES[:2]]
    listing = "".join(f"{p}\n" for p in paths).encode()
    done = run_scatter("batch", "--from-list", "-", "-o", f"{tmp_path}/{{index}}-{{stem}}.npy", "-n", "20",
                       input=listing)
    assert done.returncode == 0, done.stderr
    assert sorted(os.listdir(tmp_path)) == ["0-icosahedron_binary.npy", "1-moebius-160-10.npy"]


# every format against the API in test_shards.py; here the commands, on two of them
@pytest.mark.parametrize("suffix,extra", [("ply", []), ("csv", [])])
def test_cli_shards_merge_into_the_whole_run(tmp_path, suffix, extra):
    mesh = SAMPLES / "moebius-160-10.ply"
    common = ["-n", "1001", "-a", "normal", *extra]
    run_scatter("sample", mesh, *common, "-o", tmp_path / f"whole.{suffix}", check=True)
    parts = []
    for k in range(3):  # (the shards through the command's entry point in this process)
        parts.append(tmp_path / f"part{k}.{suffix}")
        scatter_in_process("sample", mesh, *common, "--shard", f"{k}/3", "-o", parts[-1], check=True)
    run_scatter("merge", *parts, "-o", tmp_path / f"merged.{suffix}", check=True)
    assert (tmp_path / f"merged.{suffix}").read_bytes() == (tmp_path / f"whole.{suffix}").read_bytes()


def test_cli_shard_usage_errors(tmp_path):
    mesh = SAMPLES / "moebius-160-10.ply"
    for bad in (["--poisson"], ["--radius", "0.1"]):
        proc = run_scatter("sample", mesh, "-n", "10", "--shard", "0/2", *bad)
        assert proc.returncode == 2 and b"--shard" in proc.stderr
    proc = run_scatter("sample", mesh, "-n", "10", "--shard", "2/2")
    assert proc.returncode == 2
    run_scatter("sample", mesh, "-n", "10", "-o", tmp_path / "a.ply", check=True)
    run_scatter("sample", mesh, "-n", "10", "-a", "normal", "-o", tmp_path / "b.ply", check=True)
    proc = run_scatter("merge", tmp_path / "a.ply", tmp_path / "b.ply", "-o", tmp_path / "m.ply")
    assert proc.returncode == 1 and b"b.ply" in proc.stderr and not (tmp_path / "m.ply").exists()


@pytest.mark.parametrize("suffix", ["usda", "las"])
def test_batch_writes_what_sample_writes_for_formats_that_read_the_run(tmp_path, suffix):
    """LAS takes its scale from the sampled box and USD its up axis and units from the
    input: batch hands them over as `scatter sample` does (a Z-up USD stage in cm here)."""
    if suffix == "las":
        pytest.importorskip("laspy")
    else:
        pytest.importorskip("pxr")
        from .test_usd_output import stage_with_units
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(SAMPLES / "boxtextured.glb", src / "box.glb")
    meshes = ["box.glb"]
    if suffix == "usda":
        stage_with_units(src / "cube.usda", "Z", 0.01)
        meshes.append("cube.usda")
    done = run_scatter("batch", src, "-o", f"{tmp_path}/out/{{stem}}.{suffix}", "-n", "300", "-j", "1")
    assert done.returncode == 0, done.stderr
    for name in meshes:
        stem = os.path.splitext(name)[0]
        single = run_scatter("sample", src / name, "-n", "300", "-o", tmp_path / f"{stem}.{suffix}")
        assert single.returncode == 0
        assert (tmp_path / "out" / f"{stem}.{suffix}").read_bytes() == (tmp_path / f"{stem}.{suffix}").read_bytes()


def test_a_rerun_clears_what_a_batch_killed_with_sigkill_left(tmp_path):
    """kill -9 of a batch writing its second mesh, with --report: its worker dies with it,
    leaving that output's temporary file and the report's. A --skip-existing rerun of the
    same outputs and report removes both, and its report lists both meshes."""
    src = tmp_path / "in"
    src.mkdir()
    for letter in "ab":
        shutil.copy(SAMPLES / MESHES[0], src / f"{letter}.stl")
    out = tmp_path / "out"
    args = [src, "-o", f"{out}/{{stem}}.csv", "-n", "500000", "-j", "1", "--report", tmp_path / "report.jsonl"]
    proc = start_batch(*args)
    worker = None
    while worker is None:  # until b is being written: its temporary file is there
        assert proc.poll() is None, proc.communicate()
        if out.is_dir() and [p for p in out.iterdir() if p.name.startswith(".b.csv.")]:
            worker = next(pid for pid in children(proc.pid))
            os.kill(worker, signal.SIGSTOP)  # b stays half-written until the worker is killed
    with open(f"/proc/{worker}/cmdline", "rb") as f:
        assert b"scatter_cli.engines.worker" not in f.read()  # forked from the command, as it forks them
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 60
    while alive(worker):  # killed with its parent (PR_SET_PDEATHSIG)
        assert time.monotonic() < deadline, "the worker outlived its batch"
        time.sleep(0.01)
    assert sorted(p.name.split(".")[1] for p in tmp_path.rglob("*.part")) == ["b", "report"]
    assert (out / "a.csv").is_file() and not (tmp_path / "report.jsonl").exists()
    done = run_scatter("batch", *args[:3], "-n", "20", "-j", "1", "--report", tmp_path / "report.jsonl",
                       "--skip-existing")
    assert done.returncode == 0, done.stderr
    assert not [p for p in tmp_path.rglob("*.part")]
    report = [json.loads(line) for line in (tmp_path / "report.jsonl").read_text().splitlines()]
    assert [(os.path.basename(r["input"]), r["status"]) for r in report] == [("a.stl", "skipped"), ("b.stl", "written")]


def children(pid):
    """The pids of the processes whose parent is ``pid``."""
    return [int(p) for p in filter(str.isdigit, os.listdir("/proc")) if alive(int(p)) and parent_of(int(p)) == pid]


# the command with forking turned off, as where it may not fork: its workers are started
NEVER_FORKS = ("import sys; from scatter_cli.engines import worker; worker.can_fork = lambda: False; "
               "from scatter_cli.cli import run; sys.argv[0] = 'scatter'; run()")


def numpy_mapped(pid):
    with open(f"/proc/{pid}/maps") as f:
        return "_multiarray_umath" in f.read()


@pytest.mark.parametrize("command", ["scatter", "never forks"])
def test_the_command_forks_its_workers_warm(tmp_path, command):
    """The command as a user runs it, in a large environment (1 MB in 16 variables): it
    imports NumPy and the sampler, then forks its workers (not started as `python -m
    scatter_cli.engines.worker`), each its own child. A SIGKILL'd worker's mesh fails
    alone (the command reads the signal from the worker's exit status) and the other
    meshes are written byte for byte as `scatter sample` writes them. The broken variant,
    a command that starts its workers instead, is told apart by the same checks."""
    paths = collection(tmp_path / "in")
    ref = reference(tmp_path, paths)
    fifo = tmp_path / "in" / "fifo.csv.ply"
    os.mkfifo(fifo)
    args = ["batch", tmp_path / "in", "-o", tmp_path / "out" / "{stem}", "-n", 300, "-a", "normal,face", "-j", 2,
            "--report", tmp_path / "report.jsonl"]
    argv = scatter_command(*args) if command == "scatter" else [sys.executable, "-c", NEVER_FORKS, *map(str, args)]
    env = {f"SCATTER_TEST_FILL_{i}": "x" * 65536 for i in range(16)}
    proc = popen_user(argv, stderr=subprocess.PIPE, cwd=tmp_path, env=env)
    try:
        reader = wait_for_reader(fifo, over=lambda: proc.poll() is not None)
        assert parent_of(reader) == proc.pid
        with open(f"/proc/{reader}/cmdline") as f:
            forked = "scatter_cli.engines.worker" not in f.read()
        assert (forked, numpy_mapped(proc.pid)) == ((True, True) if command == "scatter" else (False, False))
        os.kill(reader, signal.SIGKILL)
        os.close(reader_fd.pop())
        err = proc.communicate(timeout=120)[1].decode()
    finally:
        proc.kill()
    assert proc.returncode == 1, err
    records = {os.path.basename(r["input"]): r for r in map(json.loads, (tmp_path / "report.jsonl").read_text().splitlines())}
    assert "killed by SIGKILL" in records["fifo.csv.ply"]["error"]
    assert [r["status"] for name, r in records.items() if name != "fifo.csv.ply"] == ["written"] * len(paths)
    assert outputs(tmp_path / "out") == ref


def test_a_folder_that_does_not_exist_is_named(tmp_path):
    """`scatter batch nope/ -o x/{rel}.ply`: the missing folder, not the empty {rel} it would
    have given (a file that does not exist fails alone, as before)."""
    proc = run_user(scatter_command("batch", "nope/", "-o", "x/{rel}.ply"), cwd=tmp_path)
    lines = proc.stderr.decode().strip().splitlines()
    assert proc.returncode == 1 and lines == ["error: nope/: no such folder"]
    assert not (tmp_path / "x").exists()
