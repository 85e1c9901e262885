"""The two kinds of failure the command line reports, and OS errors on an output turned into them."""

class ScatterError(Exception):
    """A failure the user can act on: printed as one ``error: ...`` line, exit 1."""

    exit_code = 1


class OutputClosed(Exception):
    """The reader of standard output went away (``scatter sample ... | head``).

    Not an OSError, so that click does not turn it into a silent exit 1: ``main`` exits
    141 (128 + SIGPIPE) quietly, as a Unix tool killed by SIGPIPE would.
    """


class ScatterUsageError(ScatterError):
    """A bad option or value: printed as one ``error: ...`` line, exit 2."""

    exit_code = 2


STDOUT = "standard output"


class writing:
    """``with writing(name):`` turns OS errors while writing ``name`` into one-line
    ScatterErrors naming it.

    A broken pipe (the reader left: a pipe, a FIFO, /dev/stdout) becomes OutputClosed.
    (A class, not a generator: a batch enters it several times per mesh.)
    """

    __slots__ = ("name",)

    def __init__(self, name):
        self.name = name

    def __enter__(self):
        return None

    def __exit__(self, kind, exc, traceback):
        if kind is None or not issubclass(kind, OSError):
            return False
        if issubclass(kind, BrokenPipeError):
            raise OutputClosed() from None
        raise ScatterError(f"{self.name}: cannot write: {exc.strerror or exc}") from None
