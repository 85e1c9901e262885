"""LAS 1.4 and LAZ output (optional extra ``las``: laspy with lazrs), streamed in chunks.

Point format 6, or 7 when colour is asked for (16-bit channels, 8-bit colour times 257).
Coordinates are scaled integers: one scale for the three axes, a power of ten chosen
from the sampled bounding box so that a stored point is within 1e-6 of the box's
diagonal of its float64 position and never coarser than 0.1 mm (1e-4, for data in
metres); the offset is the box's centre. Every other column is an Extra Bytes field of
its own, in the contract's column order: real columns as float32, indices as int32, the
colour's alpha as uint8. The global-encoding WKT bit is set in every file (LAS 1.4 requires
WKT for point formats 6-10); a coordinate system (``--crs``) is one OGC coordinate system
WKT record (LASF_Projection 2112), and there are no GeoTIFF keys.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os

import numpy as np

from ..core.interrupts import held
from ..errors import ScatterError
from .base import Writer, reading
from .pointfiles import SPANS, body_error, file_bytes, reason

SOFTWARE = "scatter"
FINEST_STEP = 1e-4  # 0.1 mm in metres: never coarser than this
RELATIVE_ERROR = 1e-6  # of the bounding-box diagonal
INT32_LIMIT = 2**31 - 2
RETURN_1_OF_1 = 0x11  # point formats 6-10: return number (bits 0-3) 1 of 1 (bits 4-7)


def _laspy(doing="LAS/LAZ output"):
    try:
        import laspy
    except ImportError:
        raise ScatterError(f"{doing} needs laspy and lazrs: pip install laspy lazrs pyproj") from None
    return laspy


def quantisation(bounds):
    """(step, offset (3,)): the coordinate scale and offset for points inside ``bounds`` (2, 3).

    The largest power of ten whose rounding error (sqrt(3)/2 step in 3D) stays within
    1e-6 of the diagonal, capped at 1e-4; made coarser only if the extent would overflow
    int32 at that step.
    """
    lo, hi = np.asarray(bounds, dtype=np.float64)
    diag = float(np.linalg.norm(hi - lo))
    want = min(FINEST_STEP, 2.0 * RELATIVE_ERROR * diag / math.sqrt(3.0)) if diag > 0 else FINEST_STEP
    step = 10.0 ** math.floor(math.log10(want))
    centre = 0.5 * (lo + hi)
    while True:
        offset = np.round(centre / step) * step
        if max(np.abs(hi - offset).max(), np.abs(lo - offset).max()) / step <= INT32_LIMIT:
            return step, offset
        step *= 10.0


def quantisation_report(step, offset, bounds):
    lo, hi = np.asarray(bounds, dtype=np.float64)
    diag = float(np.linalg.norm(hi - lo))
    err = math.sqrt(3.0) / 2.0 * step
    return {"scale": [step] * 3, "offset": [float(o) for o in offset], "max_error": err,
            "max_error_of_diagonal": err / diag if diag > 0 else None}


def extra_fields(layout):
    """[(key, column index, name, numpy dtype)] of the Extra Bytes fields for ``layout``."""
    out = []
    for key, cols, dt in layout[1:]:
        if key == "color":
            out.append((key, 3, "alpha", np.dtype("u1")))
            continue
        kind = np.dtype("<f4") if dt.kind == "f" else np.dtype("<i4")
        out += [(key, j, c, kind) for j, c in enumerate(cols)]
    return out


def make_header(layout, bounds, wkt=None):
    """(laspy header, step, offset (3,), extra fields) of a file of ``layout`` inside
    ``bounds`` (2, 3), recording the coordinate system ``wkt`` (OGC WKT) if given."""
    laspy = _laspy()
    colour = any(key == "color" for key, _, _ in layout)
    header = laspy.LasHeader(point_format=7 if colour else 6, version="1.4")
    step, offset = quantisation(bounds)
    header.scales = np.full(3, step)
    header.offsets = offset
    header.generating_software = SOFTWARE
    header.system_identifier = SOFTWARE
    extras = extra_fields(layout)
    if extras:
        header.add_extra_dims([laspy.ExtraBytesParams(name=name, type=dt) for _, _, name, dt in extras])
        _no_extra_statistics(header)
    set_crs(header, wkt)  # after the Extra Bytes record, where a merged file has it too
    return header, step, offset, extras


def set_crs(header, wkt):
    """Set the global-encoding WKT bit and, when ``wkt`` is given, add its record."""
    header.global_encoding.wkt = True
    if wkt:
        from laspy.vlrs.known import WktCoordinateSystemVlr

        header.vlrs.append(WktCoordinateSystemVlr(wkt))


def crs_of(header):
    """The WKT a LAS header records, or None."""
    from laspy.vlrs.known import WktCoordinateSystemVlr

    return next((vlr.string for vlr in header.vlrs if isinstance(vlr, WktCoordinateSystemVlr)), None)


def _no_extra_statistics(header):
    """Drop the optional min/max of the Extra Bytes descriptors: laspy 2.7 fills them from
    the first chunk's values when a file is written in one chunk, so they would be wrong
    and would depend on the chunk size."""
    for vlr in header.vlrs:
        for struct in getattr(vlr, "extra_bytes_structs", ()):
            struct.options &= ~(struct.MIN_BIT_MASK | struct.MAX_BIT_MASK)


BLOCK = 1 << 15  # points per record block: its records and scratch stay in the cache (1 to 2.5 MB)
EXTREMES_ROW = 256  # points per row of the wide reductions in column_extremes


class LasWriter(Writer):
    def __init__(self, stream, layout, count, bounds=None, compress=False, wkt=None):
        super().__init__(stream, layout, count)
        if bounds is None:
            raise ScatterError("internal error: LAS output needs the sampled bounding box")
        self.compress = compress
        self.header_, self.step, self.offset, self.extras = make_header(layout, bounds, wkt)
        self.report = {"las": quantisation_report(self.step, self.offset, bounds)}
        self._las = None
        self._fd = None
        self._pending = None  # LAS: the block being written on the writer thread
        self._thread = None
        self._half = 0
        self._records = None  # reused from chunk to chunk: the fields never written stay zero
        self._views = None
        self._real = np.empty(3 * BLOCK)  # scratch of one block: coordinates being quantised
        self._ints = np.empty(3 * BLOCK, np.int32)
        self._words = np.empty((2, BLOCK), np.uint32)  # scratch of one block: colour words
        self._tiled_offset = np.tile(self.offset, BLOCK)
        self._lo = np.full(3, np.iinfo(np.int64).max)
        self._hi = np.full(3, np.iinfo(np.int64).min)

    def header(self):
        laspy = _laspy()
        need_seekable(self.stream)
        backend = laspy.LazBackend.LazrsParallel if self.compress else None
        self._las = laspy.open(self.stream, mode="w", header=self.header_, do_compress=self.compress,
                               laz_backend=backend, closefd=False)
        if not self.compress:
            from concurrent.futures import ThreadPoolExecutor

            self._fd = file_descriptor(self.stream)
            self._thread = ThreadPoolExecutor(1, thread_name_prefix="las-write")

    def write(self, samples):
        # LAZ: laspy's point writer takes a chunk's records. LAS: blocks of records go
        # straight to the file from a thread, which writes one half of the record buffer
        # while the other is filled. The header's extents and counts are kept here
        # (LasWriter.write_points would sort every chunk's return numbers, and each of our
        # points is return 1 of 1).
        n = len(samples)
        if not n:
            return
        if self.compress:
            records = _laspy().PackedPointRecord(self.records(samples), self.header_.point_format)
            self._las.point_writer.write_points(records)
        else:
            self._record_buffer(2 * BLOCK)
            for a in range(0, n, BLOCK):
                block = self._fill(self._half * BLOCK, samples, a, min(n, a + BLOCK))
                self._wait()
                self._pending = self._thread.submit(write_all, self.stream, self._fd, block)
                self._half ^= 1
        self.written += n

    def close(self):
        """Stop the writer thread once its block is written: the stream is closed next."""
        if self._thread is not None:
            self._thread.shutdown(wait=True)
            self._thread = None

    def _wait(self):
        """Wait for the block being written (raising its error)."""
        if self._pending is not None:
            pending, self._pending = self._pending, None
            pending.result()

    def records(self, samples):
        """The chunk's point records (n,), in laspy's dtype of the point format; updates the
        extents. The array is reused by the next chunk."""
        n = len(samples)
        rec = self._record_buffer(n)
        for a in range(0, n, BLOCK):
            self._fill(a, samples, a, min(n, a + BLOCK))
        return rec

    def _record_buffer(self, n):
        """The record array (n,), grown when a chunk needs more."""
        if self._records is None or len(self._records) < n:
            self._records = np.zeros(n, self.header_.point_format.dtype())
            self._records["bit_fields"] = RETURN_1_OF_1
            self._views = record_views(self._records, self.extras)
        return self._records[:n]

    def _fill(self, at, samples, start, stop):
        """Records ``at ..`` of the buffer from the points ``start .. stop - 1`` of ``samples``
        (at most BLOCK); updates the extents. Returns those records."""
        m = stop - start
        view = {k: v[at : at + m] for k, v in self._views.items()}
        points = np.ascontiguousarray(samples.points[start:stop]).reshape(-1)
        q = quantise(points, self._tiled_offset[: 3 * m], self.step, self._real[: 3 * m], self._ints[: 3 * m])
        lo, hi = column_extremes(q)
        np.minimum(self._lo, lo, out=self._lo)
        np.maximum(self._hi, hi, out=self._hi)
        view["xyz"][...] = q.view("V12")
        if "color" in samples.attributes:
            rgb_257(samples.attributes["color"][start:stop], view["rg"], view["bb"], self._words[:, :m])
        for key, j, name, _ in self.extras:
            view[name][...] = samples.attributes[key].reshape(len(samples), -1)[start:stop, j]
        return self._records[at : at + m]

    def finish(self):
        self._wait()
        super().finish()
        h = self._las.header
        h.point_count = self.written
        h.number_of_points_by_return = np.zeros_like(h.number_of_points_by_return)
        h.number_of_points_by_return[0] = self.written
        if self.written:
            h.mins = self._lo * self.step + self.offset
            h.maxs = self._hi * self.step + self.offset
        self._las.close()
        clear_creation_date(self.stream)


def make(fmt, stream, layout, count, bounds=None, wkt=None, **options):
    return LasWriter(stream, layout, count, bounds, compress=fmt == "laz", wkt=wkt)


HEADER_SIZE = 375  # LAS 1.4 public header block
VLR_HEADER_SIZE = 54


def file_size(fmt, layout, count, bounds=None, wkt=None, **options):
    """Bytes of an (uncompressed) LAS file of ``count`` points of ``layout`` (None without
    ``bounds``: the writer says what is missing)."""
    if bounds is None:
        return None
    header = make_header(layout, bounds, wkt)[0]
    vlrs = sum(VLR_HEADER_SIZE + len(vlr.record_data_bytes()) for vlr in header.vlrs)
    return HEADER_SIZE + vlrs + count * header.point_format.size


def record_views(records, extras):
    """{name: strided view (n,)} of the fields of ``records`` (n,) filled per block:
    ``xyz`` (V12: X Y Z), ``rg`` (uint32: red and green), ``bb`` (uint16: blue), each extra."""
    def field(name, dtype):
        return np.ndarray(records.shape, dtype, records, records.dtype.fields[name][1], records.strides)

    views = {"xyz": field("X", "V12")}
    if "red" in records.dtype.names:
        views["rg"], views["bb"] = field("red", np.uint32), field("blue", np.uint16)
    for _, _, name, dt in extras:
        views[name] = field(name, dt)
    return views


def quantise(values, offset, step, real, out):
    """rint((values - offset) / step) of ``values`` (k,) as int32 into ``out`` (k,), through
    the float64 scratch ``real`` (k,); ``offset`` (k,). Returns ``out``."""
    np.subtract(values, offset, out=real)
    np.divide(real, step, out=real)
    np.rint(real, out=real)
    np.copyto(out, real, casting="unsafe")
    return out


def column_extremes(q):
    """(min (3,), max (3,)) of the columns of ``q`` (3m,): x y z x y z ...

    Reduced in rows of EXTREMES_ROW points, which vectorises: down the first axis of an
    (m, 3) array NumPy reduces three values at a time."""
    m = len(q) // 3
    head = m - m % EXTREMES_ROW
    parts = [q[3 * head :].reshape(-1, 3)]
    if head:
        rows = q[: 3 * head].reshape(-1, 3 * EXTREMES_ROW)
        parts += [np.minimum.reduce(rows, axis=0).reshape(-1, 3), np.maximum.reduce(rows, axis=0).reshape(-1, 3)]
    both = np.concatenate(parts)
    return both.min(axis=0), both.max(axis=0)


def rgb_257(color, rg, bb, words):
    """257 c of the 8-bit ``color`` (m, 4) into the record fields red and green (``rg``,
    uint32 (m,)) and blue (``bb``, uint16 (m,)). 257 c has both bytes equal to c, so
    (red | green << 16) * 257 is the two channels' four bytes. ``words`` (2, m) scratch."""
    rgba = np.ascontiguousarray(color).view(np.uint32).reshape(-1)  # r | g << 8 | b << 16 | a << 24
    low, high = words
    np.bitwise_and(rgba, 0xFF, out=low)
    np.bitwise_and(rgba, 0xFF00, out=high)
    np.left_shift(high, 8, out=high)
    np.bitwise_or(low, high, out=low)
    np.multiply(low, 257, out=rg)
    np.right_shift(rgba, 16, out=high)
    np.bitwise_and(high, 0xFF, out=high)
    np.multiply(high, 257, out=bb, casting="unsafe")


