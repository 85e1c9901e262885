"""What an output can hold: the file formats and the per-point attributes a user asks for.

Names and columns only (no NumPy), so that ``--help`` and usage errors list them at no
start-up cost. A new format or attribute added here appears in ``--help`` by itself.
"""

# Output formats (-f), and the file suffixes that select them.
FORMATS = ("ply", "csv", "xyz", "npy", "pcd", "las", "laz", "usd")
SUFFIXES = {"ply": "ply", "csv": "csv", "xyz": "xyz", "txt": "xyz", "npy": "npy", "pcd": "pcd", "las": "las",
            "laz": "laz", "usd": "usd", "usda": "usd", "usdc": "usd"}
# Formats --ascii applies to.
ASCII_FORMATS = ("ply", "pcd")

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
