"""SIGINT and SIGTERM: raised as exceptions where the command's own Python code runs, held
while a writer is inside a library.

Python runs a signal's handler wherever the main thread next runs Python, and that can be
inside a library that calls back into Python: lazrs calls the output stream's ``write``
and ``seek``, and a write interrupted by the signal runs the handler right there. An
exception raised in such a callback becomes the library's own error (``LazrsError:
Failed to call seek``) and the signal is lost. Inside :func:`held` the handler only
records the signal, which is raised when the held step ends.
"""

from __future__ import annotations

import signal


class Terminated(BaseException):
    """SIGTERM."""


class Interrupted(BaseException):
    """SIGINT, raised instead of KeyboardInterrupt: click turns that into a silent exit."""


_RAISES = {signal.SIGINT: Interrupted, signal.SIGTERM: Terminated}
_holding = 0  # depth of held() sections
_pending = None  # the first signal received while holding


def _on_signal(signum, frame):
    global _pending
    if _holding:
        _pending = _pending or signum
        return
    raise _RAISES[signum]()


def install():
    """Handle SIGTERM, and SIGINT unless the process was started ignoring it (``cmd &``)."""
    signal.signal(signal.SIGTERM, _on_signal)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _on_signal)


class held:
    """``with held():`` holds SIGINT and SIGTERM for the duration (a writer's step): one
    that arrives is raised as the step ends, whatever the step raised. Without
    :func:`install` (the Python API) this does nothing."""

    __slots__ = ()

    def __enter__(self):
        global _holding
        _holding += 1

    def __exit__(self, kind, exc, traceback):
        global _holding, _pending
        _holding -= 1
        if not _holding and _pending is not None:
            signum, _pending = _pending, None
            raise _RAISES[signum]()
        return False
