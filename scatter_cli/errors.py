"""The two kinds of failure the command line reports."""


class ScatterError(Exception):
    """A failure the user can act on: printed as one ``error: ...`` line, exit 1."""

    exit_code = 1


class ScatterUsageError(ScatterError):
    """A bad option or value: printed as one ``error: ...`` line, exit 2."""

    exit_code = 2
