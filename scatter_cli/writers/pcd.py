"""PCD (Point Cloud Library's format): a text header, then packed records, streamed.

Fields as PCL names them (``x y z``, ``normal_x normal_y normal_z``, ``rgb``), the other
columns under their own names, in the contract's column order. Colour is one 4-byte
``rgb`` field holding bytes b, g, r, a, as PCL's PointXYZRGB(A) keeps it in memory:
TYPE F in binary files (PCL's own type), TYPE U in ASCII ones, where the float reading
of an opaque colour is a NaN that text cannot carry (PCL's ASCII writer prints the
integer too). The reader (:func:`read`) reads both back.
"""

from __future__ import annotations

import numpy as np

from ..errors import ScatterError
from ..run.columns import Samples
from .base import Writer, reading
from .pointfiles import PointFile
from .text import TextEncoder

PCL_NAMES = {"nx": "normal_x", "ny": "normal_y", "nz": "normal_z"}
PCD_TYPES = {"f": "F", "i": "I", "u": "U"}


def pcd_layout(layout, ascii=False):
    """[(key, field names, dtype)] of the PCD records for a writer ``layout``."""
    out = []
    for key, cols, dt in layout:
        if key == "color":
            out.append(("rgb", ("rgb",), np.dtype("<u4" if ascii else "<f4")))
        else:
            out.append((key, tuple(PCL_NAMES.get(c, c) for c in cols), dt))
    return out


def pack_rgb(color):
    """(n,) uint32 ``a << 24 | r << 16 | g << 8 | b`` of ``color`` (n, 4) uint8 RGBA."""
    c = np.asarray(color, dtype=np.uint32)
    return (c[:, 3] << 24) | (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]


def header(fields, count, ascii):
    """The PCD v0.7 header for ``fields`` (a pcd_layout) and ``count`` points, as bytes."""
    names, sizes, types = [], [], []
    for _, cols, dt in fields:
        names += cols
        sizes += [str(dt.itemsize)] * len(cols)
        types += [PCD_TYPES[dt.kind]] * len(cols)
    lines = ["# .PCD v0.7 - Point Cloud Data file format", "VERSION 0.7", "FIELDS " + " ".join(names),
             "SIZE " + " ".join(sizes), "TYPE " + " ".join(types), "COUNT " + " ".join("1" * len(names)),
             f"WIDTH {count}", "HEIGHT 1", "VIEWPOINT 0 0 0 1 0 0 0", f"POINTS {count}",
             f"DATA {'ascii' if ascii else 'binary'}"]
    return ("\n".join(lines) + "\n").encode("ascii")


class PcdWriter(Writer):
    def __init__(self, stream, layout, count, ascii=False):
        super().__init__(stream, layout, count)
        self.ascii = ascii
        self.fields = pcd_layout(layout, ascii)
        self.dtype = np.dtype([(c, dt) for _, cols, dt in self.fields for c in cols])
        if ascii:
            self._text = TextEncoder(self.fields, " ")

    def header(self):
        self.stream.write(header(self.fields, self.count, self.ascii))

    def _columns(self, samples):
        """key -> (n, k) array of each PCD field group."""
        out = {}
        for key, cols, dt in self.fields:
            if key == "points":
                data = samples.points
            elif key == "rgb":
                data = pack_rgb(samples.attributes["color"]).view(dt)
            else:
                data = samples.attributes[key]
            out[key] = data.reshape(len(samples), len(cols))
        return out

    def encode(self, samples):
        columns = self._columns(samples)
        if self.ascii:
            return self._text(Samples(columns["points"], columns))
        if len(self.fields) == 1:
            return np.ascontiguousarray(samples.points, dtype=self.fields[0][2]).data
        rec = np.empty(len(samples), dtype=self.dtype)
        for key, cols, _ in self.fields:
            for j, c in enumerate(cols):
                rec[c] = columns[key][:, j]
        return rec.data


