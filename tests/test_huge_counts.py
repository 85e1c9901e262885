"""Flat memory at any count: a run of 10^13 points holds no more memory than one of 10^9,
for every format that streams and every kind of output (a file, standard output,
/dev/null); and a count past what a run can number is a usage error.

The command is started at each count, its peak resident memory read once it has written
WRITTEN bytes (it is streaming by then), and killed: a run of 10^13 points would take
days. The broken variant builds the list of every chunk first (as a run once did), which
a count of 10^13 makes grow without end before the first point is written.
"""

import os
import subprocess
import threading
import time

import pytest

from scatter_cli import api
from scatter_cli.errors import ScatterUsageError

from .conftest import SAMPLES, popen_user, scatter_command

MESH = SAMPLES / "icosahedron_binary.stl"
WRITTEN = 8 << 20  # bytes written before the peak is read (the chunks in flight are all made by then)
DEADLINE = 30.0  # seconds a command may take to get there
LEVEL = 1.5  # the peak at 10^13 within this factor of the peak at 10^9
LIST_OF_CHUNKS = ("import sys; from scatter_cli.sampling import plan; lazy = plan.chunk_ranges; "
                  "plan.chunk_ranges = lambda *a: iter(list(lazy(*a))); from scatter_cli.cli import run; run()")


def proc_status(pid):
    """(bytes written so far, peak resident memory in bytes) of a running process."""
    with open(f"/proc/{pid}/io") as f:
        written = next(int(line.split()[1]) for line in f if line.startswith("wchar:"))
    with open(f"/proc/{pid}/status") as f:
        peak = next(int(line.split()[1]) << 10 for line in f if line.startswith("VmHWM:"))
    return written, peak


def drain(stream):
    while stream.read(1 << 20):
        pass


def peak_memory(count, fmt, where, tmp_path, most=None, code=None):
    """Peak resident bytes of ``scatter sample MESH -n count -f FMT`` (``code``: run by
    ``python -c code`` instead of the command), written to ``where`` ("file", "stdout" or
    "/dev/null"), read once it has written WRITTEN bytes, or once its peak passes
    ``most``."""
    name, *flags = fmt.split()
    args = ["sample", MESH, "-n", count, "-f", name, *flags]
    if where == "file":
        args += ["-o", tmp_path / f"out-{count}.{name}"]
    elif where == "/dev/null":
        args += ["-o", os.devnull]
    argv = scatter_command(*args) if code is None else [scatter_command()[0], "-c", code, *map(str, args)]
    proc = popen_user(argv, env={"SCATTER_THREADS": "2"}, stdout=subprocess_pipe(where), stderr=subprocess_pipe("stderr"))
    if where == "stdout":
        threading.Thread(target=drain, args=(proc.stdout,), daemon=True).start()
    try:
        t = time.monotonic()
        while proc.poll() is None and time.monotonic() - t < DEADLINE:
            written, peak = proc_status(proc.pid)
            if written >= WRITTEN or (most is not None and peak > most):
                return peak
            time.sleep(0.05)
        raise AssertionError(f"scatter {' '.join(map(str, args))}: exit {proc.returncode}, "
                             f"{proc.stderr.read().decode() if proc.returncode is not None else 'too slow'}")
    finally:
        proc.kill()
        proc.wait()
        for path in tmp_path.iterdir():
            path.unlink()


def subprocess_pipe(where):
    return subprocess.PIPE if where in ("stdout", "stderr") else subprocess.DEVNULL


def peaks(fmt, where, tmp_path, code=None):
    """(peak at 10^9, peak at 10^13) in bytes."""
    small = peak_memory("1e9", fmt, where, tmp_path)
    return small, peak_memory("1e13", fmt, where, tmp_path, most=LEVEL * small, code=code)


# every format that streams (USD is built in memory and refuses such counts), each to one
# kind of output, and every kind of output for text and binary
# (a binary file of known size is refused at once: 10^13 points do not fit any disk)
CASES = [("npy", "/dev/null"), ("ply", "stdout"), ("ply --ascii", "file"), ("csv", "stdout"), ("xyz", "file"),
         ("pcd", "/dev/null"), ("pcd --ascii", "stdout"), ("las", "/dev/null"), ("laz", "file")]


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/proc/self/io"), reason="reads /proc")
@pytest.mark.parametrize("fmt, where", CASES)
def test_memory_is_flat_at_any_count(fmt, where, tmp_path):
    small, huge = peaks(fmt, where, tmp_path)
    assert huge <= LEVEL * small, f"{huge / 2**20:.0f} MB at 10^13, {small / 2**20:.0f} MB at 10^9"


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/proc/self/io"), reason="reads /proc")
def test_a_list_of_every_chunk_is_caught(tmp_path):
    small, huge = peaks("npy", "/dev/null", tmp_path, code=LIST_OF_CHUNKS)
    assert huge > LEVEL * small


@pytest.mark.parametrize("count", [2**63, 10**19, 10**400])
def test_a_count_past_what_a_run_can_number_is_a_usage_error(count):
    with pytest.raises(ScatterUsageError, match="more than a run can number"):
        api.prepare(str(MESH), count)


def test_the_largest_count_a_run_can_number_is_taken():
    run = api.prepare(str(MESH), 2**63 - 1)  # (its chunks made as they are taken)
    last = list(run.chunks(2**63 - 11, 2**63 - 1))
    assert run.count == 2**63 - 1 and sum(len(c.points) for c in last) == 10
