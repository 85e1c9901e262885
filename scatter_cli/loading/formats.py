"""The loader table: one row per mesh format scatter reads.

Names only (no NumPy, nothing of the readers imported), so that ``--help`` lists the
formats at no start-up cost; :mod:`scatter_cli.loading.load` turns each row into the
loader it names (:data:`~scatter_cli.loading.load.LOADERS`).
"""

from __future__ import annotations

from typing import NamedTuple


class InputFormat(NamedTuple):
    name: str  # as --input-format takes it, and the file suffix that selects it
    full: str = "trimesh"  # the loader of load.py that reads any job: trimesh, obj or usd
    fast: str | None = None  # the fast reader of fast.py for plain jobs on files (None: none)
    units: tuple | None = None  # (up axis, metres per unit) the format's specification fixes


GLTF_UNITS = ("Y", 1.0)  # glTF is Y up in metres by its specification

TABLE = (
    InputFormat("ply", fast="read_ply"),
    InputFormat("obj", "obj", "read_obj"),
    InputFormat("stl", fast="read_stl"),
    InputFormat("off", fast="read_off"),
    InputFormat("glb", fast="read_glb", units=GLTF_UNITS),
    InputFormat("gltf", units=GLTF_UNITS),
    *(InputFormat(name, "usd") for name in ("usd", "usda", "usdc", "usdz")),  # optional extra `usd`
)
INPUT_FORMATS = tuple(f.name for f in TABLE)
# What standard input (`-`, with --input-format) can carry: every one (USD goes through a
# temporary file, as usd-core reads stages by name).
STDIN_FORMATS = INPUT_FORMATS
# What `scatter batch` looks for in a folder.
MESH_SUFFIXES = tuple("." + f for f in INPUT_FORMATS)
