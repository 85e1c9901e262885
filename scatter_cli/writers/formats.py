"""The output formats: one row per format, read by everything that depends on the format.

Names, suffixes and flags only (no NumPy, no format module imported), so that ``--help``
and usage errors read it at no start-up cost. The writer of a format is the class
``WRITER`` of its module ``scatter_cli.writers.MODULE``, imported when a file is written.

A format module provides ``Writer(stream, layout, count, **options)`` (see
:mod:`scatter_cli.writers.base`); a format with ``sized`` set also provides
``file_size(layout, count, **options) -> int`` (its header plus ``count`` rows, known
before any point is drawn); and every one its reader, ``read(path, fmt)``
(:mod:`scatter_cli.writers.pointfiles`), which ``merge`` (a ``mergeable`` format's
parts) and ``preview`` both read its files with.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from typing import NamedTuple

from ..errors import ScatterError, ScatterUsageError


class Format(NamedTuple):
    name: str  # as -f takes it
    suffixes: tuple  # file suffixes that select it (without the dot)
    module: str  # scatter_cli.writers.<module> holds its writer
    ascii: bool = False  # has an ASCII variant (--ascii)
    float64: bool = False  # takes float64 points whatever --precision says (it stores its own type)
    mergeable: bool = True  # scatter merge joins files of it
    sized: bool = True  # binary size known before any work: header + count x row size
    crs: bool = False  # records a coordinate system (--crs)
    extra: tuple = ()  # modules of an optional extra it needs
    needs: str = ""  # what to tell a user who lacks them
    hint: str = ""  # how to install them (the packages themselves)
    takes: tuple = ()  # what its writer takes from the run besides the points (keywords of make)
    named: bool = False  # its writer reads the output's file name (USD: .usda text, .usdc crate)
    skipped: tuple = ()  # suffixes a folder search leaves out (too many other files have them)


LAS_EXTRA = dict(float64=True, crs=True, extra=("laspy", "lazrs"), needs="laspy and lazrs",
                 hint="pip install laspy lazrs pyproj", takes=("bounds",))

TABLE = (
    Format("ply", ("ply",), "ply", ascii=True),
    Format("csv", ("csv",), "text", sized=False),
    Format("xyz", ("xyz", "txt"), "text", sized=False, skipped=("txt",)),
    Format("npy", ("npy",), "npy"),
    Format("pcd", ("pcd",), "pcd", ascii=True),
    Format("las", ("las",), "las", **LAS_EXTRA),
    Format("laz", ("laz",), "las", sized=False, **LAS_EXTRA),
    Format("usd", ("usd", "usda", "usdc"), "usd", mergeable=False, sized=False, extra=("pxr",),
           needs="usd-core", hint="pip install usd-core", takes=("up_axis", "meters_per_unit", "spacing"),
           named=True),
)
BY_NAME = {f.name: f for f in TABLE}
FORMATS = tuple(BY_NAME)
SUFFIXES = {suffix: f.name for f in TABLE for suffix in f.suffixes}
SEARCHED_SUFFIXES = tuple(suffix for f in TABLE for suffix in f.suffixes if suffix not in f.skipped)
ASCII_FORMATS = tuple(f.name for f in TABLE if f.ascii)
MERGEABLE = tuple(f.name for f in TABLE if f.mergeable)
CRS_FORMATS = tuple(f.name for f in TABLE if f.crs)


def infer_format(path, fmt=None, choices=FORMATS) -> str:
    """The output format: ``fmt`` if given, else from the suffix of ``path``, CSV on stdout.

    ``choices``: the formats the caller takes (``merge``: the mergeable ones)."""
    if fmt:
        fmt = fmt.lower()
        if fmt not in choices:
            raise ScatterUsageError(f"unknown output format '{fmt}' (choose from: {', '.join(choices)})")
        return fmt
    if path is None or str(path) == "-":
        return "csv"
    suffix = os.path.splitext(str(path))[1].lstrip(".").lower()
    if SUFFIXES.get(suffix) not in choices:
        raise ScatterUsageError(f"cannot tell the format of '{path}' from its suffix: pass -f {'|'.join(choices)}")
    return SUFFIXES[suffix]


def run_precision(fmt, precision):
    """The coordinate precision a run needs for ``fmt`` (LAS quantises float64 points itself)."""
    return "float64" if BY_NAME[fmt].float64 else precision


def check_output(fmt, ascii=False, crs=None):
    """Usage errors of the output options for ``fmt``: ``--ascii`` and ``--crs`` where the
    format has no such thing, and a ``--crs`` that is neither ``EPSG:N`` nor WKT.
    Returns the WKT of ``crs`` (None without one)."""
    if ascii and not BY_NAME[fmt].ascii:
        raise ScatterUsageError(f"--ascii applies to {' and '.join(f.upper() for f in ASCII_FORMATS)} output only")
    if crs is not None and not BY_NAME[fmt].crs:
        raise ScatterUsageError(f"--crs applies to {'/'.join(f.upper() for f in CRS_FORMATS)} output only, "
                                f"not {fmt.upper()}")
    if crs is None:
        return None
    from .crs import crs_wkt

    return crs_wkt(crs)


def check_extra(fmt):
    """A one-line error naming what to install when ``fmt`` needs an extra that is missing
    (found without importing it)."""
    spec = BY_NAME[fmt]
    if any(importlib.util.find_spec(m) is None for m in spec.extra):
        raise ScatterError(f"{fmt.upper()} output needs {spec.needs}: {spec.hint}")


def load(fmt):
    """The module of ``fmt``'s writer."""
    return importlib.import_module(f"{__package__}.{BY_NAME[fmt].module}")
