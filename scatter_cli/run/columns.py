"""The points and their per-point attributes, and the column layout every writer uses."""

from __future__ import annotations

import numpy as np

from .fields import ATTRIBUTES, KEY_ORDER


def column_layout(keys, real_dtype):
    """[(key, column names, numpy dtype)] for ``points`` then the given keys, in file order."""
    real = np.dtype(real_dtype).newbyteorder("<")
    layout = [("points", ("x", "y", "z"), real)]
    for key in KEY_ORDER:
        if key in keys:
            _, cols, kind = next(v for v in ATTRIBUTES.values() if v[0] == key)
            layout.append((key, cols, real if kind == "real" else np.dtype(kind)))
    return layout


class Samples:
    """Points ``(n, 3)`` and one array per requested attribute.

    ``samples.points``, ``samples.normal`` (n, 3), ``samples.face`` (n,) int32,
    ``samples.bary`` (n, 3), ``samples.color`` (n, 4) uint8, ``samples.uv`` (n, 2),
    ``samples.object`` (n,) int32, ``samples.orient`` (n, 4) quaternions ``qx qy qz qw``. ``info`` holds run statistics (area, radius, ...).
    """

    def __init__(self, points, attributes=None, info=None):
        self.points = points
        self.attributes = dict(attributes or {})
        self.info = dict(info or {})

    def __getattr__(self, name):
        attributes = self.__dict__.get("attributes", {})
        if name in attributes:
            return attributes[name]
        raise AttributeError(f"Samples has no attribute {name!r} (requested: {', '.join(attributes) or 'none'})")

    def __len__(self):
        return len(self.points)

    def __repr__(self):
        fields = ", ".join(["points"] + list(self.attributes))
        return f"Samples(n={len(self)}, dtype={self.points.dtype}, fields=[{fields}])"

    def layout(self):
        return column_layout(self.attributes, self.points.dtype)

    def to_structured(self):
        """One structured array (n,) with the output columns, as the NPY writer stores it."""
        layout = self.layout()
        dtype = np.dtype([(c, dt) for _, cols, dt in layout for c in cols])
        out = np.empty(len(self), dtype=dtype)
        for key, cols, _ in layout:
            data = self.points if key == "points" else self.attributes[key]
            data = data.reshape(len(self), -1)
            for j, c in enumerate(cols):
                out[c] = data[:, j]
        return out
