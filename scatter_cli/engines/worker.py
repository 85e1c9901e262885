"""One mesh at a time in a long-lived child process, with its failures kept to that mesh.

The child is forked from the command once it has imported NumPy and the sampler
(:class:`Forked`), or started as ``python -m scatter_cli.engines.worker`` and imports them
itself. It reads jobs, one JSON line each, from standard input, samples each mesh to its
output itself (``api.prepare`` and the writers, exactly as ``scatter sample`` does) and
answers one JSON line. The parent side, :class:`Lane`, hands it its jobs (the next one
queued behind a short one) and watches it: a job past its timeout or its memory limit is
killed with its process, a crash (segfault, OOM kill) is seen as the pipe closing; either
way that job fails, its temporary output is removed and the jobs after it go to a fresh
child. Both engines use it: the local one runs ``-j`` lanes, the Dask one a lane per Dask
worker thread.

The memory limit is checked by polling the child's resident set size (``/proc/PID/statm``)
every ``POLL`` seconds rather than with ``RLIMIT_AS``: an address-space limit counts
reservations that are not memory (thread stacks, glibc's 64 MB malloc arenas per thread,
files mapped by the PLY reader), so a limit in MB would fail good meshes or need a fudge
factor; resident memory is what the OOM killer and ``top`` count. The cost is that a
spike shorter than the poll interval goes unseen.
"""

from __future__ import annotations

import collections
import gc
import json
import os
import re
import select
import signal
import subprocess
import sys
import threading
import time

from ..run.options import SampleOptions

POLL = 0.05  # seconds between checks of a running job's time and memory
QUEUE_BELOW = 0.05  # seconds: after a job shorter than this, a lane queues the next behind the one running
# bytes of resident memory above a worker's own after start-up past which it hands freed
# memory back after a job (doing so after every job costs small meshes 15-25% of their time)
TRIM_ABOVE = 64 << 20
_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


class WorkerLost(Exception):
    """The child stopped before answering: the message says why (one line). ``crashed``:
    it died of itself or was killed from outside, not by its lane (a timeout, the memory
    limit, an interrupted batch)."""

    def __init__(self, message, crashed=False):
        super().__init__(message)
        self.crashed = crashed


# ---------------------------------------------------------------- the child ----

def serve():
    """The child's loop: a setup line, then one job line in, one result line out."""
    answer = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # stray prints go to standard error, not into the answers
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the parent decides
    _die_with_parent()
    setup = json.loads(sys.stdin.readline() or "null")
    if setup is None:
        return
    _warm_up()
    gc.freeze()  # what the warm-up made lives for good: collections skip it (and leave its pages shared)
    settled = resident_bytes(os.getpid())
    answer.write('{"ready": true}\n')
    setup = dict(setup, options=SampleOptions(**setup["options"]))  # built (and checked) once, not per mesh
    for line in sys.stdin:
        job = json.loads(line)
        warnings = []  # handed to the parent, which prints them between its progress lines
        result = sample_file(job["input"], job["output"], job["format"], setup,
                             None if setup.get("quiet") else warnings.append)
        answer.write(json.dumps(dict(result, warnings=warnings)) + "\n")
        if resident_bytes(os.getpid()) > settled + TRIM_ABOVE:
            _trim_heap()


_made = set()  # output folders this process has made or found (a batch writes many files to one)


def sample_file(input, output, fmt, setup, warn=None):
    """Sample ``input`` to ``output`` in format ``fmt`` as ``scatter sample INPUT -o OUTPUT`` does.

    ``setup``: ``{"options": SampleOptions, "ascii": bool, "crs": --crs or None}``.

    Returns ``{"error": None or one line, "count", "faces", "area"}``.
    """
    from .. import api
    from ..errors import ScatterError

    try:
        folder = os.path.dirname(output)
        if folder and folder not in _made:
            os.makedirs(folder, exist_ok=True)
            _made.add(folder)
        run = api.sample_to(input, setup["options"], output, fmt, setup.get("ascii", False), crs=setup.get("crs"),
                            warn=warn)
        return {"error": None, "count": run.size, "faces": int(run.info["faces"]), "area": float(run.info["area"])}
    except ScatterError as exc:
        message = str(exc)
    except MemoryError:
        message = "out of memory"
    except OSError as exc:
        message = f"{exc.strerror or exc}"
    except Exception as exc:  # a bug or a reader's surprise: this mesh fails, the worker goes on
        message = f"internal error: {type(exc).__name__}: {exc}"
    return {"error": name_the_file(message, input, output), "count": None, "faces": None, "area": None}


