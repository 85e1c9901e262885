"""Fixed-size binary rows (PLY, NPY): a layout's structured dtype and the writer that packs it."""

from __future__ import annotations

import numpy as np

from .base import Writer


def structured_dtype(layout):
    """The NumPy structured dtype of one row of ``layout`` [(key, columns, dtype)]."""
    return np.dtype([(c, dt) for _, cols, dt in layout for c in cols])


def row_size(layout) -> int:
    """Bytes of one binary row of ``layout``."""
    return sum(np.dtype(dt).itemsize * len(cols) for _, cols, dt in layout)


class BinaryWriter(Writer):
    """Rows packed as the layout's structured dtype, little-endian, no padding."""

    def encode(self, samples):
        if len(self.layout) == 1:
            return np.ascontiguousarray(samples.points, dtype=self.layout[0][2]).data
        return samples.to_structured().astype(structured_dtype(self.layout), copy=False).data
