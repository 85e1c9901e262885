"""NPY output: one structured array, its fields named as the columns."""

from __future__ import annotations

import io

import numpy as np

from ..errors import ScatterError
from .binary import BinaryWriter, row_size, structured_dtype
from .parts import Part, open_part, size


def header(descr, count) -> bytes:
    """The NPY 1.0 header of ``count`` rows of the dtype description ``descr``."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False, "shape": (count,)})
    return buf.getvalue()


class NpyWriter(BinaryWriter):
    def header(self):
        self.stream.write(header(np.lib.format.dtype_to_descr(structured_dtype(self.layout)), self.count))


def make(fmt, stream, layout, count, **options):
    return NpyWriter(stream, layout, count)


def file_size(fmt, layout, count, **options):
    """Bytes of an NPY file of ``count`` points of ``layout``."""
    return len(header(np.lib.format.dtype_to_descr(structured_dtype(layout)), count)) + count * row_size(layout)


# -- merge ------------------------------------------------------------------------------

def read_part(path, fmt="npy"):
    fmt_ = np.lib.format
    with open_part(path) as f:
        try:
            version = fmt_.read_magic(f)
            read = fmt_.read_array_header_1_0 if version == (1, 0) else fmt_.read_array_header_2_0
            shape, fortran, dtype = read(f)
        except ValueError as exc:
            raise ScatterError(f"{path}: not an NPY file ({exc})") from None
        offset = f.tell()
    if len(shape) != 1 or fortran or dtype.names is None:
        raise ScatterError(f"{path}: not an NPY array of points (one structured row a point)")
    if size(path) - offset != shape[0] * dtype.itemsize:
        raise ScatterError(f"{path}: the file size does not match its header (truncated?)")
    descr = fmt_.dtype_to_descr(dtype)
    return Part(path, ("npy", str(descr)), shape[0], (offset, size(path)),
                lambda parts: header(descr, sum(p.count for p in parts)))