def name_the_file(message, input, output=None):
    """``message`` as one line that says which file it is about."""
    message = (message.strip().splitlines() or [""])[0]
    if input in message or (output and output in message):
        return message
    return f"{input}: {message}"


def _warm_up():
    from .. import api, writers  # noqa: F401  (NumPy, the sampler and the writers)
    from ..loading.load import lean_trimesh

    lean_trimesh()  # trimesh as the command line imports it (SciPy hidden), when a mesh needs it


def _die_with_parent():
    """Ask Linux to kill this child when its parent dies, so none is left working for nobody."""
    try:
        import ctypes

        ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except Exception:
        return
    if os.getppid() == 1:  # the parent died before prctl
        os._exit(1)


def _trim_heap():
    """Hand freed memory back to the system, so a worker's footprint does not ratchet up."""
    try:
        import ctypes

        ctypes.CDLL(None).malloc_trim(0)
    except Exception:
        pass


# ---------------------------------------------------------------- the parent side ----

class WorkerProcess:
    """One child; ``send(...)`` hands it a job, ``receive(...)`` waits for the answer to
    the oldest job it has not answered.

    ``fork``: fork it from this process (:class:`Forked`; see :func:`can_fork`) instead of
    starting ``python -m scatter_cli.engines.worker``.
    """

    def __init__(self, setup, env=None, fork=False):
        self.proc = None
        if fork:
            try:
                self.proc = Forked(env)
            except OSError:  # no room for another process now: try the ordinary way
                pass
        if self.proc is None:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "scatter_cli.engines.worker"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, bufsize=0,
            )
        self.proc.stdin.write((json.dumps(setup) + "\n").encode())
        self.oom_kills = oom_kills()  # the kernel's count when the child started
        self.ready = False
        self.killed_for = None
        self.unread = b""  # what the child answered past the last line read

    def wait_ready(self):
        """Wait for the child's imports (start-up counts against no job's time limit)."""
        if not self.ready:
            self._read_line(None, None)
            self.ready = True

    def send(self, input, output, fmt):
        """Hand the child a job (it runs its jobs in the order sent, one at a time)."""
        self.wait_ready()
        try:
            self.proc.stdin.write((json.dumps({"input": input, "output": output, "format": fmt}) + "\n").encode())
        except OSError:
            raise self._lost() from None

    def receive(self, timeout=None, max_memory=None, started=None):
        """The answer to the oldest job sent, which began at ``started`` (time.monotonic())."""
        return json.loads(self._read_line(timeout, max_memory, started))

    def _read_line(self, timeout, max_memory, started=None):
        started = time.monotonic() if started is None else started
        out = self.proc.stdout
        while True:
            line, newline, rest = self.unread.partition(b"\n")
            if newline:  # (two answers can come in one read)
                self.unread = rest
                return line
            ready, _, _ = select.select([out], [], [], POLL)
            if ready:
                block = os.read(out.fileno(), 65536)
                if not block:
                    raise self._lost()
                self.unread += block
                continue
            if self.killed_for:
                raise self._lost()
            if timeout is not None and time.monotonic() - started > timeout:
                self.kill(f"timed out after {timeout:g} s")
                raise self._lost()
            if max_memory is not None:
                rss = resident_bytes(self.proc.pid, private=True)
                if rss > max_memory * 2**20:
                    self.kill(f"exceeded --max-memory {max_memory:g} MB (resident {rss / 2**20:.0f} MB)")
                    raise self._lost()

    def kill(self, reason="stopped"):
        self.killed_for = self.killed_for or reason
        try:
            self.proc.kill()
        except OSError:
            pass

    def _lost(self):
        """The WorkerLost of the child's end, once it has ended."""
        code = self.proc.wait()
        if self.killed_for:
            return WorkerLost(self.killed_for)
        if code < 0:
            try:
                name = signal.Signals(-code).name
            except ValueError:
                name = f"signal {-code}"
            hint = " (out of memory?)" if -code == signal.SIGKILL and self.memory_likely() else ""
            return WorkerLost(f"its worker was killed by {name}{hint}", crashed=True)
        return WorkerLost(f"its worker exited with status {code}", crashed=True)

    def memory_likely(self):
        """Whether memory is the likely cause of a SIGKILL: the kernel's OOM killer has
        killed a process since the child started (a kill by hand is no such sign)."""
        now = oom_kills()
        return now is not None and self.oom_kills is not None and now > self.oom_kills

    def close(self):
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def can_fork() -> bool:
    """Whether workers may be forked from this process: on Linux, from the main thread
    while it is the only one (a thread holding a lock at the fork would leave the
    child's copy of that lock held for ever)."""
    return (sys.platform.startswith("linux") and threading.current_thread() is threading.main_thread()
            and threading.active_count() == 1)


