"""The Dask engine on a real local cluster: a `dask scheduler` and two `dask worker`
processes on 127.0.0.1, started here and torn down after."""

import json
import os
import signal
import socket
import subprocess
import sys
import threading

import pytest

import scatter_cli

from .conftest import SAMPLES, popen_user, scatter_command
from .batchtools import collection, gone, outputs, parent_of, reference, reader_fd, wait_for_reader

distributed = pytest.importorskip("distributed")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_cluster(workers, scheduler_env=None):
    """A `dask scheduler` and ``workers`` one-thread `dask worker` processes on 127.0.0.1:
    (client, address, worker processes, all processes)."""
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    procs = [popen_user([*dask, "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], env=scheduler_env,
                        **quiet)]
    worker = [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-nanny",
              "--no-dashboard", "--host", "127.0.0.1"]
    procs += [popen_user(worker, **quiet) for _ in range(workers)]
    try:
        client = distributed.Client(address, timeout=60, set_as_default=False)
        client.wait_for_workers(workers, timeout=60)
    except BaseException:
        stop(procs)
        raise
    return client, address, procs[1:], procs


def stop(procs):
    for p in reversed(procs):
        p.kill()
        p.wait()


@pytest.fixture(scope="module")
def cluster():
    client, address, workers, procs = start_cluster(2)
    try:
        yield client, address, workers
    finally:
        client.close()
        stop(procs)


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    base = tmp_path_factory.mktemp("meshes")
    paths = collection(base / "in")
    return base, paths, reference(base, paths)


def test_dask_writes_what_sample_writes(tmp_path, cluster, meshes):
    client, address, _ = cluster
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


def test_a_dask_worker_killed_mid_batch(tmp_path, cluster, meshes):
    """The lost worker's task runs again on the other one: every good mesh is written."""
    client, address, workers = cluster
    base, paths, ref = meshes
    fifo = tmp_path / "in" / "fifo.npy.obj"  # gets narrow_triangles.obj's bytes, late
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    bad = tmp_path / "in" / "bad.ply.obj"
    bad.write_text("f 1 2 3\n")
    inputs = [fifo, bad, *paths]
    result = {}
    thread = threading.Thread(target=lambda: result.update(records=scatter_cli.batch(
        inputs, str(tmp_path / "out" / "{stem}"), client=client, count=300, attributes="normal,face")))
    thread.start()
    over = lambda: not thread.is_alive()  # noqa: E731
    reader = wait_for_reader(fifo, timeout=120, over=over)
    dask_worker = parent_of(reader)
    assert dask_worker in [w.pid for w in workers]
    os.kill(dask_worker, signal.SIGKILL)
    gone(reader)  # the sampling process dies with its Dask worker
    os.close(reader_fd.pop())
    wait_for_reader(fifo, timeout=120, over=over)  # the task again, on the other worker
    with os.fdopen(reader_fd.pop(), "wb") as f:
        os.set_blocking(f.fileno(), True)
        f.write((SAMPLES / "narrow_triangles.obj").read_bytes())
    thread.join(120)
    records = result["records"]
    assert [r["status"] for r in records] == ["written", "failed"] + ["written"] * len(paths)
    assert "bad.ply.obj" in records[1]["error"]
    got = outputs(tmp_path / "out")
    assert got.pop("fifo.npy") == ref["narrow_triangles.npy"]
    assert got == ref
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
        yield address, workers
    finally:
        client.close()
        stop(procs)


def test_a_mesh_whose_workers_keep_dying_fails_alone(tmp_path, fragile_cluster, meshes):
    """Each time a worker opens the FIFO, it is killed: Dask gives the task up (KilledWorker)
    and the batch reports that mesh failed, one line, and writes every other mesh."""
    address, workers = fragile_cluster
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
    over = lambda: proc.poll() is not None  # noqa: E731
    killed = []
    for _ in range(2):  # allowed-failures + 1 lost workers
        reader = wait_for_reader(fifo, timeout=120, over=over)
        killed.append(parent_of(reader))
        assert killed[-1] in [w.pid for w in workers]
        os.kill(killed[-1], signal.SIGKILL)
        gone(reader)
        os.close(reader_fd.pop())
    stdout, stderr = proc.communicate(timeout=120)
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
