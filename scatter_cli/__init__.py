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

# The layers, lowest first: a module may import from its own layer and the layers below,
# never from one above (tests/test_layers.py holds every module to it, function-level
# imports included). A module's layer is the longest entry that names it or a folder above it.
LAYERS = (
    ("errors", "core"),  # the two kinds of failure; machinery that knows no mesh
    ("stats",),  # statistics: chi-square, exact surface measures
    ("surface",),  # the surface model
    ("loading",),  # mesh files -> surface
    ("sampling",),  # surface -> points: the plan, warps, methods, weights, sources
    ("sampling.poisson",),  # Poisson-disk thinning
    ("sampling.stable",),  # --stable
    ("sampling.exterior",),  # --exterior
    ("volume",),  # points in space and their labels
    ("run",),  # options, the pipeline, chunks of points and attributes
    ("writers",),  # the table of formats; chunks -> files, and files read back
    ("api",),  # the Python API
    ("engines",),  # scatter batch: worker processes, Dask
    ("commands",),  # info, check, bench, merge, preview
    ("cli", "__main__"),  # the command line
)

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
    if name == "batch":
        from .engines.batch import batch

        return batch
    if name == "preview":
        from .commands.preview import preview

        return preview
    if name == "load_surface":
        from .loading.load import load_surface

        return load_surface
    if name == "Samples":
        from .run.columns import Samples

        return Samples
    if name == "ScatterError":
        from .errors import ScatterError

        return ScatterError
    raise AttributeError(f"module 'scatter_cli' has no attribute {name!r}")
