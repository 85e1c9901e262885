"""The surface model: float64 geometries and instances (``model``), what a geometry's file
provides besides its triangles (normals, colours, UVs, textures), face areas and edges."""
