"""Workers for ``scatter batch`` forked from a process that imports what they need while
the command reads its arguments.

A batch's workers need NumPy and the sampler (about 70 ms of imports), the command its
command line (about 30 ms more than both share). Done one after the other they make most
of a small batch's fixed cost. So the ``scatter`` entry point (:func:`scatter_cli.__main__.main`)
starts a *fork server* when the command is a batch (:func:`wanted`), once the package and
the standard library both need are imported: a child that imports the sampler on the
other core while the command parses its arguments, then forks each worker when asked.

Each worker must be the command's own child, for the command waits for it, kills it and
reads its exit status (:class:`scatter_cli.engines.worker.WorkerProcess`). The server forks it
through a middle process that exits at once, and the command has made itself a child
subreaper (``PR_SET_CHILD_SUBREAPER``, :func:`claim`): Linux gives the orphaned worker to
it. A worker serves no job before that has happened (:func:`_adopted`).

A request travels over a Unix socket: the worker's environment as JSON, its standard
input and output as file descriptors (``SCM_RIGHTS``). When no server runs, or it fails,
the command forks its workers itself.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import sys
import time

PR_SET_CHILD_SUBREAPER = 36
REPLY_WITHIN = 120.0  # seconds the command waits for a worker's pid before it forks its own
_server = None  # the Server this process started, until claimed


def wanted(argv) -> bool:
    """Whether ``scatter ARGV`` is a batch on the local engine, on Linux: the first word
    that is not an option is ``batch``, and neither help nor the Dask engine is asked for
    (``SCATTER_FORKSERVER=0`` turns the server off)."""
    if not sys.platform.startswith("linux") or os.environ.get("SCATTER_FORKSERVER", "1") == "0":
        return False
    words = [a for a in argv if not a.startswith("-")]
    if not words or words[0] != "batch":
        return False
    dask = any(a == "--engine=dask" or (a == "--engine" and b == "dask") for a, b in zip(argv, argv[1:] + [""]))
    return not dask and not any(a in ("-h", "--help", "--scheduler") or a.startswith("--scheduler=") for a in argv)


def start() -> bool:
    """Start this process's fork server (once); False when it cannot be started."""
    global _server
    if _server is None:
        try:
            _server = Server()
        except OSError:
            return False
    return True


def claim():
    """The fork server, handed over once, with this process made the subreaper of the
    workers it forks; None when there is none or Linux refuses."""
    global _server
    server, _server = _server, None
    if server is None:
        return None
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl")
    except (OSError, AttributeError):
        server.close(kill=True)
        return None
    return server


class Server:
    """The command's side of the fork server: ``fork(env, stdin_fd, stdout_fd)`` returns
    the pid of a new worker, a child of this process; ``close()`` stops the server."""

    def __init__(self):
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self.pid = os.fork()
        except OSError:
            ours.close()
            theirs.close()
            raise
        if self.pid == 0:
            code = 1
            try:
                ours.close()
                _serve(theirs)
                code = 0
            finally:
                os._exit(code)
        theirs.close()
        ours.settimeout(REPLY_WITHIN)
        self.sock = ours

    def fork(self, env, stdin_fd, stdout_fd) -> int:
        """A worker reading jobs on ``stdin_fd`` and answering on ``stdout_fd`` (both stay
        open here too: the caller closes them). OSError when the server cannot."""
        if self.sock is None:
            raise OSError("the fork server stopped")
        try:
            _send(self.sock, json.dumps(env).encode(), [stdin_fd, stdout_fd])
            reply = b""
            while not reply.endswith(b"\n"):
                more = self.sock.recv(64)
                if not more:
                    raise OSError("the fork server stopped")
                reply += more
            return int(reply)
        except (OSError, ValueError):
            self.close(kill=True)
            raise OSError("the fork server stopped") from None

    def close(self, kill=False):
        """Stop the server (it leaves when its socket closes) and wait for it."""
        if self.sock is None:
            return
        self.sock.close()
        self.sock = None
        if kill:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        try:
            os.waitpid(self.pid, 0)
        except ChildProcessError:
            pass


def _serve(sock):
    """The server: import what the workers need, then fork one for every request, until
    the command closes its end."""
    from ..core import process
    from . import worker

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the group: the command decides
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    worker.die_with_parent()
    devnull = os.open(os.devnull, os.O_RDWR)
    os.dup2(devnull, 0)  # the command's standard input and output are not the server's
    os.dup2(devnull, 1)
    os.close(devnull)
    process.single_threaded_blas()
    process.keep_freed_memory()
    worker.preload()
    while True:
        request = _receive(sock)
        if request is None:
            return
        env, (stdin_fd, stdout_fd) = request
        try:
            pid = _fork_orphan(sock, json.loads(env), stdin_fd, stdout_fd)
        finally:
            os.close(stdin_fd)
            os.close(stdout_fd)
        sock.sendall(b"%d\n" % pid)


def _fork_orphan(sock, env, stdin_fd, stdout_fd) -> int:
    """Fork a worker through a middle process that exits at once, so that the worker is
    orphaned and adopted by the command (its subreaper); returns the worker's pid once
    the middle process is gone."""
    pid_r, pid_w = os.pipe()
    middle = os.fork()
    if middle == 0:
        code = 1
        try:
            os.close(pid_r)
            sock.close()
            me = os.getpid()
            pid = os.fork()
            if pid == 0:
                os.close(pid_w)
                _adopted(me)
                from .worker import forked_child

                forked_child(stdin_fd, stdout_fd, env)  # never returns
            os.write(pid_w, b"%d" % pid)
            code = 0
        finally:
            os._exit(code)
    os.close(pid_w)
    with os.fdopen(pid_r, "rb") as f:
        text = f.read()
    os.waitpid(middle, 0)
    return int(text)


def _adopted(middle, wait=5.0):
    """Wait until the middle process has left and this one has a new parent (the command,
    its subreaper), so that what follows (``PR_SET_PDEATHSIG`` among it) applies to the
    command."""
    deadline = time.monotonic() + wait
    while os.getppid() == middle:
        if time.monotonic() > deadline:
            os._exit(1)
        time.sleep(0.0005)


def _send(sock, data, fds):
    message = len(data).to_bytes(4, "little") + data
    sent = socket.send_fds(sock, [message], fds)
    if sent < len(message):  # a stream socket may take a large message in parts
        sock.sendall(message[sent:])


def _receive(sock):
    """(data, [fd, fd]) of one request, or None when the command has closed its end."""
    msg, fds, _, _ = socket.recv_fds(sock, 65536, 2)
    if not msg:
        return None
    size = int.from_bytes(msg[:4], "little")
    data = msg[4:]
    while len(data) < size:
        more = sock.recv(size - len(data))
        if not more:
            break
        data += more
    if len(fds) != 2 or len(data) != size:
        for fd in fds:
            os.close(fd)
        return None
    return data, fds
