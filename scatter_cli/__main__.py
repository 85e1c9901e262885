"""``python -m scatter_cli`` and the ``scatter`` command (``main``)."""

from .cli import run as main

if __name__ == "__main__":
    main()
