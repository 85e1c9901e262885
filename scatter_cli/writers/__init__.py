"""Writers: one module per output format, one table of formats (:mod:`.formats`), and
what they share (:mod:`.base`: the writer protocol and atomic output files).

Importing this package imports no format module and no NumPy: a format's module is
imported when a file of it is written.
"""

from __future__ import annotations

from ..core.interrupts import held
from .base import Writer, _Writer, check_room, copy_range, open_output
from .formats import (ASCII_FORMATS, BY_NAME, FORMATS, MERGEABLE, SUFFIXES, check_extra, check_output, infer_format,
                      load, run_precision)

__all__ = ["ASCII_FORMATS", "FORMATS", "MERGEABLE", "PLY_TYPES", "SUFFIXES", "Writer", "check_output", "copy_range",
           "file_size", "infer_format", "make_writer", "open_output", "run_precision", "write_samples", "write_stream"]


def make_writer(stream, fmt, layout, count, ascii=False, bounds=None, **options):
    """The writer of ``fmt``; ``bounds`` (2, 3): the sampled bounding box (LAS scale and offset).

    ``options`` for USD: ``path`` (its suffix picks .usda text or .usdc crate), ``up_axis``,
    ``meters_per_unit`` (from the input when it has them), ``spacing`` (placeholder size).
    """
    return load(fmt).make(fmt, stream, layout, count, ascii=ascii, bounds=bounds, **options)


def file_size(fmt, layout, count, ascii=False, **options):
    """Bytes of the output of ``count`` points of ``layout`` in ``fmt``, or None when the
    size is not known before the points are (text, ASCII, compressed, in-memory formats)."""
    return BY_NAME[fmt].file_size(layout, count, ascii, **options)


def write_samples(chunks, path, fmt, layout, count, ascii=False, bounds=None, crs=None, **options):
    """Write an iterable of Samples chunks (``count`` points in all) to ``path`` or stdout.

    ``crs``: LAS/LAZ only, the coordinate system to record, ``EPSG:N`` or WKT.

    Before any chunk is drawn: the output options are checked (usage errors), the format's
    extra must be installed, and a file whose size is known must fit on its file system.
    Returns what the writer reports for ``--stats`` (LAS: the quantisation), a dict.
    """
    check_output(fmt, ascii, crs)
    check_extra(fmt)
    if crs is not None:
        from .crs import crs_wkt

        options["wkt"] = crs_wkt(crs)
    size = file_size(fmt, layout, count, ascii, bounds=bounds, **options)
    if fmt == "usd":
        options["path"] = path
    with open_output(path, size) as stream:
        return write_stream(chunks, stream, fmt, layout, count, ascii, bounds, **options)


def write_stream(chunks, stream, fmt, layout, count, ascii=False, bounds=None, **options):
    """Write the chunks to the binary ``stream`` as :func:`write_samples` does (no checks).

    SIGINT and SIGTERM are held while the writer works (a library it calls, such as lazrs,
    would turn them into its own error) and raised between its steps."""
    writer = make_writer(stream, fmt, layout, count, ascii, bounds, **options)
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