def preload():
    """Import in this process what the workers forked from it need (NumPy, the sampler,
    the writers), so that none imports it again. Not trimesh: the fast readers load the
    plain formats without it (a worker imports it for the first mesh that needs it)."""
    from .. import api, writers  # noqa: F401


class Forked:
    """A worker forked from this process (which has imported what it needs: :func:`preload`),
    in place of ``subprocess.Popen``: ``pid``, ``stdin``, ``stdout``, ``wait``, ``kill``.

    Fork only where :func:`can_fork` says so. The child keeps standard error; its standard
    input and output are pipes to this process, every other file of this process is closed
    in it (another worker's pipe held open would hide that worker's death), and it leaves
    with ``os._exit``, so buffers and handlers of this process never run there.
    """

    def __init__(self, env=None):
        job_r, job_w = os.pipe()
        answer_r, answer_w = os.pipe()
        try:
            self.pid = os.fork()
        except OSError:
            for fd in (job_r, job_w, answer_r, answer_w):
                os.close(fd)
            raise
        if self.pid == 0:
            _forked_child(job_r, answer_w, env)
        os.close(job_r)
        os.close(answer_w)
        self.stdin = os.fdopen(job_w, "wb", buffering=0)
        self.stdout = os.fdopen(answer_r, "rb", buffering=0)
        self.returncode = None

    def poll(self):
        if self.returncode is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout=None):
        if timeout is None:
            if self.returncode is None:
                self.returncode = os.waitstatus_to_exitcode(os.waitpid(self.pid, 0)[1])
            return self.returncode
        deadline = time.monotonic() + timeout
        nap = 0.0005  # doubled up to 50 ms, as subprocess waits: a worker told to stop is gone in a moment
        while self.poll() is None:
            if time.monotonic() > deadline:
                raise subprocess.TimeoutExpired(f"worker {self.pid}", timeout)
            time.sleep(nap)
            nap = min(2 * nap, 0.05)
        return self.returncode

    def kill(self):
        if self.poll() is None:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


def _forked_child(job_r, answer_w, env):
    """The forked worker: standard input and output on the pipes, then :func:`serve`."""
    code = 1
    try:
        os.dup2(job_r, 0)
        os.dup2(answer_w, 1)
        _close_files_from(3)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        if env is not None:
            os.environ.update(env)
        # streams of its own: this process's may hold buffered text that is not the child's
        sys.stdin = open(0, encoding="utf-8", closefd=False)
        sys.stdout = open(1, "w", buffering=1, closefd=False)
        sys.stderr = open(2, "w", buffering=1, closefd=False)
        serve()
        code = 0
    finally:
        os._exit(code)


def _close_files_from(low):
    try:
        fds = [int(fd) for fd in os.listdir("/proc/self/fd")]
    except OSError:
        os.closerange(low, os.sysconf("SC_OPEN_MAX"))
        return
    for fd in fds:
        if fd >= low:
            try:
                os.close(fd)
            except OSError:
                pass