def need_seekable(stream):
    """Refuse a stream that cannot seek (standard output, a pipe): laspy completes the
    header at the end."""
    try:
        seekable = stream.seekable()
    except (AttributeError, OSError):
        seekable = False
    if not seekable:
        raise ScatterError("LAS/LAZ output needs a file (-o PATH): its header is completed at the end")


def file_descriptor(stream):
    """The file descriptor behind ``stream``, its buffer flushed, or None (an in-memory stream)."""
    try:
        fd = stream.fileno()
    except (AttributeError, OSError):
        return None
    stream.flush()
    return fd


def write_all(stream, fd, data):
    """Write the array ``data`` to the file descriptor ``fd`` (the stream's: no copy into its
    buffer) or, without one, to ``stream``."""
    view = memoryview(data.view(np.uint8))
    if fd is None:
        stream.write(view)
        return
    while view:
        view = view[os.write(fd, view):]


CREATION_DATE_AT = 90  # header bytes 90-93: creation day of year and year (uint16 each)


def clear_creation_date(stream):
    """Zero the header's creation date ("not set"): the output depends on the input, the
    options and the seed only, not on the day it was written (laspy always stamps today)."""
    stream.seek(CREATION_DATE_AT)
    stream.write(bytes(4))
    stream.seek(0, 2)


