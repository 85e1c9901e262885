"""Standard output whose reader goes away: exit 141, quietly, for every size and every
format that can go there, whether standard output is buffered or not (PYTHONUNBUFFERED).

Every format and size runs in this process, its standard output a real pipe; two runs of
the real command (a reader gone before the first byte, and `| head -c 10`) check the way
out of the process, where Python's last flush can meet the closed pipe."""

import contextlib
import io
import os
import signal
import subprocess
import sys
import threading

import pytest

from scatter_cli import cli
from scatter_cli.core import process
from scatter_cli.errors import ScatterError
from scatter_cli.writers import FORMATS

from .batchtools import sample_in_process
from .conftest import SAMPLES, run_user, scatter_command

MESH = SAMPLES / "skull.ply"
SMALL, LARGE = 10, 20_000  # a few rows; one write of over 200 KB, more than a pipe holds
UNBUFFERED = {"PYTHONUNBUFFERED": "1"}

# every format standard output takes (LAS and LAZ need a file to seek in), binary and text
STDOUT_OUTPUTS = [("-f", f) for f in FORMATS if f not in ("las", "laz")] + [("-f", "ply", "--ascii"),
                                                                           ("-f", "pcd", "--ascii")]


def output_id(args):
    return "-".join(a.strip("-") for a in args[1:])


def needs_extra(args):
    return args[1] == "usd" and pytest.importorskip("pxr")


def run_into_pipe(argv, reader, unbuffered=False):
    """``scatter ARGV`` in this process, its standard output the writing end of a pipe
    (``unbuffered``: as PYTHONUNBUFFERED leaves it, no buffered layer) whose reading end
    ``reader(fd)`` takes, in a thread, and closes. Returns (exit code, standard error)."""
    read_end, write_end = os.pipe()
    raw = io.FileIO(write_end, "wb", closefd=False)
    binary = raw if unbuffered else io.BufferedWriter(raw)
    stdout = io.TextIOWrapper(binary, encoding="utf-8", line_buffering=True, write_through=unbuffered)
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    stderr = io.StringIO()
    thread = threading.Thread(target=reader, args=(read_end,))
    thread.start()
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = stdout, stderr
    try:
        code = cli.main([str(a) for a in argv])
    finally:
        streams = {sys.stdout, stdout}  # (the command may have given standard output a buffer)
        sys.stdout, sys.stderr = saved
        for s, h in handlers.items():
            signal.signal(s, h)
        thread.join()
        discard(streams, write_end)
    return code, stderr.getvalue()


def discard(streams, fd):
    """Close ``streams`` and their file descriptor ``fd``: what they still hold goes to
    /dev/null now, not to whatever file has that number when they are collected."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    os.close(devnull)
    for stream in streams:
        with contextlib.suppress(OSError, ValueError):
            stream.close()
    os.close(fd)


def gone(fd):
    """A reader that leaves before reading anything."""
    os.close(fd)


def head(fd):
    """`head -c 10`: takes ten bytes and leaves."""
    got = b""
    while len(got) < 10:
        block = os.read(fd, 10 - len(got))
        if not block:
            break
        got += block
    os.close(fd)


@pytest.mark.parametrize("count", [SMALL, LARGE])
@pytest.mark.parametrize("output", STDOUT_OUTPUTS, ids=output_id)
def test_a_reader_gone_before_any_byte_gives_141(output, count):
    """The few rows of a small run sit in a buffer until the end: they meet the closed pipe
    at the last flush, and that is 141 as much as a large run's first write is."""
    needs_extra(output)
    assert run_into_pipe(["sample", MESH, "-n", count, *output], gone) == (141, "")


@pytest.mark.parametrize("unbuffered", [False, True], ids=["buffered", "unbuffered"])
@pytest.mark.parametrize("output", STDOUT_OUTPUTS, ids=output_id)
def test_a_reader_gone_in_the_middle_of_the_last_write_gives_141(output, unbuffered):
    """All the rows of the run are one write, longer than a pipe holds, and the last one:
    the reader leaves while it is under way."""
    needs_extra(output)
    assert run_into_pipe(["sample", MESH, "-n", LARGE, *output], head, unbuffered) == (141, "")


@pytest.mark.parametrize("broken", [False, True])
def test_an_unbuffered_standard_output_gets_a_buffer(monkeypatch, broken):
    """What the runs above rely on: without a buffered layer (PYTHONUNBUFFERED) the OS can
    take part of the last large write without an error and the rest is dropped (exit 0);
    whole_writes gives standard output that layer. The broken variant (no whole_writes)
    leaves the raw file under it."""
    if broken:
        monkeypatch.setattr(process, "whole_writes", lambda: None)
    read_end, write_end = os.pipe()
    raw = io.TextIOWrapper(io.FileIO(write_end, "wb", closefd=False), encoding="utf-8", write_through=True)
    monkeypatch.setattr(sys, "stdout", raw)
    process.whole_writes()
    layered = isinstance(sys.stdout.buffer, io.BufferedWriter)
    monkeypatch.undo()
    os.close(read_end)
    discard({raw}, write_end)
    assert layered is not broken


def test_merge_onto_a_closed_pipe_gives_141(tmp_path):
    part = tmp_path / "part.ply"
    sample_in_process(["sample", str(MESH), "-n", str(SMALL), "-o", str(part)])
    assert run_into_pipe(["merge", part, "-o", "-"], gone, unbuffered=True) == (141, "")


@pytest.mark.slow
def test_the_command_gives_141_on_its_way_out():
    """The real command: its few rows buffered until Python's last flush, which meets a
    reader gone before the first byte."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = run_user(scatter_command("sample", MESH, "-n", SMALL), stdout=write_end, stderr=subprocess.PIPE)
    finally:
        os.close(write_end)
    assert (proc.returncode, proc.stderr) == (141, b"")


@pytest.mark.slow
def test_the_command_piped_into_head_gives_141():
    """What the issue ran, with standard output unbuffered: `scatter sample MESH -n N | head -c 10`."""
    command = " ".join(f"'{a}'" for a in scatter_command("sample", MESH, "-n", LARGE))
    proc = run_user(["bash", "-c", f"{command} | head -c 10 > /dev/null; echo ${{PIPESTATUS[0]}}"], env=UNBUFFERED)
    assert (int(proc.stdout), proc.stderr) == (141, b"")


class Pipe(io.BytesIO):
    def seekable(self):
        return False


@pytest.mark.parametrize("broken", [False, True])
def test_merge_of_las_onto_standard_output_says_it_needs_a_file(tmp_path, monkeypatch, broken):
    """The joined LAS header is completed at the end: a stream that cannot seek is the
    one-line error sample gives; the broken variant (no such check) fails inside laspy."""
    pytest.importorskip("laspy")
    from scatter_cli.writers import las
    from scatter_cli.writers.pointfiles import read_file

    part = tmp_path / "part.las"
    sample_in_process(["sample", str(MESH), "-n", str(SMALL), "-o", str(part)])
    if broken:
        monkeypatch.setattr(las, "need_seekable", lambda stream: None)
    file = read_file(str(part), "las")
    with pytest.raises(Exception) as caught:
        file.join([file], Pipe())
    assert isinstance(caught.value, ScatterError) != broken
    assert broken or "LAS/LAZ output needs a file" in str(caught.value)
