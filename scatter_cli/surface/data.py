"""What a geometry's file provides besides positions: UVs, colours, textures, normals.

Only looks at what trimesh already holds (no image is decoded here); every table is
built by the caller that needs it, once per geometry, never per instance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.elementary import atan2
from .texture import REPEAT, Texture


@dataclass
class VertexTables:
    """What a reader other than trimesh found besides positions (a Geometry's ``mesh``).

    vertices (V, 3), faces (F, 3): the geometry's own arrays. uv (V, 2) float64; normals
    (V, 3) float64 (None: computed from the faces when asked for); colour as one of
    vertex_colors (V, 4), face_colors (F, 4) or constant_color (4,), float64 RGBA in
    [0, 255]. ``point_of`` (V,) int64: when the vertices are per-corner copies (to carry
    face-varying values), the file point each copy came from, so that computed normals
    are smooth across the copies.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None = None
    normals: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None
    face_colors: np.ndarray | None = None
    constant_color: np.ndarray | None = None
    point_of: np.ndarray | None = None

    @property
    def vertex_normals(self):
        if self.normals is not None:
            return self.normals
        if self.point_of is None:
            return weighted_vertex_normals(self.vertices, self.faces)
        points = np.empty((int(self.point_of.max()) + 1, 3)) if len(self.point_of) else np.empty((0, 3))
        points[self.point_of] = self.vertices
        return weighted_vertex_normals(points, self.point_of[self.faces])[self.point_of]


def weighted_vertex_normals(vertices, faces):
    """(V, 3) float64 unit vertex normals: face normals summed around each vertex, weighted
    by the corner angle (as trimesh computes them). vertices (V, 3), faces (F, 3) int64."""
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[~np.isfinite(n).all(axis=1)] = 0.0
    angles = np.empty(faces.shape)
    for k in range(3):
        a, b = tri[:, (k + 1) % 3] - tri[:, k], tri[:, (k + 2) % 3] - tri[:, k]
        angles[:, k] = atan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))
    angles[~np.isfinite(angles)] = 0.0
    flat = faces.ravel()
    out = np.empty((len(vertices), 3))
    for c in range(3):
        out[:, c] = np.bincount(flat, weights=(angles * n[:, c : c + 1]).ravel(), minlength=len(vertices))
    with np.errstate(invalid="ignore", divide="ignore"):
        out /= np.linalg.norm(out, axis=1, keepdims=True)
    return out


def uv_table(mesh):
    """(V, 2) float64 texture coordinates, or None when the geometry has none."""
    if isinstance(mesh, VertexTables):
        return mesh.uv
    visual = getattr(mesh, "visual", None)
    uv = getattr(visual, "uv", None) if getattr(visual, "kind", None) == "texture" else None
    if uv is None:
        return None
    uv = np.asarray(uv, dtype=np.float64)
    return uv if uv.ndim == 2 and uv.shape[1] == 2 and len(uv) == len(mesh.vertices) else None


def vertex_normal_table(geometry):
    """(V, 3) float64 vertex normals of a :class:`~scatter_cli.surface.model.Geometry`: the
    file's when it has them, else :func:`weighted_vertex_normals` (trimesh's own needs
    SciPy, which the command line does not import, and without it takes time quadratic in
    the vertex count)."""
    mesh = geometry.mesh
    if isinstance(mesh, VertexTables):
        return mesh.vertex_normals
    if mesh is not None and "vertex_normals" in mesh._cache:  # trimesh keeps the file's normals there
        return np.asarray(mesh.vertex_normals, dtype=np.float64)
    return weighted_vertex_normals(geometry.vertices, geometry.faces)


def _placeholder(image):
    """trimesh's stand-in image for a material without a texture (a few pixels, made in memory;
    without Pillow, a wrapper of the ImportError, which any look at it raises)."""
    try:
        return getattr(image, "format", "x") is None and getattr(image, "size", (99, 99))[0] <= 2
    except ImportError:
        return True