# -- the reader ---------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class LasFile:
    """A LAS or LAZ file as its laspy ``header`` describes it (see :mod:`.pointfiles`);
    ``compress``: a file joined from it is LAZ."""

    path: str
    header: object
    compress: bool
    up_axis: str = "Z"

    @property
    def count(self):
        return self.header.point_count

    @property
    def layout(self):
        """What files must share to be joined: point format, extra bytes, scale, offset
        and coordinate system."""
        h = self.header
        return ("las", h.point_format.id, tuple(h.point_format.extra_dimension_names), tuple(h.scales.tolist()),
                tuple(h.offsets.tolist()), crs_of(h))

    def columns(self, limit=None):
        """x, y, z (float64), the colour in 8 bits (``red``, ``green``, ``blue``) and every
        Extra Bytes column: of every point, or of SPANS runs of about ``limit`` in all."""
        if not self.count:
            return {c: np.empty(0) for c in "xyz"}
        with las_errors(self.path), _laspy().open(self.path) as reader:
            if limit is None or self.count <= limit:
                parts = [reader.read_points(self.count)]
            else:
                parts = list(_spans(reader, self.count, math.ceil(limit / SPANS)))
        columns = {c: np.concatenate([np.asarray(p[c], dtype=np.float64) for p in parts]) for c in "xyz"}
        names = self.header.point_format.dimension_names
        for name in [c for c in ("red", "green", "blue") if c in names]:  # scatter writes 8-bit colour times 257
            columns[name] = np.concatenate([np.asarray(p[name]) >> 8 for p in parts])
        for name in self.header.point_format.extra_dimension_names:
            columns[name] = np.concatenate([np.asarray(p[name]) for p in parts])
        return columns

    def join(self, files, stream):
        """Write ``files`` (this one first, all of its layout) to ``stream`` as one file:
        their points re-written through laspy (LAZ points are compressed chunks) under a
        header like this one's."""
        with held():  # laspy and lazrs write: a signal is raised once they are done
            write_joined([f.path for f in files], self.header, stream, self.compress)