def oom_kills():
    """How many processes the kernel's OOM killer has killed since boot (``oom_kill`` in
    /proc/vmstat, a cgroup's limit included), or None where the system does not say."""
    try:
        with open("/proc/vmstat") as f:
            for line in f:
                if line.startswith("oom_kill "):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def resident_bytes(pid, private=False) -> int:
    """Resident memory of process ``pid`` in bytes; ``private``: only the pages it does not
    share (not libraries, nor what a forked worker still shares with the process that
    forked it, which would otherwise count that process's memory against each mesh)."""
    if private:
        try:
            with open(f"/proc/{pid}/smaps_rollup") as f:
                return sum(int(line.split()[1]) for line in f if line.startswith("Private_")) * 1024
        except (OSError, ValueError, IndexError):
            pass  # no smaps_rollup (Linux before 4.14): every resident page
    try:
        with open(f"/proc/{pid}/statm") as f:
            return int(f.read().split()[1]) * _PAGE
    except (OSError, ValueError, IndexError):
        return 0


def remove_temps(output):
    """Delete the temporary files ``writers.open_output`` makes for ``output``
    (``.NAME.XXXXXXXX.part`` beside it) that a killed worker or run left behind."""
    folder, base = os.path.split(os.path.abspath(output))
    pattern = re.compile(r"\." + re.escape(base) + r"\.[A-Za-z0-9_]{8}\.part\Z")
    try:
        names = os.listdir(folder)
    except OSError:
        return
    for name in names:
        if pattern.match(name):
            try:
                os.unlink(os.path.join(folder, name))
            except OSError:
                pass


class StaleTemps:
    """Temporary files of earlier, killed runs, listed once per output folder.

    ``clear(output)`` deletes those of ``output``: a directory of a million outputs is
    listed once, not once per mesh.
    """

    PATTERN = re.compile(r"\.(.+)\.[A-Za-z0-9_]{8}\.part\Z")

    def __init__(self):
        self.folders = {}
        self.lock = threading.Lock()
        self.cwd = os.getcwd()  # (os.path.abspath asks for it at every call)

    def clear(self, output):
        folder, base = os.path.split(os.path.normpath(os.path.join(self.cwd, output)))
        with self.lock:
            if folder not in self.folders:
                self.folders[folder] = self.scan(folder)
            names = self.folders[folder].pop(base, ())
        _unlink_all(folder, names)

    @classmethod
    def scan(cls, folder):
        """{output name: [its temporary files]} in ``folder``."""
        found = {}
        try:
            with os.scandir(folder) as it:
                for entry in it:
                    m = cls.PATTERN.match(entry.name)
                    if m:
                        found.setdefault(m.group(1), []).append(entry.name)
        except OSError:
            pass
        return found


class KeptTemps:
    """No clearing: the Dask engine's lanes, which live from batch to batch (a listing
    taken in one batch misses what a lost worker left later); the command clears its
    batch's temporary files once every task is done (:func:`remove_temps_of`)."""

    def clear(self, output):
        pass


def _unlink_all(folder, names):
    for name in names:
        try:
            os.unlink(os.path.join(folder, name))
        except OSError:
            pass


def remove_temps_of(folders, ours):
    """Delete the temporary files in ``folders`` of the outputs for which ``ours(path)``
    is true: what a batch's workers left (a worker lost while writing) once its jobs are
    done, one listing of each folder."""
    for folder in folders:
        for base, names in StaleTemps.scan(folder).items():
            if ours(os.path.join(folder, base)):
                _unlink_all(folder, names)