def make(fmt, stream, layout, count, ascii=False, **options):
    return PcdWriter(stream, layout, count, ascii)


def file_size(fmt, layout, count, **options):
    """Bytes of a binary PCD file of ``count`` points of ``layout``."""
    fields = pcd_layout(layout)
    return len(header(fields, count, False)) + count * sum(dt.itemsize * len(cols) for _, cols, dt in fields)


# -- the reader ---------------------------------------------------------------------------

PCD_KINDS = {"F": "f", "I": "i", "U": "u"}
CONTRACT_NAMES = {v: k for k, v in PCL_NAMES.items()}
MAX_HEADER = 1 << 16  # bytes a header may take


class PcdFile(PointFile):
    def columns(self, limit=None):
        """The columns as the contract names them: ``normal_x`` as ``nx``..., the packed
        ``rgb`` as ``red``, ``green``, ``blue`` and ``alpha``."""
        columns = {CONTRACT_NAMES.get(k, k): v for k, v in super().columns(limit).items()}
        if "rgb" in columns:
            columns.update(zip(("red", "green", "blue", "alpha"), unpack_rgb(columns.pop("rgb"))))
        return columns


def unpack_rgb(packed):
    """(r, g, b, a), each (n,) uint8, of the packed colours ``packed`` (n,) (4-byte float or uint32)."""
    word = np.ascontiguousarray(packed).view(np.uint32)
    return tuple(((word >> shift) & 255).astype(np.uint8) for shift in (16, 8, 0, 24))


def read(path, fmt="pcd"):
    """A binary or ASCII PCD file of one value a field."""
    lines, offset = header_lines(path)
    keys = {words[0]: words[1:] for words in (ln.split() for ln in lines if not ln.startswith("#")) if words}
    if not {"FIELDS", "SIZE", "TYPE", "POINTS", "DATA"} <= set(keys):
        raise ScatterError(f"{path}: not a PCD file")
    if keys["DATA"] not in (["ascii"], ["binary"]):
        raise ScatterError(f"{path}: PCD DATA {' '.join(keys['DATA'])} (scatter writes ascii and binary)")
    names = keys["FIELDS"]
    if any(c != "1" for c in keys.get("COUNT", ())):
        raise ScatterError(f"{path}: PCD fields of more than one value are not point columns")
    try:
        count = int(keys["POINTS"][0])
        dtype = np.dtype([(n, f"<{PCD_KINDS[t]}{s}") for n, s, t in zip(names, keys["SIZE"], keys["TYPE"], strict=True)])
    except (IndexError, KeyError, TypeError, ValueError):
        raise ScatterError(f"{path}: malformed PCD header (its FIELDS, SIZE, TYPE or POINTS)") from None
    layout = tuple(ln for ln in lines if not ln.startswith(("WIDTH", "POINTS", "#")))
    return PcdFile.checked(path, dtype, count, offset, keys["DATA"] == ["binary"], ("pcd", layout),
                           lambda total: header_from_lines(layout, total))


def header_lines(path):
    """(the header's lines, stripped, up to its DATA line; the offset of the byte after it)."""
    lines, offset = [], 0
    with reading(path), open(path, "rb") as f:
        for raw in iter(lambda: f.readline(4096), b""):
            offset += len(raw)
            lines.append(raw.decode("ascii", "replace").strip())
            if lines[-1].split()[:1] == ["DATA"] or offset > MAX_HEADER:
                break
    return lines, offset


def header_from_lines(layout, count):
    """A header with ``layout``'s lines (WIDTH/POINTS dropped) and ``count`` points."""
    lines = ["# .PCD v0.7 - Point Cloud Data file format"]
    for ln in layout:
        if ln.startswith("HEIGHT"):
            lines.append(f"WIDTH {count}")
        if ln.startswith("DATA"):
            lines.append(f"POINTS {count}")
        lines.append(ln)
    return ("\n".join(lines) + "\n").encode("ascii")
