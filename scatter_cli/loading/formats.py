"""What scatter reads: the mesh formats and the file suffixes that select them.

Names only (no NumPy), so that ``--help`` lists them at no start-up cost.
"""

# Read through the fast readers or trimesh.
MESH_FORMATS = ("ply", "obj", "stl", "off", "glb", "gltf")
# Read by usdread (optional extra `usd`).
USD_FORMATS = ("usd", "usda", "usdc", "usdz")
INPUT_FORMATS = MESH_FORMATS + USD_FORMATS
# What standard input (`-`, with --input-format) can carry: every one (USD goes through a
# temporary file, as usd-core reads stages by name).
STDIN_FORMATS = INPUT_FORMATS
# What `scatter batch` looks for in a folder.
MESH_SUFFIXES = tuple("." + f for f in INPUT_FORMATS)