class ColorSource:
    """How one geometry's colour is found at a point: ``colors(face, bary) -> (n, 4) float64``.

    kind: "vertex" (interpolated vertex colours), "face" (face colours), "texture"
    (texture at the interpolated UV times the material's base colour factor) or
    "constant" (a material colour without a texture). Values are in [0, 255].
    """

    def __init__(self, kind, faces, table=None, uv=None, texture=None, factor=None):
        self.kind = kind
        self.faces = faces
        self.table = table
        self.uv = uv
        self.texture = texture
        self.factor = None if factor is None else np.asarray(factor, dtype=np.float64).reshape(4)

    def prepare(self):
        """Decode what lookups need (call once, before any thread uses the source)."""
        if self.texture is not None:
            self.texture.pixels()

    def colors(self, face, bary):
        """face (n,) int64 local face index, bary (n, 3) -> (n, 4) float64 RGBA in [0, 255]."""
        n = len(face)
        if self.kind == "constant":
            return np.broadcast_to(self.factor, (n, 4))
        if self.kind == "face":
            return self.table[face].astype(np.float64)
        if self.kind == "vertex":
            return interpolate(self.table, self.faces, face, bary)
        c = self.texture.lookup(interpolate(self.uv, self.faces, face, bary))
        if self.factor is not None and not np.all(self.factor == 255):
            c *= self.factor / 255.0
        return c


def interpolate(table, faces, face, bary):
    """Barycentric blend of a per-vertex ``table`` (V, C) over ``faces[face]`` -> (n, C) float64."""
    corners = faces[face]
    out = table[corners[:, 0]] * bary[:, :1]
    out += table[corners[:, 1]] * bary[:, 1:2]
    out += table[corners[:, 2]] * bary[:, 2:3]
    return out


def color_source(mesh, faces, source="<mesh>", textures=None):
    """The :class:`ColorSource` of a geometry (trimesh or :class:`VertexTables`), or None
    when it has no colour."""
    if isinstance(mesh, VertexTables):
        return _table_color_source(mesh, faces)
    visual = getattr(mesh, "visual", None)
    kind = getattr(visual, "kind", None)
    if kind == "vertex":
        return ColorSource("vertex", faces, table=np.asarray(visual.vertex_colors, dtype=np.float64))
    if kind == "face":
        return ColorSource("face", faces, table=np.asarray(visual.face_colors, dtype=np.uint8))
    if kind != "texture":
        return None
    material = getattr(visual, "material", None)
    factor = _factor(material)
    image = getattr(material, "baseColorTexture", None) if hasattr(material, "baseColorTexture") else getattr(material, "image", None)
    uv = uv_table(mesh)
    if image is not None and not _placeholder(image) and uv is not None:
        return ColorSource("texture", faces, uv=uv, texture=_shared_texture(textures, image, REPEAT, REPEAT, source), factor=factor)
    if factor is not None:
        return ColorSource("constant", faces, factor=factor)
    return None


def _table_color_source(tables, faces):
    if tables.vertex_colors is not None:
        return ColorSource("vertex", faces, table=tables.vertex_colors)
    if tables.face_colors is not None:
        return ColorSource("face", faces, table=tables.face_colors)
    if tables.constant_color is not None:
        return ColorSource("constant", faces, factor=tables.constant_color)
    return None


def _shared_texture(textures, image, wrap_s, wrap_t, source):
    """One :class:`Texture` per image in ``textures`` (a dict the surface keeps), so
    geometries sharing an image decode it once."""
    if textures is None:
        return Texture(image, wrap_s, wrap_t, source)
    key = (id(image), wrap_s, wrap_t)
    tex = textures.get(key)
    if tex is None or tex.image is not image:
        tex = textures[key] = Texture(image, wrap_s, wrap_t, source)
    return tex


def _factor(material):
    """(4,) float64 RGBA 0..255 material colour, or None when the material sets none."""
    if material is None:
        return None
    if hasattr(material, "baseColorFactor"):
        f = material.baseColorFactor
        return None if f is None else _rgba(f)
    # A SimpleMaterial (OBJ/MTL) without an image has its Kd colour; trimesh's stand-in
    # material for "no material" carries a placeholder image and gives no colour.
    diffuse = getattr(material, "diffuse", None)
    if diffuse is not None and getattr(material, "image", None) is None:
        return _rgba(diffuse)
    return None


def _rgba(color):
    c = np.asarray(color, dtype=np.float64).ravel()
    if c.size == 3:
        c = np.append(c, 255.0)
    if c.max() <= 1.0 and np.asarray(color).dtype.kind == "f":
        c = c * 255.0
    return c[:4]
