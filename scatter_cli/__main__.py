"""``python -m scatter_cli`` and the ``scatter`` command."""

import sys


def main():
    """Start a batch's fork server first (it imports what the workers need while the
    command reads its arguments: :mod:`scatter_cli.engines.forkserver`), then run the command."""
    from .engines import forkserver

    if forkserver.wanted(sys.argv[1:]):
        forkserver.start()
    from .cli import run

    run()


if __name__ == "__main__":
    main()
