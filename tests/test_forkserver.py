"""scatter_cli.engines.forkserver: a batch's workers forked by a server the command starts first,
each of them the command's own child (adopted through PR_SET_CHILD_SUBREAPER)."""

import json
import os
import signal
import subprocess
import sys
import textwrap

import pytest

from scatter_cli.engines import forkserver

from .batchtools import collection, outputs, parent_of, reader_fd, reference, wait_for_reader
from .conftest import ROOT, popen_user, run_user, scatter_command


@pytest.mark.parametrize("argv, wanted", [
    (["batch", "in/", "-o", "out/{stem}.ply"], True),
    (["--debug", "batch", "in/", "-o", "x/{stem}.ply", "-j", "2"], True),
    (["sample", "m.ply", "-o", "batch.ply"], False),
    (["batch", "--help"], False),
    (["batch", "in/", "-o", "o/{stem}.ply", "--engine", "dask"], False),
    (["batch", "in/", "-o", "o/{stem}.ply", "--engine=dask"], False),
    (["batch", "in/", "-o", "o/{stem}.ply", "--engine", "local"], True),
    (["batch", "in/", "-o", "o/{stem}.ply", "--scheduler=tcp://h:8786"], False),
    ([], False),
])
def test_only_a_local_batch_starts_a_server(argv, wanted, monkeypatch):
    monkeypatch.delenv("SCATTER_FORKSERVER", raising=False)
    assert forkserver.wanted(argv) is wanted
    monkeypatch.setenv("SCATTER_FORKSERVER", "0")
    assert forkserver.wanted(argv) is False


def numpy_mapped(pid):
    with open(f"/proc/{pid}/maps") as f:
        return "_multiarray_umath" in f.read()


@pytest.mark.slow
@pytest.mark.parametrize("server", ["1", "0"])
def test_a_batch_worker_is_the_commands_child(tmp_path, server):
    """The command as a user runs it: its workers come from the fork server (the command
    itself never imports NumPy; with SCATTER_FORKSERVER=0 it does, and forks them), yet
    each is the command's child (parent pid, and a SIGKILL it reads from the worker's exit
    status). The other meshes are written byte for byte as `scatter sample` writes them."""
    paths = collection(tmp_path / "in")
    ref = reference(tmp_path, paths)
    fifo = tmp_path / "in" / "fifo.csv.ply"
    os.mkfifo(fifo)
    proc = popen_user(scatter_command("batch", tmp_path / "in", "-o", tmp_path / "out" / "{stem}", "-n", 300,
                                      "-a", "normal,face", "-j", 2, "--report", tmp_path / "report.jsonl"),
                      stderr=subprocess.PIPE, cwd=tmp_path, env={"SCATTER_FORKSERVER": server})
    try:
        reader = wait_for_reader(fifo, over=lambda: proc.poll() is not None)
        assert parent_of(reader) == proc.pid
        assert numpy_mapped(proc.pid) is (server == "0")
        assert "scatter_cli.engines.worker" not in open(f"/proc/{reader}/cmdline").read()  # forked, not started
        os.kill(reader, signal.SIGKILL)
        os.close(reader_fd.pop())
        err = proc.communicate(timeout=120)[1].decode()
    finally:
        proc.kill()
    assert proc.returncode == 1, err
    records = {os.path.basename(r["input"]): r for r in map(json.loads, (tmp_path / "report.jsonl").read_text().split("\n")[:-1])}
    assert "killed by SIGKILL" in records["fifo.csv.ply"]["error"]
    assert [r["status"] for name, r in records.items() if name != "fifo.csv.ply"] == ["written"] * len(paths)
    assert outputs(tmp_path / "out") == ref


SCRIPT = textwrap.dedent("""
    import json, os, sys
    from scatter_cli.engines import forkserver
    from scatter_cli.engines.worker import Forked

    assert forkserver.start()
    server = forkserver.claim() if sys.argv[1] == "claim" else forkserver._server
    worker = Forked(dict(os.environ), server)
    with open(f"/proc/{worker.pid}/stat") as f:
        parent = int(f.read().rsplit(")", 1)[1].split()[1])
    try:
        worker.kill()
        status = worker.wait()
    except ChildProcessError:
        status = "not a child"
    print(json.dumps({"parent": parent, "me": os.getpid(), "status": status}))
""")


@pytest.mark.slow
def test_without_the_subreaper_a_worker_is_lost(tmp_path):
    """What claim() is for: the server's worker is this process's child only when this
    process is its subreaper; without it, the worker goes to another parent and this
    process can neither wait for it nor read how it ended."""
    def run(mode):
        done = run_user([sys.executable, "-c", SCRIPT, mode], cwd=tmp_path, env={"PYTHONPATH": str(ROOT)})
        assert done.returncode == 0, done.stderr.decode()
        return json.loads(done.stdout)

    claimed = run("claim")
    assert claimed["parent"] == claimed["me"] and claimed["status"] == -signal.SIGKILL
    lost = run("no-claim")
    assert lost["parent"] != lost["me"] and lost["status"] == "not a child"


FALLBACK = textwrap.dedent("""
    import json, os, signal, sys
    from scatter_cli.engines import forkserver
    from scatter_cli.run.options import SampleOptions
    from scatter_cli.engines.worker import WorkerProcess

    assert forkserver.start()
    os.kill(forkserver._server.pid, signal.SIGKILL)  # the server dies before it is asked
    server = forkserver.claim()
    setup = {"options": SampleOptions(count=100).as_dict(), "ascii": False, "crs": None, "quiet": True}
    worker = WorkerProcess(setup, dict(os.environ), server=server)
    worker.send(sys.argv[1], sys.argv[2], "ply")
    answer = worker.receive(timeout=60)
    worker.close()
    print(json.dumps({"worker": type(worker.proc).__name__, "error": answer["error"], "count": answer["count"]}))
""")


@pytest.mark.slow
def test_a_dead_server_leaves_the_batch_to_started_workers(tmp_path):
    """A fork server that died (killed, out of memory) costs only speed: the worker is
    started as a new process instead, and samples the mesh."""
    done = run_user([sys.executable, "-c", FALLBACK, str(ROOT / "samples" / "icosahedron_binary.stl"),
                     str(tmp_path / "out.ply")], cwd=tmp_path, env={"PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr.decode()
    assert json.loads(done.stdout) == {"worker": "Popen", "error": None, "count": 100}
    assert (tmp_path / "out.ply").stat().st_size > 100 * 12


@pytest.mark.slow
def test_a_large_environment_reaches_the_worker(tmp_path):
    """The worker's environment travels to the server as one message on a stream socket;
    one of several megabytes, more than the socket takes at once, arrives whole: the
    server forks the worker (a message cut short would leave it waiting for the rest, and
    the command would give up on it)."""
    script = textwrap.dedent("""
        import os, sys
        from scatter_cli.engines import forkserver
        from scatter_cli.engines.worker import Forked

        forkserver.REPLY_WITHIN = 20
        assert forkserver.start()
        worker = Forked(dict(os.environ, BIG="x" * 3_000_000), forkserver.claim())
        worker.kill()
        print(worker.wait())
    """)
    done = run_user([sys.executable, "-c", script], cwd=tmp_path, env={"PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr.decode()
    assert done.stdout.split() == [str(-signal.SIGKILL).encode()]
