"""Helpers of the batch tests: a small collection, what `scatter sample` writes for it,
and the process that holds a FIFO open."""

import os
import shutil
import signal
import time

from .conftest import ROOT, SAMPLES, run_scatter, run_user, scatter_command

GOOD = ["icosahedron_binary.stl", "moebius-160-10.ply", "hemisphere.off", "narrow_triangles.obj",
        "boxvertexcolors.glb"]
# the output format of each good mesh: its stem ends with it ({stem} drops only the mesh suffix)
FORMAT_OF = dict(zip(GOOD, ["ply", "csv", "xyz", "npy", "ply"]))
OPTIONS = ["-n", "300", "-a", "normal,face"]


def collection(folder):
    """The good meshes copied to ``folder`` as NAME.FORMAT.SUFFIX: returns their paths."""
    folder.mkdir(exist_ok=True)
    paths = []
    for name in GOOD:
        stem, suffix = os.path.splitext(name)
        paths.append(folder / f"{stem}.{FORMAT_OF[name]}{suffix}")
        shutil.copy(SAMPLES / name, paths[-1])
    return paths


def reference(tmp_path, paths, *extra):
    """What `scatter sample MESH -o OUT` writes for each mesh: {output name: bytes}.

    The first through a subprocess, the others through the command's own entry point in
    this process (the same code, without paying Python's start-up for each).
    """
    out = {}
    for i, p in enumerate(paths):
        name = os.path.splitext(p.name)[0]
        target = tmp_path / "ref" / name
        target.parent.mkdir(exist_ok=True)
        argv = ["sample", str(p), *OPTIONS, *extra, "-o", str(target)]
        if i == 0:
            run_scatter(*argv, check=True)
        else:
            sample_in_process(argv)
        out[name] = target.read_bytes()
    return out


def sample_in_process(argv):
    assert command_in_process(argv) == 0, argv


def command_in_process(argv):
    """``scatter ARGV`` through the command's entry point in this process: its exit code
    (the signal handlers it installs are put back)."""
    from scatter_cli.cli import main

    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return main(argv)
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)


def outputs(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def no_temporary_files(folder):
    return not [p for p in folder.rglob("*") if p.name.endswith(".part")]


reader_fd = []


def wait_for_reader(fifo, timeout=30, over=None):
    """The pid of the process that opened ``fifo`` to read it (we open its writing end).

    ``over``: a callable, true once the batch has ended: then no reader will come, and
    the wait fails at once instead of at ``timeout`` (a backstop for a loaded machine).
    """
    deadline = time.monotonic() + timeout
    while True:
        try:
            reader_fd.append(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
            break
        except OSError:
            if over is not None and over():
                raise AssertionError(f"the batch ended with nobody reading {fifo}") from None
            if time.monotonic() > deadline:
                raise AssertionError(f"nobody opened {fifo} in {timeout} s") from None
            time.sleep(0.02)
    deadline = time.monotonic() + 30  # it has the FIFO open: only its pid is left to find
    while time.monotonic() < deadline:
        pid = fifo_reader(fifo)
        if pid is not None:
            return pid
        time.sleep(0.02)
    raise AssertionError("no reader of the FIFO found")


HANG = 600  # seconds: only a batch that hangs (neither goes on nor ends) gets this far


class Feeder:
    """The writing end of a FIFO input of a batch whose readers get killed.

    Opened at the first reader and held to the end: a reader that opens the FIFO later
    (the task run again) then blocks until fed. (Closing it after a kill and opening it
    again let a reader that came between read end-of-file: its mesh failed as empty and
    nobody ever opened the FIFO again.) Waits end on an event: a reader not seen before,
    or the batch's end (``over()``, a failure).
    """

    def __init__(self, fifo, over):
        self.fifo, self.over = fifo, over
        self.fd = None
        self.seen = set()

    def next_reader(self):
        """The pid of the next process that opens the FIFO to read it."""
        deadline = time.monotonic() + HANG
        while time.monotonic() < deadline:
            if self.fd is None:
                try:
                    self.fd = os.open(self.fifo, os.O_WRONLY | os.O_NONBLOCK)  # fails until a reader comes
                except OSError:
                    pass
            pid = None if self.fd is None else fifo_reader(self.fifo, exclude=self.seen)
            if pid is not None:
                self.seen.add(pid)
                return pid
            if self.over():
                raise AssertionError(f"the batch ended with no new reader of {self.fifo}")
            time.sleep(0.02)
        raise AssertionError(f"the batch hung: no new reader of {self.fifo} and no end in {HANG} s")

    def feed(self, data):
        """Write ``data`` to the reader and close: it reads ``data``, then end-of-file."""
        with os.fdopen(self.fd, "wb") as f:
            self.fd = None
            os.set_blocking(f.fileno(), True)
            f.write(data)

    def close(self):
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def alive(pid):
    """Whether process ``pid`` is running (a zombie is not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in "ZX"
    except OSError:
        return False


def fifo_reader(fifo, exclude=()):
    """The pid of a process (not this one, nor one of ``exclude``) that has ``fifo`` open, or None."""
    for pid in filter(str.isdigit, os.listdir("/proc")):
        if int(pid) == os.getpid() or int(pid) in exclude:
            continue
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                if os.readlink(f"/proc/{pid}/fd/{fd}") == str(fifo):
                    return int(pid)
            except OSError:
                pass
    return None


def parent_of(pid):
    with open(f"/proc/{pid}/stat") as f:
        return int(f.read().rsplit(")", 1)[1].split()[1])


def warning_meshes(folder):
    """Two meshes that sample with a warning: one with a face whose vertex is not finite,
    one so far from the origin that float32 would move its points (float64 is written)."""
    folder.mkdir(exist_ok=True)
    (folder / "non-finite.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 0\nf 1 2 3\nf 1 2 4\n")
    (folder / "far.obj").write_text("v 1e7 0 0\nv 10000001 0 0\nv 1e7 1 0\nf 1 2 3\n")
    return [folder / "non-finite.obj", folder / "far.obj"]


def sample_warnings(mesh, cwd, *options):
    """The warning lines of `scatter sample MESH OPTIONS` run in ``cwd``, each naming
    ``mesh`` as a batch names it: what a batch of ``mesh`` must print."""
    done = run_elsewhere(cwd, "sample", mesh, *options, "-f", "ply", "-o", os.devnull)
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.decode().splitlines() if line.startswith("warning: ")]
    assert lines, f"scatter sample {mesh} gave no warning"
    return [line if str(mesh) in line else f"warning: {mesh}: {line[len('warning: '):]}" for line in lines]


def warning_lines(stderr):
    return sorted(line for line in stderr.decode().splitlines() if line.startswith("warning:"))


def run_elsewhere(cwd, *args):
    """The real command run in the folder ``cwd`` (this tree still the one imported)."""
    return run_user(scatter_command(*args), cwd=cwd, env={"PYTHONPATH": str(ROOT)})
