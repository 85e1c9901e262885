"""Writers: PLY (binary or ASCII), CSV, XYZ, NPY, and through their modules PCD, LAS/LAZ and USD.

A file is written to a temporary name beside it and renamed into place only when
complete, so a failure never leaves a partial file and an existing one stays untouched.
"""

from __future__ import annotations

import contextlib
import os
import stat
import sys
import tempfile

import numpy as np

from .errors import STDOUT, ScatterError, ScatterUsageError, writing
from .outputs import FORMATS, SUFFIXES

PLY_TYPES = {"f4": "float", "f8": "double", "i4": "int", "u1": "uchar"}


def infer_format(path, fmt=None) -> str:
    """The output format: ``fmt`` if given, else from the suffix of ``path``, CSV on stdout."""
    if fmt:
        fmt = fmt.lower()
        if fmt not in FORMATS:
            raise ScatterUsageError(f"unknown output format '{fmt}' (choose from: {', '.join(FORMATS)})")
        return fmt
    if path is None or str(path) == "-":
        return "csv"
    suffix = os.path.splitext(str(path))[1].lstrip(".").lower()
    if suffix not in SUFFIXES:
        raise ScatterUsageError(f"cannot tell the format of '{path}' from its suffix: pass -f {'|'.join(FORMATS)}")
    return SUFFIXES[suffix]


def run_precision(fmt, precision):
    """The coordinate precision a run needs for ``fmt``: LAS quantises float64 points itself."""
    return "float64" if fmt in ("las", "laz") else precision


def _structured_dtype(layout):
    return np.dtype([(c, dt) for _, cols, dt in layout for c in cols])


class _Writer:
    def __init__(self, stream, layout, count):
        self.stream = stream
        self.layout = layout
        self.count = count
        self.written = 0
        self.report = {}

    def header(self):
        pass

    def write(self, samples):
        self.written += len(samples)
        self.stream.write(self.encode(samples))

    def finish(self):
        if self.count is not None and self.written != self.count:
            raise ScatterError(f"internal error: wrote {self.written} points, announced {self.count}")

    def close(self):
        """Release what the writer holds before its stream is closed, finished or not."""


class _BinaryWriter(_Writer):
    def encode(self, samples):
        if len(self.layout) == 1:
            return np.ascontiguousarray(samples.points, dtype=self.layout[0][2]).data
        return samples.to_structured().astype(_structured_dtype(self.layout), copy=False).data


class PlyWriter(_BinaryWriter):
    def __init__(self, stream, layout, count, ascii=False):
        super().__init__(stream, layout, count)
        self.ascii = ascii
        if ascii:
            self.encode = _TextEncoder(layout, " ")

    def header(self):
        lines = ["ply", f"format {'ascii' if self.ascii else 'binary_little_endian'} 1.0",
                 "comment made by scatter", f"element vertex {self.count}"]
        for _, cols, dt in self.layout:
            lines += [f"property {PLY_TYPES[dt.str[1:]]} {c}" for c in cols]
        lines.append("end_header")
        self.stream.write(("\n".join(lines) + "\n").encode("ascii"))


class NpyWriter(_BinaryWriter):
    def header(self):
        fmt = np.lib.format
        fmt.write_array_header_1_0(
            self.stream,
            {"descr": fmt.dtype_to_descr(_structured_dtype(self.layout)), "fortran_order": False, "shape": (self.count,)},
        )


class TextWriter(_Writer):
    def __init__(self, stream, layout, count, sep, with_header):
        super().__init__(stream, layout, count)
        self.encode = _TextEncoder(layout, sep)
        self.sep = sep
        self.with_header = with_header

    def header(self):
        if self.with_header:
            cols = [c for _, names, _ in self.layout for c in names]
            self.stream.write((self.sep.join(cols) + "\n").encode("ascii"))


