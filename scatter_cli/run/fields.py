"""The per-point attributes a user asks for, and the columns each one fills.

Names and columns only (no NumPy), so that ``--help`` and usage errors list them at no
start-up cost. A new attribute (here) appears in ``--help`` by itself; the file formats
are the writers' table (:mod:`scatter_cli.writers.formats`).
"""

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
    "sharp": ("sharp", ("sharp",), "u1"),
}
# Columns always come in this order, whatever the order of -a.
KEY_ORDER = ("normal", "orient", "sdf", "inside", "winding", "closest", "face", "bary", "color", "uv", "object",
             "sharp")
