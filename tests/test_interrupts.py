"""SIGINT and SIGTERM during a write: exit 130 / 143, one line, no output and no temporary
file, for every format; and a signal that arrives inside a library's callback (lazrs
writing LAZ) is not turned into that library's error."""

import io
import os
import signal
import subprocess
import time

import pytest

from scatter_cli import api
from scatter_cli.core import interrupts
from scatter_cli.writers import FORMATS, write_stream

from .conftest import SAMPLES, popen_user, scatter_command

EXPECTED = {signal.SIGINT: (130, "error: interrupted"), signal.SIGTERM: (143, "error: terminated")}
# A run that takes seconds to write: long enough to be signalled mid-write. A binary output
# of known size is first checked against the free space (10^9 LAS points would need 42 GB
# free: 10^8 need 4.2 GB), and USD gathers its points in memory: a count that fits.
COUNT = {"usd": 3_000_000}
DEFAULT_COUNT = 10**8


def writing_started(folder, fmt):
    """The run's temporary file, once it exists (and, but for USD, holds data)."""
    for name in os.listdir(folder):
        if name.endswith(".part") and (fmt == "usd" or os.path.getsize(folder / name) > 0):
            return True
    return False


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
@pytest.mark.parametrize("fmt", FORMATS)
def test_a_signal_during_a_write_stops_it_cleanly(tmp_path, fmt, sig):
    out = tmp_path / "out"
    out.mkdir()
    argv = scatter_command("sample", SAMPLES / "skull.ply", "-n", COUNT.get(fmt, DEFAULT_COUNT), "-a", "normal",
                           "-o", out / f"points.{fmt}")
    proc = popen_user(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while not writing_started(out, fmt):
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "the write never started"
            time.sleep(0.01)
        proc.send_signal(sig)
        err = proc.communicate(timeout=60)[1].decode()
    finally:
        proc.kill()
    code, line = EXPECTED[sig]
    assert (proc.returncode, err.splitlines()) == (code, [line])
    assert os.listdir(out) == []


class SignallingFile(io.BytesIO):
    """A seekable in-memory file that sends its process ``sig`` from inside its first
    ``seek``: the LAZ writer's first seek is lazrs's, from inside the compressor, so the
    signal arrives while the library is calling back into Python."""

    def __init__(self, sig):
        super().__init__()
        self.sig, self.seeks = sig, 0

    def seek(self, *args):
        self.seeks += 1
        if self.seeks == 1:
            os.kill(os.getpid(), self.sig)
        return super().seek(*args)


@pytest.fixture
def handlers():
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    interrupts.install()
    yield
    for s, h in saved.items():
        signal.signal(s, h)


@pytest.mark.parametrize("sig,raised", [(signal.SIGTERM, interrupts.Terminated),
                                        (signal.SIGINT, interrupts.Interrupted)])
def test_a_signal_inside_the_laz_compressor_is_raised_after_it(handlers, sig, raised):
    pytest.importorskip("lazrs")
    run = api.prepare(SAMPLES / "skull.ply", 300_000, seed=1, precision="float64", chunk_size=50_000)
    stream = SignallingFile(sig)
    with pytest.raises(raised):
        write_stream(run.chunks(), stream, "laz", run.layout, run.size, **api.output_options(run, "laz"))
    assert stream.seeks >= 1


def test_a_signal_as_the_temporary_file_is_made_leaves_no_file(handlers, tmp_path, monkeypatch):
    """SIGTERM the moment ``.NAME.XXXXXXXX.part`` exists, before the writer has its stream
    (the main thread can wait there for the GIL while the sampling threads run): the
    signal is raised once both exist, and the file goes with it."""
    from scatter_cli.writers import base

    made = base._create_temp

    def create_then_signal(path, folder):
        got = made(path, folder)
        os.kill(os.getpid(), signal.SIGTERM)
        return got

    monkeypatch.setattr(base, "_create_temp", create_then_signal)
    with pytest.raises(interrupts.Terminated):
        with base.open_output(tmp_path / "points.ply") as stream:
            stream.write(b"never")
    assert os.listdir(tmp_path) == []