class _TextEncoder:
    """Rows of text with enough digits to read back the exact binary values.

    float32: 9 significant digits; float64: the shortest repr that round-trips.
    """

    def __init__(self, layout, sep):
        self.layout = layout
        specs = []
        for _, cols, dt in layout:
            spec = {"f4": "%.9g", "f8": "%r"}.get(dt.str[1:], "%d")
            specs += [spec] * len(cols)
        self.ncols = len(specs)
        self.row = sep.join(specs) + "\n"

    def __call__(self, samples):
        n = len(samples)
        flat = [None] * (n * self.ncols)
        j = 0
        for key, cols, dt in self.layout:
            data = samples.points if key == "points" else samples.attributes[key]
            data = np.asarray(data, dtype=dt).reshape(n, len(cols))
            for c in range(len(cols)):
                flat[j :: self.ncols] = data[:, c].tolist()
                j += 1
        return ((self.row * n) % tuple(flat)).encode("ascii")


def make_writer(stream, fmt, layout, count, ascii=False, bounds=None, **options):
    """The writer of ``fmt``; ``bounds`` (2, 3): the sampled bounding box (LAS scale and offset).

    ``options`` for USD: ``path`` (its suffix picks .usda text or .usdc crate), ``up_axis``,
    ``meters_per_unit`` (from the input when it has them), ``spacing`` (placeholder size).
    """
    if fmt == "usd":
        from .usdwrite import UsdWriter

        return UsdWriter(stream, layout, count, **options)
    if fmt in ("las", "laz"):
        from .las import LasWriter

        return LasWriter(stream, layout, count, bounds, compress=fmt == "laz")
    if fmt == "pcd":
        from .pcd import PcdWriter

        return PcdWriter(stream, layout, count, ascii)
    if fmt == "ply":
        return PlyWriter(stream, layout, count, ascii)
    if fmt == "npy":
        return NpyWriter(stream, layout, count)
    if fmt == "csv":
        return TextWriter(stream, layout, count, ",", True)
    return TextWriter(stream, layout, count, " ", False)


def write_samples(chunks, path, fmt, layout, count, ascii=False, bounds=None, **options):
    """Write an iterable of Samples chunks (``count`` points in all) to ``path`` or stdout.

    Returns what the writer reports for ``--stats`` (LAS: the quantisation), a dict.
    """
    with open_output(path) as stream:
        if fmt == "usd":
            options["path"] = path
        writer = make_writer(stream, fmt, layout, count, ascii, bounds, **options)
        try:
            writer.header()
            for chunk in chunks:
                writer.write(chunk)
            writer.finish()
        finally:
            writer.close()
    return writer.report


def copy_tail(path, offset, stream, block=1 << 22):
    """Copy the bytes of file ``path`` from ``offset`` to its end into ``stream`` (for merging)."""
    with _reading(path), open(path, "rb") as f:
        f.seek(offset)
        for data in iter(lambda: f.read(block), b""):
            stream.write(data)


@contextlib.contextmanager
def _reading(path):
    try:
        yield
    except OSError as exc:
        raise ScatterError(f"{path}: cannot read: {exc.strerror or exc}") from None


@contextlib.contextmanager
def open_output(path):
    """A binary stream for ``path``; ``None`` or ``'-'`` is standard output.

    Regular files are written atomically through a temporary file in the same folder.
    Devices and pipes (``/dev/null``, a FIFO) are written in place.
    """
    if path is None or str(path) == "-":
        with writing(STDOUT):
            yield sys.stdout.buffer
            sys.stdout.buffer.flush()
        return
    path = os.fspath(path)
    if os.path.exists(path) and not os.path.isfile(path):
        if os.path.isdir(path):
            raise ScatterError(f"{path}: is a directory")
        with writing(path), open(path, "wb") as stream:
            yield stream
        return
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise ScatterError(f"{path}: cannot write: folder '{os.path.dirname(path) or '.'}' does not exist")
    with writing(path):
        fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".part", dir=folder)
    try:
        with writing(path), os.fdopen(fd, "wb", buffering=1 << 20) as stream:
            yield stream
        _set_mode(tmp, path)
        with writing(path):
            os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _set_mode(tmp, path):
    """Give the new file the mode an ordinary ``open(path, 'w')`` would (mkstemp makes 0600)."""
    if os.path.exists(path):
        mode = stat.S_IMODE(os.stat(path).st_mode)
    else:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    os.chmod(tmp, mode)
