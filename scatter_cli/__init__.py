"""scatter: spread points uniformly over mesh surfaces.

    >>> import scatter_cli
    >>> s = scatter_cli.sample("mesh.ply", count=1000, attributes=("normal",))
    >>> s.points.shape, s.normal.shape
    ((1000, 3), (1000, 3))
"""

# The distribution's name on the package index (the command is `scatter`, the import
# package `scatter_cli`): `--version` reads its version.
DISTRIBUTION = "mesh-scatter"

__all__ = ["sample", "prepare", "batch", "preview", "load_surface", "Samples", "ScatterError", "version"]

# The function, not the module of the same name (which imports only the standard library).
from .batch import batch  # noqa: E402
from .preview import preview  # noqa: E402


def version() -> str:
    """The installed package's version; from pyproject.toml when run from a checkout."""
    from importlib import metadata

    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return _checkout_version()


def _checkout_version():
    import tomllib
    from pathlib import Path

    try:
        with open(Path(__file__).resolve().parent.parent / "pyproject.toml", "rb") as f:
            return tomllib.load(f)["project"]["version"]
    except (OSError, KeyError, tomllib.TOMLDecodeError):
        return "unknown"


def __getattr__(name):
    if name == "__version__":
        return version()
    # Imported on first use so that `scatter --help` does not pay for numpy and trimesh.
    if name in ("sample", "prepare"):
        from . import api

        return getattr(api, name)
    if name == "load_surface":
        from .loaders import load_surface

        return load_surface
    if name == "Samples":
        from .columns import Samples

        return Samples
    if name == "ScatterError":
        from .errors import ScatterError

        return ScatterError
    raise AttributeError(f"module 'scatter_cli' has no attribute {name!r}")
