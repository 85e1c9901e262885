"""Standard output whose reader goes away: exit 141, quietly, for every size and every
format that can go there, whether standard output is buffered or not (PYTHONUNBUFFERED)."""

import io
import os
import subprocess
import sys

import pytest

from scatter_cli.errors import ScatterError
from scatter_cli.writers import FORMATS

from .conftest import SAMPLES, run_user, scatter_command

pytestmark = pytest.mark.slow  # a subprocess a run

MESH = SAMPLES / "skull.ply"
SMALL, LARGE = 10, 100_000  # a few rows; one chunk of megabytes, far more than a pipe holds
UNBUFFERED = {"PYTHONUNBUFFERED": "1"}

# every format standard output takes (LAS and LAZ need a file to seek in), binary and text
STDOUT_OUTPUTS = [("-f", f) for f in FORMATS if f not in ("las", "laz")] + [("-f", "ply", "--ascii"),
                                                                           ("-f", "pcd", "--ascii")]


def output_id(args):
    return "-".join(a.strip("-") for a in args[1:])


def needs_extra(args):
    return args[1] == "usd" and pytest.importorskip("pxr")


def closed_reader(args, env=None):
    """Run ``scatter ARGS`` with standard output a pipe whose reader closed before it began."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        return run_user(scatter_command(*args), env=env, stdout=write_end, stderr=subprocess.PIPE)
    finally:
        os.close(write_end)


def head_reader(args, env=None, prelude=""):
    """``scatter ARGS | head -c 10``: the reader takes ten bytes and leaves. ``prelude``:
    Python run before the command in its process. Returns (exit code, standard error)."""
    code = f"import sys\nfrom scatter_cli import cli\nfrom scatter_cli.core import process\n{prelude}\n" \
           "process.exit_now(cli.main(sys.argv[1:]))"
    command = " ".join(f"'{a}'" for a in [sys.executable, "-c", code, *map(str, args)])
    proc = run_user(["bash", "-c", f"{command} | head -c 10 > /dev/null; echo ${{PIPESTATUS[0]}}"], env=env)
    return int(proc.stdout), proc.stderr.decode()


@pytest.mark.parametrize("count", [SMALL, LARGE])
@pytest.mark.parametrize("output", STDOUT_OUTPUTS, ids=output_id)
def test_a_reader_gone_before_any_byte_gives_141(output, count):
    """The few rows of a small run sit in a buffer until the end: they meet the closed pipe
    at the last flush, and that is 141 as much as a large run's first write is."""
    needs_extra(output)
    proc = closed_reader(["sample", MESH, "-n", count, *output])
    assert (proc.returncode, proc.stderr) == (141, b"")


@pytest.mark.parametrize("env", [None, UNBUFFERED], ids=["buffered", "unbuffered"])
@pytest.mark.parametrize("output", STDOUT_OUTPUTS, ids=output_id)
def test_a_reader_gone_in_the_middle_of_the_last_write_gives_141(output, env):
    """One chunk of a large run is one write, longer than a pipe holds, and the last one:
    the reader leaves while it is under way."""
    needs_extra(output)
    assert head_reader(["sample", MESH, "-n", LARGE, *output], env=env) == (141, "")


def test_the_unbuffered_last_write_is_what_the_check_catches():
    """The broken variant: standard output left unbuffered, the OS takes part of the last
    write without an error, the rest is dropped and the run ends 0."""
    broken = "process.whole_writes = lambda: None"
    assert head_reader(["sample", MESH, "-n", LARGE], env=UNBUFFERED, prelude=broken) == (0, "")


def test_merge_onto_a_closed_pipe_gives_141(tmp_path):
    part = tmp_path / "part.ply"
    run_user(scatter_command("sample", MESH, "-n", SMALL, "-o", part), check=True)
    proc = closed_reader(["merge", part, "-o", "-"], env=UNBUFFERED)
    assert (proc.returncode, proc.stderr) == (141, b"")


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
    run_user(scatter_command("sample", MESH, "-n", SMALL, "-o", part), check=True)
    if broken:
        monkeypatch.setattr(las, "need_seekable", lambda stream: None)
    file = read_file(str(part), "las")
    with pytest.raises(Exception) as caught:
        file.join([file], Pipe())
    assert isinstance(caught.value, ScatterError) != broken
    assert broken or "LAS/LAZ output needs a file" in str(caught.value)
