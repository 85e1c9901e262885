"""Writers: one module per output format, one table of formats (:mod:`.formats`), and
what they share (:mod:`.base`: the writer protocol and atomic output files).

Importing this package imports no format module and no NumPy: a format's module is
imported when a file of it is written.
"""

from __future__ import annotations

from typing import NamedTuple

from ..core.interrupts import held
from .base import Writer, copy_range, open_output
from .formats import (ASCII_FORMATS, BY_NAME, FORMATS, MERGEABLE, SUFFIXES, check_extra, check_output, infer_format,
                      load, run_precision)

__all__ = ["ASCII_FORMATS", "FORMATS", "MERGEABLE", "PLY_TYPES", "SUFFIXES", "Output", "Writer", "check_output",
           "copy_range", "file_size", "infer_format", "open_output", "output", "run_precision", "write_output",
           "write_samples", "write_stream"]


class Output(NamedTuple):
    """An output with its options checked (:func:`output`): ``path`` (None or ``'-'``:
    standard output), the name of its format, ``--ascii`` and the WKT of ``--crs``."""

    path: object
    format: str
    ascii: bool = False
    wkt: str | None = None


def output(path, fmt=None, ascii=False, crs=None) -> Output:
    """The output ``path`` in ``fmt`` (default: from its suffix; CSV on standard output)
    with ``ascii`` and ``crs`` checked against that format: its usage errors, raised here."""
    fmt = infer_format(path, fmt)
    return Output(path, fmt, ascii, check_output(fmt, ascii, crs))


def file_size(fmt, layout, count, ascii=False, **options):
    """Bytes of the output of ``count`` points of ``layout`` in ``fmt``, or None when the
    size is not known before the points are (text, ASCII, compressed, in-memory formats)."""
    return _file_size(load(fmt), fmt, layout, count, ascii, **options)


def _file_size(module, fmt, layout, count, ascii, **options):
    if not BY_NAME[fmt].sized or ascii:
        return None
    return module.file_size(fmt, layout, count, **options)


def write_samples(chunks, path, fmt, layout, count, ascii=False, bounds=None, crs=None, **options):
    """Write an iterable of Samples chunks (``count`` points in all) to ``path`` or stdout
    in ``fmt``, its output options checked first (:func:`output`), as :func:`write_output`.

    ``bounds`` (2, 3): the sampled bounding box (LAS scale and offset); ``crs``: LAS/LAZ
    only, the coordinate system to record, ``EPSG:N`` or WKT. ``options`` for USD:
    ``up_axis``, ``meters_per_unit`` (from the input when it has them), ``spacing``
    (placeholder size).
    """
    return write_output(chunks, output(path, fmt, ascii, crs), layout, count, bounds=bounds, **options)


def write_output(chunks, out: Output, layout, count, **options):
    """Write an iterable of Samples chunks (``count`` points in all) to the checked output
    ``out``; ``options``: what the format's writer takes besides the points (its row's
    ``takes``: see :func:`write_samples`).

    Before any chunk is drawn: the format's extra must be installed, and a file whose size
    is known must fit on its file system. Returns what the writer reports for ``--stats``
    (LAS: the quantisation), a dict.
    """
    check_extra(out.format)
    module = load(out.format)
    if out.wkt is not None:
        options["wkt"] = out.wkt
    size = _file_size(module, out.format, layout, count, out.ascii, **options)
    if BY_NAME[out.format].named:
        options["path"] = out.path
    with open_output(out.path, size) as stream:
        return _drive(module.make(out.format, stream, layout, count, ascii=out.ascii, **options), chunks)


def write_stream(chunks, stream, fmt, layout, count, ascii=False, bounds=None, **options):
    """Write the chunks to the binary ``stream`` as :func:`write_samples` does (no checks)."""
    return _drive(load(fmt).make(fmt, stream, layout, count, ascii=ascii, bounds=bounds, **options), chunks)


def _drive(writer, chunks):
    """Run ``writer`` over the chunks; returns its report.

    SIGINT and SIGTERM are held while the writer works (a library it calls, such as lazrs,
    would turn them into its own error) and raised between its steps."""
    try:
        with held():
            writer.header()
        for chunk in chunks:
            with held():
                writer.write(chunk)
        with held():
            writer.finish()
    finally:
        writer.close()
    return writer.report


def __getattr__(name):
    # Names of a format module, kept importable from here without importing NumPy up front.
    if name == "PLY_TYPES":
        from .ply import PLY_TYPES

        return PLY_TYPES
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
