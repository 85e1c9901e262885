"""``scatter_cli.batch``: the same bytes as ``scatter sample``, and one bad mesh fails alone."""

import json
import os
import shutil
import threading

import numpy as np
import pytest

import scatter_cli
from scatter_cli.engines import batch, worker
from scatter_cli.errors import ScatterUsageError
from scatter_cli.run.options import SampleOptions

from .batchtools import collection, no_temporary_files, outputs, reader_fd, reference, wait_for_reader
from .conftest import ROOT, SAMPLES, triangles_mesh


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    base = tmp_path_factory.mktemp("meshes")
    paths = collection(base / "in")
    return base, paths, reference(base, paths), reference(base, paths[:2], "--ascii", "-f", "ply")


@pytest.mark.slow
@pytest.mark.parametrize("jobs", [1, 2])
def test_batch_writes_what_sample_writes(tmp_path, meshes, jobs):
    base, paths, ref, _ = meshes
    records = scatter_cli.batch([base / "in"], tmp_path / "out" / "{stem}", jobs=jobs, count=300,
                                attributes="normal,face", report=tmp_path / "report.jsonl")
    assert outputs(tmp_path / "out") == ref
    assert [r["status"] for r in records] == ["written"] * len(paths)
    assert [r["input"] for r in records] == sorted(str(p) for p in paths)
    lines = [json.loads(line) for line in (tmp_path / "report.jsonl").read_text().splitlines()]
    assert lines == records
    assert set(lines[0]) == {"input", "output", "status", "error", "count", "faces", "area", "seconds"}


@pytest.mark.slow
def test_batch_ascii_ply(tmp_path, meshes):
    base, paths, _, ref_ascii = meshes
    scatter_cli.batch(paths[:2], str(tmp_path / "{stem}"), jobs=2, count=300, attributes="normal,face", ascii=True,
                      format="ply")
    assert outputs(tmp_path) == ref_ascii


def test_template_fields_and_collisions(tmp_path):
    tree = tmp_path / "in"
    (tree / "a" / "b").mkdir(parents=True)
    shutil.copy(SAMPLES / "icosahedron_binary.stl", tree / "a" / "b" / "x.stl")
    shutil.copy(SAMPLES / "icosahedron_binary.stl", tree / "a" / "x.stl")
    (tree / "notes.txt").write_text("not a mesh")
    records = scatter_cli.batch([tree], str(tmp_path / "out" / "{rel}-{index}-{name}.csv"), jobs=1, count=5)
    assert [os.path.relpath(r["output"], tmp_path / "out") for r in records] == \
        ["a/b/x-0-x.stl.csv", "a/x-1-x.stl.csv"]
    with pytest.raises(ScatterUsageError, match="would both write"):
        scatter_cli.batch([tree], str(tmp_path / "flat" / "{stem}.csv"), count=5)
    with pytest.raises(ScatterUsageError, match="field"):
        scatter_cli.batch([tree], str(tmp_path / "{size}.csv"), count=5)
    with pytest.raises(ScatterUsageError, match="format"):
        scatter_cli.batch([tree], str(tmp_path / "{rel}.obj"), count=5)
    assert not (tmp_path / "flat").exists()


@pytest.mark.parametrize("text", ["{stem}.ply", "{rel}/{index:05d}.ply", "{name:>12}-{stem[0]}.csv", "x.npy",
                                  "{index}{rel}{name}{stem}.ply"])
def test_a_template_fills_only_its_fields_and_gets_every_path_right(tmp_path, text):
    tree = tmp_path / "in"
    (tree / "a").mkdir(parents=True)
    for path in (tree / "a" / "x.y.stl", tree / "b.obj"):
        path.write_bytes(b"")
    found = batch.collect_inputs([tree, tmp_path / "in" / "a" / "x.y.stl"])
    template = batch.Template(text)
    assert template.fields == {f for f in batch.TEMPLATE_FIELDS if "{" + f in text}
    for i in range(len(found)):
        full = found.fields(i)
        assert template.output(found, i) == text.format(**full)
        assert found.fields(i, template.fields).items() <= full.items()
    assert [found.fields(i)["rel"] for i in range(len(found))] == ["a/x.y", "b", "x.y"]


