"""What an output can hold: the per-point attributes a user asks for (and, from the
format table :mod:`scatter_cli.writers.formats`, the file formats).

Names and columns only (no NumPy), so that ``--help`` and usage errors list them at no
start-up cost. A new format (in the table) or attribute (here) appears in ``--help`` by itself.
"""

# Output formats (-f), the file suffixes that select them, those --ascii applies to: from
# the one table of formats.
from .writers.formats import ASCII_FORMATS, FORMATS, SUFFIXES  # noqa: E402,F401

# Attribute name (as given to -a) -> (key in Samples, output columns, dtype kind).
# "real" columns take the coordinate precision; the others have a fixed type.
ATTRIBUTES = {
    "normal": ("normal", ("nx", "ny", "nz"), "real"),
    "smooth-normal": ("normal", ("nx", "ny", "nz"), "real"),
    "face": ("face", ("face_index",), "<i4"),
    "bary": ("bary", ("bary0", "bary1", "bary2"), "real"),
    "color": ("color", ("red", "green", "blue", "alpha"), "u1"),
    "uv": ("uv", ("u", "v"), "real"),
    "object": ("object", ("object_index",), "<i4"),
    "orient": ("orient", ("qx", "qy", "qz", "qw"), "real"),
    "sdf": ("sdf", ("sdf",), "<f8"),
    "inside": ("inside", ("inside",), "u1"),
    "winding": ("winding", ("winding",), "<f8"),
    "closest": ("closest", ("cx", "cy", "cz"), "real"),
}
# Columns always come in this order, whatever the order of -a.
KEY_ORDER = ("normal", "orient", "sdf", "inside", "winding", "closest", "face", "bary", "color", "uv", "object")
