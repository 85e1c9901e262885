"""trimesh's vertex split of an OBJ material group whose faces carry ``vt`` or ``vn`` refs.

trimesh's OBJ loader (``process=False``) gives such a group one vertex per distinct
(v, vt, vn) ref triple (v, vt or v, vn for the other forms), in the order of its
``unmerge_faces``: the triples hashed into one uint64 each (``grouping.hashable_rows``),
made unique (sorted by that hash), then ordered by ``argsort`` of the v column (NumPy's
default, unstable kind, so ties keep the order that sort leaves). The compiled reader
(``_creaders.read_obj(data, True)``) gives each triangle corner's hash in trimesh's
triangle order; this module finishes the split with the same NumPy calls on the same
arrays, so the vertices, faces, UVs and normals are trimesh's bit for bit.
"""

from __future__ import annotations

import numpy as np

_COLUMNS = {1: ("v", "vt"), 2: ("v", "vn"), 3: ("v", "vt", "vn")}


def split_group(vertices, keys, form, vt, vn):
    """(vertices (P, 3), faces (F, 3) int64, tables {"uv": (P, 2) or None, "normals":
    (P, 3) or None}) of one group, or None (hand the file to trimesh).

    vertices (V, 3), vt (T, 2), vn (N, 3) float64: the file's; keys (F, 3) int64 holding
    the uint64 hash of each corner's refs, overwritten with the faces (returned in its
    memory); form 1 (v/vt), 2 (v//vn) or 3 (v/vt/vn).
    """
    columns = _COLUMNS[form]
    hashes = keys.reshape(-1).view(np.uint64)
    unique = _sorted_unique(hashes)  # trimesh's pairs = stack[unique], as their hashes
    # trimesh's pairs[:, 0].argsort(): NumPy sorts a contiguous copy of that strided
    # column, so the column alone gives the same order, ties included
    order = _column(unique, 0, len(columns)).argsort()
    remap = np.empty(len(order), dtype=np.int64)
    remap[order] = np.arange(len(order))
    for a in range(0, len(hashes), _BLOCK):  # the faces into the keys' memory, block by block
        hashes[a : a + _BLOCK] = remap[np.searchsorted(unique, hashes[a : a + _BLOCK])]
    del remap
    pairs = unique[order]
    del unique, order
    split = {}
    for name, table in (("v", vertices), ("vt", vt), ("vn", vn)):
        if name in columns:
            refs = _column(pairs, columns.index(name), len(columns))
            if not len(table) or refs.min() < -len(table) or refs.max() >= len(table):
                return None  # trimesh drops what it cannot index, or reads no such lines
            split[name] = table[refs]
            del refs
    return split["v"], keys, {"uv": split.get("vt"), "normals": split.get("vn")}


_BLOCK = 1 << 16


def _sorted_unique(values):
    """np.unique(values) for (n,) uint64, by a sort and a mask: the same array (np.unique
    of NumPy 2.4 takes 30 times as long on millions of keys)."""
    s = np.sort(values)
    keep = np.empty(len(s), dtype=bool)
    keep[:1] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]


def _column(hashes, k, count):
    """Column k of the (n, count) int64 rows packed in ``hashes`` (n,) uint64, as
    trimesh's hashable_rows packs them: ``precision`` bits each, offset by half its range."""
    precision = 64 // count
    bits = hashes >> np.uint64(k * precision)
    np.bitwise_and(bits, np.uint64(2**precision - 1), out=bits)
    column = bits.view(np.int64)  # below 2**precision: the same values
    column -= 2 ** (precision - 1)
    return column
