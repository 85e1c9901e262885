"""The Dask engine on a real local cluster: a `dask scheduler` and two `dask worker`
processes on 127.0.0.1, started here and torn down after."""

import importlib.util
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

import pytest

import scatter_cli
from scatter_cli.engines import dask_engine, worker

from .conftest import ROOT, SAMPLES, popen_user, scatter_command
from .batchtools import (HANG, Feeder, alive, collection, outputs, parent_of, reference, run_elsewhere,
                         sample_in_process, sample_warnings, warning_lines, warning_meshes)

# (Dask is imported by the tests that start a cluster, not at collection: it takes a second)
pytestmark = pytest.mark.skipif(importlib.util.find_spec("distributed") is None, reason="dask[distributed] not installed")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_cluster(workers, scheduler_env=None, home=None):
    """A `dask scheduler` and ``workers`` one-thread `dask worker` processes on 127.0.0.1,
    the workers in the folder ``home``: (client, address, worker processes, all processes)."""
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    procs = [popen_user([*dask, "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], env=scheduler_env,
                        **quiet)]
    procs += [start_worker(address, home) for _ in range(workers)]
    try:
        import distributed

        client = distributed.Client(address, timeout=60, set_as_default=False)
        client.wait_for_workers(workers, timeout=60)
    except BaseException:
        stop(procs)
        raise
    return client, address, procs[1:], procs


def start_worker(address, home=None):
    """A one-thread `dask worker` process for the scheduler at ``address``, working in the
    folder ``home`` (default: a new one), not the tests' (as on another machine)."""
    own = home is None
    home = home or tempfile.mkdtemp(prefix="dask-worker-")
    proc = popen_user([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-nanny",
                       "--no-dashboard", "--host", "127.0.0.1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                      cwd=home, env={"PYTHONPATH": str(ROOT)})
    proc.own_home = home if own else None
    return proc


def stop(procs):
    for p in reversed(procs):
        p.kill()
        p.wait()
        if getattr(p, "own_home", None):
            shutil.rmtree(p.own_home, ignore_errors=True)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    home = tmp_path_factory.mktemp("dask-worker-home")
    client, address, workers, procs = start_cluster(2, home=home)
    try:
        yield client, address, workers, home  # a test may add workers to ``workers``
    finally:
        client.close()
        stop(procs + [w for w in workers if w not in procs])


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    base = tmp_path_factory.mktemp("meshes")
    paths = collection(base / "in")
    return base, paths, reference(base, paths)


@pytest.mark.slow
def test_dask_writes_what_sample_writes(tmp_path, cluster, meshes):
    client, address, _, _ = cluster
    base, paths, ref = meshes
    (base / "in" / "garbage.ply.stl").write_bytes(b"solid nothing\n" * 3)
    try:
        records = scatter_cli.batch([base / "in"], tmp_path / "out" / "{stem}", client=client, count=300,
                                    attributes="normal,face", report=tmp_path / "report.jsonl")
    finally:
        (base / "in" / "garbage.ply.stl").unlink()
    assert outputs(tmp_path / "out") == ref
    statuses = {os.path.basename(r["input"]): r["status"] for r in records}
    assert statuses.pop("garbage.ply.stl") == "failed"
    assert set(statuses.values()) == {"written"}
    local = scatter_cli.batch([base / "in"], tmp_path / "local" / "{stem}", jobs=1, count=300,
                              attributes="normal,face")
    assert [{k: v for k, v in r.items() if k != "seconds"} for r in records if r["status"] == "written"] == \
        [{k: v.replace("/local/", "/out/") if k == "output" else v for k, v in r.items() if k != "seconds"}
         for r in local]


class GroupsOfFour(dask_engine.GroupSize):
    """Tasks of four meshes from the first."""

    size = 4

    def learn(self, records):
        super().learn(records)
        self.size = 4


def batch_in_thread(client, inputs, out, **options):
    """``scatter_cli.batch`` of ``inputs`` to ``out/{stem}`` on the cluster, in a thread:
    (the thread, a dict that gets the records)."""
    result = {}
    thread = threading.Thread(target=lambda: result.update(records=scatter_cli.batch(
        inputs, str(out / "{stem}"), client=client, count=300, attributes="normal,face", **options)))
    thread.start()
    return thread, result


@pytest.mark.slow
def test_a_dask_worker_killed_mid_batch(tmp_path, cluster, meshes):
    """The lost worker's task runs again on the other one: every good mesh is written."""
    client, address, workers, _ = cluster
    base, paths, ref = meshes
    fifo = tmp_path / "in" / "fifo.npy.obj"  # gets narrow_triangles.obj's bytes, late
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    bad = tmp_path / "in" / "bad.ply.obj"
    bad.write_text("f 1 2 3\n")
    inputs = [fifo, bad, *paths]
    thread, result = batch_in_thread(client, inputs, tmp_path / "out")
    feeder = Feeder(fifo, over=lambda: not thread.is_alive())
    try:
        reader = feeder.next_reader()
        dask_worker = parent_of(reader)
        assert dask_worker in [w.pid for w in workers]
        os.kill(dask_worker, signal.SIGKILL)
        again = feeder.next_reader()  # the task again, on the other worker
        assert parent_of(again) in [w.pid for w in workers if w.pid != dask_worker]
        feeder.feed((SAMPLES / "narrow_triangles.obj").read_bytes())
    finally:
        feeder.close()
    thread.join(HANG)
    records = result["records"]
    assert [r["status"] for r in records] == ["written", "failed"] + ["written"] * len(paths)
    assert "bad.ply.obj" in records[1]["error"]
    got = outputs(tmp_path / "out")
    assert got.pop("fifo.npy") == ref["narrow_triangles.npy"]
    assert got == ref
    assert not [p for p in tmp_path.rglob("*.part")]
    assert not alive(reader)  # the sampling process died with its Dask worker


@pytest.mark.slow
def test_a_rerun_task_reports_written_what_this_batch_wrote(tmp_path, meshes, monkeypatch):
    """--skip-existing: a task that Dask runs again after losing its worker reports the
    meshes it had written there written (as an uninterrupted batch reports them), not
    skipped. One task of two meshes on a one-thread worker: it writes the first, then
    blocks on the FIFO; its worker is killed, and a new worker runs the task again."""
    base, paths, ref = meshes
    monkeypatch.setattr(dask_engine, "GroupSize", GroupsOfFour)
    client, address, workers, procs = start_cluster(1)
    try:
        fifo = tmp_path / "in" / "fifo.npy.obj"
        fifo.parent.mkdir()
        os.mkfifo(fifo)
        first = os.path.splitext(paths[0].name)[0]
        thread, result = batch_in_thread(client, [paths[0], fifo], tmp_path / "out", skip_existing=True)
        feeder = Feeder(fifo, over=lambda: not thread.is_alive())
        try:
            reader = feeder.next_reader()
            assert (tmp_path / "out" / first).read_bytes() == ref[first]  # written by this batch, this task
            os.kill(parent_of(reader), signal.SIGKILL)
            procs.append(start_worker(address))
            again = feeder.next_reader()
            assert parent_of(again) == procs[-1].pid
            feeder.feed((SAMPLES / "narrow_triangles.obj").read_bytes())
        finally:
            feeder.close()
        thread.join(HANG)
    finally:
        client.close()
        stop(procs)
    assert [(r["input"], r["status"]) for r in result["records"]] == [(str(paths[0]), "written"),
                                                                       (str(fifo), "written")]
    assert outputs(tmp_path / "out") == {first: ref[first], "fifo.npy": ref["narrow_triangles.npy"]}
    assert not [p for p in tmp_path.rglob("*.part")]


@pytest.fixture
def fragile_cluster():
    """Three workers; the scheduler gives a task up when its worker is lost twice
    (allowed-failures 1) and hands a worker one task at a time (worker-saturation 1.0),
    so a lost worker takes down no other mesh's task with it."""
    env = {"DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "1",
           "DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION": "1.0"}
    client, address, workers, procs = start_cluster(3, env)
    try:
        assert client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.allowed_failures) == 1
        yield client, address, workers, procs
    finally:
        client.close()
        stop(procs)


@pytest.mark.slow
def test_a_mesh_whose_workers_keep_dying_fails_alone(tmp_path, fragile_cluster, meshes):
    """Each time a worker opens the FIFO, it is killed: Dask gives the task up (KilledWorker)
    and the batch reports that mesh failed, one line, and writes every other mesh."""
    client, address, workers, procs = fragile_cluster
    base, paths, ref = meshes
    src = tmp_path / "in"
    src.mkdir()
    fifo = src / "0-killer.ply.obj"
    os.mkfifo(fifo)
    for copy in ("a", "b"):  # more tasks than twice the threads: Dask queues them (one per worker)
        (src / copy).mkdir()
        for p in paths:
            os.symlink(p, src / copy / p.name)
    out = tmp_path / "out"
    proc = popen_user(scatter_command("batch", src, "-o", f"{out}/{{rel}}", "-n", "300", "-a", "normal,face",
                                      "--engine", "dask", "--scheduler", address, "--report", tmp_path / "report.jsonl"),
                      stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    feeder = Feeder(fifo, over=lambda: proc.poll() is not None)
    killed = []
    try:
        for _ in range(2):  # allowed-failures + 1 lost workers
            killed.append(parent_of(feeder.next_reader()))
            assert killed[-1] in [w.pid for w in workers]
            os.kill(killed[-1], signal.SIGKILL)
    finally:
        feeder.close()  # a third run of the task would read an empty file: a different error
    stdout, stderr = proc.communicate(timeout=HANG)
    assert len(set(killed)) == 2
    assert proc.returncode == 1, stderr.decode()
    errors = [line for line in stderr.decode().splitlines() if line.startswith("error:")]
    assert errors == [f"error: {fifo}: the Dask worker sampling it was lost 2 times (Dask's allowed-failures)"]
    assert "Traceback" not in stderr.decode()
    report = [json.loads(line) for line in (tmp_path / "report.jsonl").read_text().splitlines()]
    assert [(r["input"], r["status"]) for r in report if r["status"] != "written"] == [(str(fifo), "failed")]
    assert len(report) == 1 + 2 * len(paths)
    for copy in ("a", "b"):
        assert {p.name: p.read_bytes() for p in (out / copy).iterdir()} == ref
    assert not (out / "0-killer.ply").exists()
    assert not [p for p in tmp_path.rglob("*.part")]


@pytest.mark.slow
def test_a_group_that_loses_its_workers_runs_again_one_mesh_a_task(tmp_path, fragile_cluster, meshes, monkeypatch):
    """A task of four meshes, one of them killing each worker that reads it: when Dask gives
    the task up, its meshes run again one a task; the three others are written, the killer
    alone fails."""
    client, address, workers, procs = fragile_cluster
    base, paths, ref = meshes
    monkeypatch.setattr(dask_engine, "GroupSize", GroupsOfFour)
    fifo = tmp_path / "in" / "killer.ply.obj"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    inputs = [paths[0], paths[1], fifo, *paths[2:]]  # tasks: the first four, then the last two
    thread, result = batch_in_thread(client, inputs, tmp_path / "out")
    feeder = Feeder(fifo, over=lambda: not thread.is_alive())
    try:
        for _ in range(4):  # (allowed-failures + 1) lost workers for the group, as many for the killer alone
            os.kill(parent_of(feeder.next_reader()), signal.SIGKILL)
            procs.append(start_worker(address))
    finally:
        feeder.close()  # a fifth run would read an empty file: a different error
    thread.join(HANG)
    records = result["records"]
    assert [r["status"] for r in records] == ["written", "written", "failed"] + ["written"] * (len(paths) - 2)
    assert records[2]["error"] == f"{fifo}: the Dask worker sampling it was lost 2 times (Dask's allowed-failures)"
    assert outputs(tmp_path / "out") == ref
    assert not [p for p in tmp_path.rglob("*.part")]


def test_group_size_follows_the_measured_time_per_mesh():
    size = dask_engine.GroupSize()
    assert size.size == 1  # nothing measured yet
    size.learn([{"seconds": 0.02}] * 10)
    assert size.size == 10  # 0.2 s / 20 ms
    size.learn([{"seconds": 0.2}])  # a bigger mesh among them: the mean (36 ms) is what counts
    assert size.size == 5
    big = dask_engine.GroupSize()
    big.learn([{"seconds": 3.0}] * 4)
    assert big.size == 1
    skipped = dask_engine.GroupSize()
    skipped.learn([{"seconds": 0.0}] * 4)
    assert skipped.size == dask_engine.MAX_GROUP


@pytest.mark.slow
def test_relative_paths_are_the_commands_not_the_workers(tmp_path, cluster, meshes):
    """The Dask workers run in a folder of their own: relative inputs, template and report
    are the command's, and --skip-existing looks where the tasks write."""
    client, address, _, home = cluster
    base, paths, ref = meshes
    cmd = tmp_path / "cmd"
    cmd.mkdir()
    collection(cmd / "coll")

    def batch(*args):
        done = run_elsewhere(cmd, "batch", *args, "-n", "300", "-a", "normal,face", "--engine", "dask",
                             "--scheduler", address)
        assert done.returncode == 0, done.stderr.decode()
        return [json.loads(line) for line in (cmd / args[-1]).read_text().splitlines()]

    report = batch("coll", "-o", "pts/{rel}", "--report", "report.jsonl")
    assert outputs(cmd / "pts") == ref
    names = sorted(p.name for p in paths)
    assert [(r["input"], r["output"], r["status"]) for r in report] == \
        [(f"coll/{n}", f"pts/{os.path.splitext(n)[0]}", "written") for n in names]
    first = os.path.splitext(names[0])[0]
    (cmd / "pts" / first).unlink()
    again = batch(cmd / "coll", "-o", "pts/{rel}", "--skip-existing", "--report", "again.jsonl")
    assert [r["status"] for r in again] == ["written"] + ["skipped"] * (len(names) - 1)
    assert outputs(cmd / "pts") == ref
    assert not [p for p in home.rglob("*") if p.name in ref or p.suffix == ".jsonl"]


@pytest.mark.slow
def test_warnings_name_their_mesh_on_both_engines(tmp_path, cluster):
    """A mesh's warnings reach the command's standard error from a Dask worker as from a
    local one: the lines `scatter sample` prints, each naming its mesh."""
    client, address, _, _ = cluster
    warning_meshes(tmp_path / "in")
    options = ["-n", "100"]
    expected = sorted(line for name in ("in/non-finite.obj", "in/far.obj")
                      for line in sample_warnings(name, tmp_path, *options))
    assert len(expected) == 2
    local = run_elsewhere(tmp_path, "batch", "in", "-o", "local/{stem}.ply", *options, "-j", "2")
    dask = run_elsewhere(tmp_path, "batch", "in", "-o", "dask/{stem}.ply", *options, "--engine", "dask",
                         "--scheduler", address)
    assert local.returncode == dask.returncode == 0, (local.stderr, dask.stderr)
    assert warning_lines(local.stderr) == warning_lines(dask.stderr) == expected
    quiet = run_elsewhere(tmp_path, "batch", "in", "-o", "quiet/{stem}.ply", *options, "--engine", "dask",
                          "--scheduler", address, "-q")
    assert quiet.returncode == 0 and quiet.stderr == b""


def temporary_files(folder):
    return sorted(p.name for p in folder.rglob("*.part"))


@pytest.mark.slow
def test_a_worker_killed_while_writing_leaves_no_temporary_file(tmp_path, cluster, monkeypatch):
    """A Dask worker killed while its sampling process writes a mesh's output: the task
    runs again on another worker and writes it, and the temporary file the killed one left
    is removed when the batch ends. The first reader of the FIFO gets a large triangle
    (tens of millions of points at the density asked, so the kill comes mid-write), the
    second the small mesh. The broken variant is the batch's state just before its end
    removes the temporary files: the killed worker's is there, and nothing else removes it."""
    client, address, workers, home = cluster
    fifo = tmp_path / "in" / "fifo.npy.obj"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    out = tmp_path / "out"
    density = ["--density", "18000"]  # about 300 points on narrow_triangles.obj
    sample_in_process(["sample", str(SAMPLES / "narrow_triangles.obj"), *density, "-o", str(tmp_path / "ref.npy")])
    at_end = []
    clear = dask_engine.BatchOutputs.clear_temps
    monkeypatch.setattr(dask_engine.BatchOutputs, "clear_temps",
                        lambda self: at_end.append(temporary_files(out)) or clear(self))
    result = {}
    thread = threading.Thread(target=lambda: result.update(records=scatter_cli.batch(
        [fifo], str(out / "{stem}"), client=client, density=18000)))
    thread.start()
    feeder = Feeder(fifo, over=lambda: not thread.is_alive())
    try:
        killed = parent_of(feeder.next_reader())
        feeder.feed(b"v 0 0 0\nv 47 0 0\nv 0 47 0\nf 1 2 3\n")
        while not temporary_files(out):
            assert thread.is_alive()
            time.sleep(0.02)
        if sum(map(alive, (w.pid for w in workers))) < 2:  # an earlier test killed the other
            workers.append(start_worker(address, home))
        os.kill(killed, signal.SIGKILL)
        again = feeder.next_reader()
        assert parent_of(again) != killed and alive(parent_of(again))
        feeder.feed((SAMPLES / "narrow_triangles.obj").read_bytes())
    finally:
        feeder.close()
    thread.join(HANG)
    assert [r["status"] for r in result["records"]] == ["written"]
    assert outputs(out) == {"fifo.npy": (tmp_path / "ref.npy").read_bytes()}
    [left] = at_end  # the files there when the batch's end clears them: the killed worker's
    assert len(left) == 1 and left[0].startswith(".fifo.npy.") and left[0].endswith(".part"), left
    assert temporary_files(tmp_path) == []


@pytest.mark.slow
@pytest.mark.parametrize("broken", [False, True])
def test_a_killed_sampling_process_is_retried_as_allowed_failures_says(tmp_path, cluster, meshes, monkeypatch,
                                                                      broken):
    """The sampling process of a Dask worker killed by hand: the task runs again (Dask's
    allowed-failures, 3 here) and the mesh is written. The broken variant, no retry, fails
    the mesh at once, and its message does not guess memory (a kill by hand)."""
    client, address, workers, home = cluster
    base, paths, ref = meshes
    if broken:
        monkeypatch.setattr(dask_engine, "allowed_failures", lambda client: 0)
    fifo = tmp_path / "in" / "fifo.npy.obj"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    thread, result = batch_in_thread(client, [fifo], tmp_path / "out")
    feeder = Feeder(fifo, over=lambda: not thread.is_alive())
    try:
        os.kill(feeder.next_reader(), signal.SIGKILL)
        if not broken:
            feeder.next_reader()
            feeder.feed((SAMPLES / "narrow_triangles.obj").read_bytes())
    finally:
        feeder.close()
    thread.join(HANG)
    [record] = result["records"]
    if broken:
        assert (record["status"], record["error"]) == \
            ("failed", f"{fifo}: its worker was killed by SIGKILL, 1 time (Dask's allowed-failures)")
        return
    assert record["status"] == "written" and dask_engine.allowed_failures(client) == 3
    assert outputs(tmp_path / "out") == {"fifo.npy": ref["narrow_triangles.npy"]}


@pytest.mark.slow
@pytest.mark.parametrize("broken", [False, True])
@pytest.mark.parametrize("engine", ["dask", "local"])
def test_a_rerun_of_either_engine_removes_what_a_killed_run_left(tmp_path, cluster, meshes, monkeypatch, engine,
                                                                  broken):
    """Outputs complete, and beside two of them the temporary files of a killed run: a
    rerun with --skip-existing skips every mesh and removes those files. The broken
    variants: the Dask batch's end clearing nothing, the local lanes clearing nothing."""
    client, address, workers, home = cluster
    base, paths, ref = meshes
    out = tmp_path / "out"
    out.mkdir()
    for name, data in ref.items():
        (out / name).write_bytes(data)
    left = [f".{name}.k1ll3d00.part" for name in sorted(ref)[:2]]
    for name in left:
        (out / name).write_bytes(b"half")
    if broken:
        target = dask_engine.BatchOutputs if engine == "dask" else worker.StaleTemps
        monkeypatch.setattr(target, "clear_temps" if engine == "dask" else "clear", lambda *a: None)
    where = {"client": client} if engine == "dask" else {"jobs": 1}
    records = scatter_cli.batch(paths, str(out / "{stem}"), skip_existing=True, count=300, **where)
    assert [r["status"] for r in records] == ["skipped"] * len(paths)
    assert outputs(out) == dict(ref, **({name: b"half" for name in left} if broken else {}))
