"""NPY output: one structured array, its fields named as the columns; and its reader."""

from __future__ import annotations

import io

import numpy as np

from ..errors import ScatterError
from .binary import BinaryWriter, row_size, structured_dtype
from .base import reading
from .pointfiles import PointFile, reason


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


# -- the reader ---------------------------------------------------------------------------

def read(path, fmt="npy"):
    """An NPY file of one structured array, a row a point."""
    npy = np.lib.format
    with reading(path), open(path, "rb") as f:
        try:
            version = npy.read_magic(f)
            read_header = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
            shape, fortran, dtype = read_header(f)
        except ValueError as exc:
            raise ScatterError(f"{path}: not an NPY file ({reason(exc)})") from None
        offset = f.tell()
    if len(shape) != 1 or fortran or dtype.names is None:
        raise ScatterError(f"{path}: not an NPY array of points (one structured row a point)")
    descr = npy.dtype_to_descr(dtype)
    return PointFile.checked(path, dtype, shape[0], offset, True, ("npy", str(descr)), lambda count: header(descr, count))