def _spans(reader, total, rows):
    """Runs of ``rows`` points read at SPANS evenly spaced points of the file."""
    for j in range(SPANS):
        start = total * j // SPANS
        reader.seek(start)
        yield reader.read_points(min(rows, total - start))


def read(path, fmt):
    """A LAS or LAZ file (``fmt``: "las" or "laz", what a file joined from it is); an
    uncompressed one must hold the points its header says."""
    laspy = _laspy(f"{path}: reading LAS/LAZ")
    with las_errors(path), laspy.open(path) as f:
        header = f.header
    have, row = file_bytes(path) - header.offset_to_point_data, header.point_format.size
    if not header.are_points_compressed and have < header.point_count * row:
        raise body_error(path, have, header.point_count, row)
    return LasFile(path, header, fmt == "laz")


@contextlib.contextmanager
def las_errors(path):
    """laspy's errors on a file that is not LAS/LAZ as one line naming it."""
    try:
        with reading(path):
            yield
    except ScatterError:
        raise
    except Exception as exc:  # laspy raises its own error types for bad files
        raise ScatterError(f"{path}: not a LAS/LAZ file ({reason(exc)})") from None


def write_joined(paths, first, stream, compress, chunk=1 << 20):
    """Write the points of ``paths`` in order to ``stream`` under a header like ``first``'s."""
    laspy = _laspy()
    header = laspy.LasHeader(point_format=first.point_format, version=first.version)
    header.scales, header.offsets = first.scales, first.offsets
    header.generating_software = first.generating_software
    header.system_identifier = first.system_identifier
    set_crs(header, crs_of(first))
    _no_extra_statistics(header)
    need_seekable(stream)
    backend = laspy.LazBackend.LazrsParallel if compress else None
    with laspy.open(stream, mode="w", header=header, do_compress=compress, laz_backend=backend,
                    closefd=False) as writer:
        for p in paths:
            for points in _chunks(p, chunk):
                writer.write_points(points)
    clear_creation_date(stream)


def _chunks(path, chunk):
    """The points of the file ``path``, ``chunk`` at a time; a bad one (a LAZ part is
    checked only as it is read) is the reader's one-line error."""
    with las_errors(path), _laspy().open(path) as f:
        yield from f.chunk_iterator(chunk)