class Lane:
    """Runs jobs one after another in a child, replacing it when a job kills it."""

    def __init__(self, setup, env=None, timeout=None, max_memory=None, skip_existing=False, stale=None, worker=None,
                 crash_raises=False):
        """``worker``: a :class:`WorkerProcess` to start with (later ones, after a job
        killed its child, are started with ``python -m scatter_cli.engines.worker``).
        ``crash_raises``: a child that crashed (:class:`WorkerLost`'s ``crashed``) raises
        its WorkerLost from :meth:`run`, the jobs not yet answered dropped, instead of
        failing its job (the Dask engine: Dask runs the task again)."""
        self.setup, self.env = setup, env
        self.crash_raises = crash_raises
        self.timeout, self.max_memory = timeout, max_memory
        self.skip_existing = skip_existing
        self.stale = stale if stale is not None else StaleTemps()
        self.worker = worker
        self.sent = collections.deque()  # jobs the child has been given and not answered, oldest first
        self.stopped = False

    def run(self, jobs, done):
        """Run ``jobs`` (``(key, input, output, format, skip)`` each; ``skip``: whether an
        existing output is skipped, None for the lane's ``skip_existing``) and call
        ``done(key, record)`` for each, in the order given. A record has ``input``,
        ``output``, ``status``, ``error``, ... and ``warnings`` (lines naming the mesh)
        when sampling warned.

        After a job shorter than ``QUEUE_BELOW`` the next one is sent before its answer
        comes, so that the child never waits for this process between small meshes.
        A job that kills the child fails alone; the job queued behind it goes to the next child.
        """
        jobs = iter(jobs)
        last = None  # seconds the last job took
        free_at = 0.0  # when the child answered its last job
        while True:
            depth = 2 if last is not None and last < QUEUE_BELOW else 1
            while len(self.sent) < depth and not self.stopped:
                job = next(jobs, None)
                if job is None:
                    break
                skipped = self._skipped(job)
                if skipped is not None:
                    done(job[0], skipped)
                else:
                    self.sent.append((job, self._send(job)))
            if not self.sent:
                return
            job, sent_at = self.sent[0]
            started = max(sent_at, free_at)
            answer = self._receive(job, started)
            self.sent.popleft()
            free_at = time.monotonic()
            last = free_at - started
            done(job[0], self._record(job, answer, last))

    def _skipped(self, job):
        """Clear what earlier runs left of the job's output; its record if it is skipped."""
        _, input, output, _, skip = job
        t = time.perf_counter()
        self.stale.clear(output)
        if (self.skip_existing if skip is None else skip) and os.path.isfile(output):
            return record(input, output, "skipped", None, seconds=time.perf_counter() - t)
        return None

    def _send(self, job):
        """Give the job to the child (a new one if there is none); when it was sent."""
        _, input, output, fmt, _ = job
        if self.worker is None:
            self.worker = WorkerProcess(self.setup, self.env)
        sent_at = time.monotonic()
        try:
            self.worker.wait_ready()
            sent_at = time.monotonic()
            self.worker.send(input, output, fmt)
        except WorkerLost:
            pass  # the child died on a job before this one: reading that job's answer says so
        return sent_at

    def _receive(self, job, started):
        """The answer to the oldest job sent; when the child dies, that job's failure, and
        the jobs queued behind it are given to a new child."""
        try:
            return self.worker.receive(self.timeout, self.max_memory, started)
        except WorkerLost as lost:
            self.worker = None
            remove_temps(job[2])
            if self.stopped:
                raise
            if lost.crashed and self.crash_raises:
                self.sent.clear()
                raise
            for k, (queued, _) in enumerate(list(self.sent)[1:], 1):
                self.sent[k] = (queued, self._send(queued))
            return {"error": name_the_file(str(lost), job[1]), "count": None, "faces": None, "area": None}

    @staticmethod
    def _record(job, answer, seconds):
        _, input, output, _, _ = job
        status = "failed" if answer["error"] else "written"
        rec = record(input, output, status, answer["error"], answer["count"], answer["faces"], answer["area"], seconds)
        if answer.get("warnings"):  # not a report field: the batch prints and drops them
            rec["warnings"] = [name_the_file(w, input) for w in answer["warnings"]]
        return rec

    def stop(self):
        """Kill the child now (an interrupted batch); the job in flight raises WorkerLost."""
        self.stopped = True
        worker = self.worker
        if worker is not None:
            worker.kill("interrupted")
            for job, _ in list(self.sent):
                remove_temps(job[2])

    def close(self):
        if self.worker is not None:
            self.worker.close()
            self.worker = None


def record(input, output, status, error, count=None, faces=None, area=None, seconds=0.0):
    return {"input": input, "output": output, "status": status, "error": error, "count": count,
            "faces": faces, "area": area, "seconds": round(seconds, 6)}


if __name__ == "__main__":
    serve()