def bad_meshes(folder):
    """{path: what its error says} for meshes that must fail, written into ``folder``."""
    folder.mkdir(exist_ok=True)
    bad = {}
    (folder / "garbage.stl").write_bytes(np.random.default_rng(1).bytes(300))
    bad["garbage.stl"] = "garbage.stl"
    (folder / "empty.obj").write_bytes(b"")
    bad["empty.obj"] = "empty"
    flat = triangles_mesh([[[0, 0, 0], [1, 1, 1], [2, 2, 2]]] * 3)
    flat.export(folder / "zero-area.ply")
    bad["zero-area.ply"] = "area"
    (folder / "non-finite.obj").write_text("v nan nan nan\n" * 3 + "f 1 2 3\n")
    bad["non-finite.obj"] = "non-finite|no area|no faces"
    os.symlink(folder / "nowhere.ply", folder / "dangling.ply")
    bad["dangling.ply"] = "no such file"
    return bad


@pytest.fixture(params=["forked", "started"])
def workers(request, monkeypatch):
    """How the local engine starts its workers: forked from this process (as the command
    does), or each started as `python -m scatter_cli.engines.worker` (a program with threads)."""
    monkeypatch.setattr(worker, "can_fork", lambda: request.param == "forked")
    return request.param


def test_workers_are_forked_only_from_a_lone_main_thread():
    assert worker.can_fork() is (threading.active_count() == 1)
    got = []
    thread = threading.Thread(target=lambda: got.append(worker.can_fork()))
    thread.start()
    thread.join()
    assert got == [False]


@pytest.mark.slow
def test_bad_meshes_fail_alone(tmp_path, meshes, workers):
    base, paths, ref, _ = meshes
    bad = bad_meshes(tmp_path / "bad")
    os.mkfifo(tmp_path / "bad" / "fifo.ply")  # nobody writes to it: only --timeout ends it
    bad["fifo.ply"] = "timed out after 6 s"
    hog = tmp_path / "bad" / "hog.stl"  # its area makes --density ask for 2.5 million points
    mesh = scatter_cli.load_surface(str(SAMPLES / "icosahedron_binary.stl"))
    big = triangles_mesh(mesh.geometries[0].vertices[mesh.geometries[0].faces] * 70.0)
    big.export(hog)
    bad["hog.stl"] = "exceeded --max-memory 200 MB"
    small = tmp_path / "small"
    small.mkdir()
    for p in paths[:2]:  # area about 10: 100 points a mesh at density 10
        shutil.copy(p, small / p.name)
    inputs = [small / p.name for p in paths[:2]] + sorted((tmp_path / "bad").iterdir())
    records = scatter_cli.batch(inputs, str(tmp_path / "out" / "{stem}.ply"), jobs=2, density=10.0, poisson=True,
                                timeout=6, max_memory=200)
    failed = {os.path.basename(r["input"]): r["error"] for r in records if r["status"] == "failed"}
    assert set(failed) == set(bad)
    for name, why in bad.items():
        assert name in failed[name]
        assert any(w in failed[name] for w in why.split("|")), failed[name]
        assert "\n" not in failed[name]
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert written == sorted(f"{os.path.splitext(p.name)[0]}.ply" for p in paths[:2])
    assert no_temporary_files(tmp_path)


@pytest.mark.slow
def test_a_worker_killed_mid_batch_fails_its_mesh_alone(tmp_path, meshes, workers):
    base, paths, ref, _ = meshes
    fifo = tmp_path / "in" / "fifo.csv.ply"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    inputs = [paths[0], fifo, *paths[1:]]
    result = {}
    thread = threading.Thread(target=lambda: result.update(records=scatter_cli.batch(
        inputs, str(tmp_path / "out" / "{stem}"), jobs=2, count=300, attributes="normal,face")))
    thread.start()
    reader = wait_for_reader(fifo)
    assert ("scatter_cli.engines.worker" in open(f"/proc/{reader}/cmdline").read()) is (workers == "started")
    os.kill(reader, 9)
    os.close(reader_fd.pop())
    thread.join(60)
    records = result["records"]
    assert [r["status"] for r in records] == ["written", "failed"] + ["written"] * (len(paths) - 1)
    assert "fifo.csv.ply" in records[1]["error"] and "SIGKILL" in records[1]["error"]
    assert outputs(tmp_path / "out") == ref
    assert no_temporary_files(tmp_path)


