"""The Dask engine on a real local cluster: a `dask scheduler` and two `dask worker`
processes on 127.0.0.1, started here and torn down after."""

import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

import scatter_cli

from .conftest import SAMPLES, popen_user
from .batchtools import collection, outputs, reference, reader_fd, wait_for_reader

distributed = pytest.importorskip("distributed")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cluster():
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    procs = [popen_user([*dask, "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], **quiet)]
    worker = [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-nanny",
              "--no-dashboard", "--host", "127.0.0.1"]
    procs += [popen_user(worker, **quiet) for _ in range(2)]
    client = distributed.Client(address, timeout=60, set_as_default=False)
    try:
        client.wait_for_workers(2, timeout=60)
        yield client, address, procs[1:]
    finally:
        client.close()
        for p in reversed(procs):
            p.kill()
            p.wait()


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
    reader = wait_for_reader(fifo)
    dask_worker = int(open(f"/proc/{reader}/stat").read().rsplit(")", 1)[1].split()[1])
    assert dask_worker in [w.pid for w in workers]
    os.kill(dask_worker, signal.SIGKILL)
    gone(reader)  # the sampling process dies with its Dask worker
    os.close(reader_fd.pop())
    wait_for_reader(fifo, timeout=120)  # the task again, on the other worker (Dask may take a while to notice)
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


def gone(pid, timeout=30):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            state = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
        except OSError:
            return
        if state in "ZX":
            return
        time.sleep(0.02)
    raise AssertionError(f"process {pid} still alive")