@pytest.mark.slow
def test_a_forked_worker_is_not_charged_for_the_memory_it_shares(tmp_path, monkeypatch):
    """A worker forked from a large process (a program calling scatter_cli.batch) shares
    that process's pages: --max-memory counts the worker's own. The worker waits on a FIFO
    nobody writes, so its memory is polled until --timeout: it must time out, not be
    charged for its parent's 300 MB. Counting every resident page fails it for memory."""
    import numpy as np

    monkeypatch.setattr(worker, "can_fork", lambda: True)
    fifo = tmp_path / "waits.ply"
    os.mkfifo(fifo)
    ballast = np.ones(300 * 2**20 // 8)  # 300 MB resident in this process, shared with the fork
    args = dict(count=100, max_memory=200, timeout=2, jobs=1)
    records = scatter_cli.batch([str(fifo)], str(tmp_path / "out" / "{stem}.ply"), **args)
    assert "timed out" in records[0]["error"], records
    real = worker.resident_bytes
    monkeypatch.setattr(worker, "resident_bytes", lambda pid, private=False: real(pid))
    records = scatter_cli.batch([str(fifo)], str(tmp_path / "again" / "{stem}.ply"), **args)
    assert "--max-memory" in records[0]["error"], records
    del ballast


@pytest.mark.slow
def test_the_job_queued_behind_a_killed_one_goes_to_the_next_worker(tmp_path, meshes, monkeypatch):
    """After a short job a lane sends the next one before the answer comes; here the FIFO
    mesh runs with a good mesh queued behind it in the same worker. The worker is killed:
    the FIFO mesh fails alone, the queued mesh is sampled by the next worker, byte for
    byte as `scatter sample` writes it. A lane that forgot what it had queued would fail
    the queued mesh with the FIFO's error, or lose it."""
    base, paths, ref, _ = meshes
    monkeypatch.setattr(worker, "QUEUE_BELOW", 3600.0)  # every mesh is short, however loaded the machine
    fifo = tmp_path / "in" / "fifo.csv.ply"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    inputs = [paths[0], fifo, *paths[1:]]
    out = tmp_path / "out"
    stems = [os.path.splitext(p.name)[0] for p in inputs]  # NAME.FORMAT
    jobs = [(i, str(p), str(out / stem), stem.rsplit(".", 1)[1], False) for i, (p, stem) in enumerate(zip(inputs, stems))]
    setup = {"options": SampleOptions(count=300, attributes=("normal", "face")).check().as_dict(), "ascii": False,
             "crs": None, "quiet": True}
    lane = worker.Lane(setup, dict(os.environ, PYTHONPATH=str(ROOT)))
    sent = []
    real_send = lane._send
    lane._send = lambda job: sent.append((job[0], len(lane.sent))) or real_send(job)
    records = {}
    thread = threading.Thread(target=lambda: lane.run(jobs, lambda key, rec: records.__setitem__(key, rec)))
    thread.start()
    reader = wait_for_reader(fifo)
    os.kill(reader, 9)
    os.close(reader_fd.pop())
    thread.join(60)
    lane.close()
    assert (2, 1) in sent, sent  # mesh 2 was sent while the FIFO mesh (1) was running
    assert [records[i]["status"] for i in range(len(inputs))] == ["written", "failed"] + ["written"] * (len(paths) - 1)
    assert "SIGKILL" in records[1]["error"]
    assert outputs(out) == ref
    assert no_temporary_files(tmp_path)


class Killed:
    """A child process that ended by SIGKILL."""

    def wait(self, timeout=None):
        return -9


@pytest.mark.parametrize("broken", [False, True])
def test_out_of_memory_is_guessed_only_when_the_kernel_killed_for_memory(monkeypatch, broken):
    """A SIGKILL says "(out of memory?)" only when the kernel's OOM kills went up while the
    child ran (a kill by hand is no such sign); the broken variant, the old rule, says it
    for every SIGKILL."""
    if broken:
        monkeypatch.setattr(worker.WorkerProcess, "memory_likely", lambda self: True)
    kills = [7]
    monkeypatch.setattr(worker, "oom_kills", lambda: kills[0])
    child = worker.WorkerProcess.__new__(worker.WorkerProcess)
    child.proc, child.killed_for, child.oom_kills = Killed(), None, worker.oom_kills()
    by_hand = child._lost()
    kills[0] += 1
    by_the_kernel = child._lost()
    assert str(by_the_kernel) == "its worker was killed by SIGKILL (out of memory?)" and by_the_kernel.crashed
    assert (str(by_hand) == "its worker was killed by SIGKILL") != broken

