"""Loading a surface: a mesh file, standard input, a trimesh object or scene -> a Surface.

One table, :data:`LOADERS` (the rows of :mod:`.formats` with the functions they name),
says per input format how it is read: the fast reader for plain jobs (fast.py: vertices
and faces without trimesh), the loader that reads it whole (trimesh, or usd.py for USD
stages), and what the format fixes of the scene's units. A format trimesh knows but the
table does not name is read by trimesh. What a
loader has to say about a file (USD's diagnostics, geometry it did not keep) comes back
on the surface it returns: ``surface.warnings`` and ``surface.unsampled``.
"""

from __future__ import annotations

import io
import logging
import os
import sys
from dataclasses import dataclass
from typing import Callable

import numpy as np

from . import fast as readers
from ..errors import ScatterError, ScatterUsageError
from . import ply
from .formats import INPUT_FORMATS, STDIN_FORMATS, TABLE
from .sourcefile import check_readable, stream_bytes
from ..surface.model import Geometry, Instance, Surface, Unsampled, select_objects

GLTF_FORMATS = ("glb", "gltf")

# Called before trimesh is first imported, when set: the command line imports it with
# SciPy hidden (lean_trimesh). Nothing imports trimesh before a mesh needs it.
import_trimesh = None


def import_trimesh_lean():
    """Import trimesh with SciPy hidden: trimesh imports SciPy eagerly when it is installed
    (0.4 s or more on every call) only for features that loading and sampling never use.
    Only the command line does this; the Python API leaves the user's trimesh alone.
    """
    if "trimesh" in sys.modules or "scipy" in sys.modules:
        return
    sys.modules["scipy"] = None  # makes `import scipy` raise ImportError
    try:
        import trimesh  # noqa: F401
    except Exception:
        pass  # a broken trimesh is reported where the mesh is loaded
    finally:
        del sys.modules["scipy"]


def lean_trimesh():
    """Have the mesh loader import trimesh without SciPy, when a mesh needs it (not before)."""
    global import_trimesh
    import_trimesh = import_trimesh_lean


@dataclass(frozen=True)
class Job:
    """What is asked of a loader: the file (``path``, ``-`` for standard input; ``name``
    as messages call it), its format, the objects to keep and the tables wanted (see
    :func:`load_surface`)."""

    path: str
    name: str
    format: str
    objects: tuple | None
    plain: bool
    smooth: bool
    color: bool
    uv: bool


@dataclass(frozen=True)
class Loader:
    """How one input format is read.

    ``fast``: a fast.py function for plain jobs on files (None: none), given the bytes;
    ``full``: reads any job of the format -> Surface; ``units``: the (up axis, metres per
    unit) the format fixes by its specification, None where it says nothing.
    """

    full: Callable[[Job], Surface]
    fast: Callable | None = None
    units: tuple | None = None


def load_surface(source, *, input_format: str | None = None, objects=None, plain=False, smooth=False,
                 color=False, uv=False) -> Surface:
    """Load ``source`` (path, ``'-'`` for standard input, trimesh.Trimesh or trimesh.Scene;
    a Surface is taken as it is).

    ``plain``: only vertices and faces are wanted (no colours, UVs or normals from the
    file), so the fast readers (fast.py) may read it without importing trimesh.
    ``smooth``: smooth vertex normals are wanted too; the fast readers then read a
    PLY's own normals and otherwise only files without normals or UVs of their own (the
    normals are computed from the faces, as for trimesh's mesh of such a file).
    ``color``: vertex colours are wanted too; the fast readers then read only PLY.
    ``uv``: texture coordinates are wanted too; the fast readers then read only OBJ.

    The surface's ``warnings`` (lines naming the file) are for the caller to print.
    """
    if isinstance(source, Surface):
        return _finished(source, source.source, objects)
    if not isinstance(source, (str, os.PathLike)):
        return _finished(_from_trimesh(source, "<mesh>"), "<mesh>", objects)
    path = os.fspath(source)
    kind = (input_format or os.path.splitext(path)[1].lstrip(".")).lower()
    job = Job(path, "<stdin>" if path == "-" else path, kind, tuple(objects) if objects else None, plain,
              smooth, color, uv)
    loader = LOADERS.get(kind, TRIMESH)
    surface = None
    if loader.fast is not None and plain and not objects and path != "-":
        surface = _read_fast(job, loader.fast)
    if surface is None:
        surface = loader.full(job)
    if loader.units is not None:
        surface.up_axis, surface.meters_per_unit = loader.units
    return surface


def _finished(surface, name, objects):
    if objects:
        surface = select_objects(surface, objects)
    if surface.face_count == 0:
        raise ScatterError(f"{name}: the mesh has no faces")
    return surface


# -- the fast readers ----------------------------------------------------------------------


def _read_fast(job, read):
    """The Surface of a mesh file read by a fast reader, or None (read it whole).

    One geometry makes a mesh, several a scene, as trimesh.load makes them; the names
    follow trimesh's for an OBJ split by material (file name, then name_1, name_2...).
    """
    if check_readable(job.path):
        return None  # a pipe: read once, whole
    parts = readers.read_file(job.path, read, job.smooth, job.color, job.uv)
    if parts is None:
        return None
    tables = [p[2] if len(p) > 2 else {} for p in parts] if isinstance(parts, list) else None
    surface = _plain_surface(job.path, parts if tables is None else [p[:2] for p in parts])
    if job.smooth or job.color or job.uv:
        from ..surface.data import VertexTables

        for g, t in zip(surface.geometries, tables or [{}] * len(surface.geometries)):
            g.mesh = VertexTables(g.vertices, g.faces, **t)  # normals computed from the faces unless given
    return surface


def _plain_surface(path, parts):
    if isinstance(parts, tuple):  # a GLB scene
        geometries = [checked_geometry(n, v, f, path) for n, v, f in parts[0]]
        surface = Surface(geometries, [Instance(*i) for i in parts[1]], path, is_scene=True)
    elif len(parts) == 1:
        surface = Surface([checked_geometry(path, *parts[0], path)], [Instance(os.path.basename(path), 0)], path)
    else:
        base = os.path.basename(path)
        names = [base] + [f"{base}_{k}" for k in range(1, len(parts))]
        geometries = [checked_geometry(n, *arrays, path) for n, arrays in zip(names, parts)]
        surface = Surface(geometries, [Instance(n, k) for k, n in enumerate(names)], path, is_scene=True)
    if surface.face_count == 0:
        raise ScatterError(f"{path}: the mesh has no faces")
    return surface


# -- trimesh -------------------------------------------------------------------------------


def _trimesh_surface(job):
    """Any format trimesh loads, read whole (attributes, materials, scene graph); the
    frames trimesh names at random in a glTF scene renamed by their place in the file."""
    loaded = _trimesh_file(job)
    frames = None
    if job.format in GLTF_FORMATS and hasattr(loaded, "graph"):
        from .gltf import primitive_frames

        frames = primitive_frames(loaded.graph)
    return _finished(_from_trimesh(loaded, job.name, frames), job.name, job.objects)


def _obj_surface(job):
    """An OBJ through trimesh; with colours asked for, a material library it names that is
    not there is named, as it is the reason the colours are missing."""
    surface = _trimesh_surface(job)
    if job.color and job.path != "-":
        missing = readers.missing_material_library(job.path)
        if missing and not any(_has_vertex_colors(g.mesh) for g in surface.geometries):
            raise ScatterError(f"{job.name}: cannot write attribute 'color': its material library "
                               f"'{missing}' is not there (looked for beside the file)")
    return surface


def _has_vertex_colors(mesh):
    return getattr(getattr(mesh, "visual", None), "kind", None) == "vertex"


def _import_trimesh():
    if import_trimesh is not None and "trimesh" not in sys.modules:
        import_trimesh()
    import trimesh

    logging.getLogger("trimesh").setLevel(logging.ERROR)
    return trimesh


def _trimesh_file(job):
    """What trimesh.load makes of the job's file or stream (a Trimesh, a Scene...)."""
    trimesh = _import_trimesh()
    path, file_type = job.path, job.format
    if path == "-":
        if not file_type:
            raise ScatterUsageError(f"reading a mesh from standard input needs --input-format "
                                    f"({', '.join(STDIN_FORMATS)})")
        file_obj = io.BytesIO(stream_bytes(path, "<stdin>: no data on standard input"))
    else:
        stream = check_readable(path)
        if not file_type:
            pipe = "a pipe has " if stream else ""
            raise ScatterUsageError(f"{path}: {pipe}no file suffix to tell the format; pass --input-format")
        file_obj = path
        if stream:  # a pipe, e.g. `scatter sample <(gunzip -c mesh.ply.gz)`: read it once
            file_obj = io.BytesIO(stream_bytes(path, f"{path}: no data in the pipe"))
    if file_type not in trimesh.available_formats():
        raise ScatterUsageError(f"{path}: unknown mesh format '{file_type}' (try one of: {', '.join(INPUT_FORMATS)})")
    if file_type in GLTF_FORMATS:
        from .draco import check_decoder

        file_type = _gltf_kind(file_obj, file_type)
        check_decoder(path, file_type, file_obj)
        if file_type == "gltf" and isinstance(file_obj, io.BytesIO):
            _check_self_contained(job.name, file_obj)
    if file_type == "ply":
        _check_whole_ply(file_obj, path)
    try:
        with np.errstate(all="ignore"):
            return trimesh.load(file_obj, file_type=file_type, process=False)
    except MemoryError:
        raise ScatterError(f"{path}: out of memory while reading the mesh") from None
    except Exception as exc:  # trimesh raises many kinds on malformed input
        # A PLY header that is not one: said as merge and preview say it (one parser).
        malformed = file_type == "ply" and ply.header_error(_head(file_obj, ply.MAX_HEADER))
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ScatterError(f"{path}: {malformed or f'not a readable {file_type.upper()} mesh ({reason[:200]})'}") from None


def _check_whole_ply(file_obj, path):
    """A PLY that ends before the rows its header declares is an error saying where it
    ends (trimesh reads a short ASCII body without a word)."""
    if isinstance(file_obj, io.BytesIO):
        problem = ply.truncation(file_obj.getbuffer())
    else:
        with ply.contents(file_obj) as data:
            problem = None if data is None else ply.truncation(data)
    if problem:
        raise ScatterError(f"{path}: {problem}")


def _head(file_obj, size):
    """The first ``size`` bytes of ``file_obj``, a path or a BytesIO."""
    if isinstance(file_obj, io.BytesIO):
        return file_obj.getbuffer()[:size].tobytes()
    with open(file_obj, "rb") as f:
        return f.read(size)


def _gltf_kind(file_obj, file_type):
    """What the bytes are, whatever the suffix or --input-format said: "glb" when they
    start with the binary glTF magic, "gltf" when with a JSON object; else ``file_type``."""
    head = _head(file_obj, 64)
    if head[:4] == b"glTF":
        return "glb"
    return "gltf" if head.lstrip(b" \t\r\n\xef\xbb\xbf").startswith(b"{") else file_type


def _check_self_contained(name, file_obj):
    """A glTF read from a stream has no folder: refuse one whose buffers are files."""
    import json

    from .draco import gltf_json

    try:
        doc = json.loads(gltf_json(file_obj, "gltf") or b"{}")
        uris = [b.get("uri") for b in doc.get("buffers", [])]
    except (ValueError, AttributeError, TypeError):
        return  # not JSON: trimesh words the error
    outside = [u for u in uris if isinstance(u, str) and not u.startswith("data:")]
    if outside:
        raise ScatterError(f"{name}: the glTF's buffers are files beside it ({', '.join(outside[:3])}), which "
                           "standard input cannot carry: pass the .gltf's path, or a .glb")


def _from_trimesh(loaded, name, frames=None) -> Surface:
    """The Surface of a trimesh object; ``frames``: {frame: name} renaming scene nodes."""
    trimesh = _import_trimesh()
    if isinstance(loaded, trimesh.Trimesh):
        return Surface([_geometry(name, loaded, name)], [Instance(os.path.basename(name), 0)], name)
    if isinstance(loaded, trimesh.Scene):
        return _from_scene(loaded, name, frames or {})
    raise ScatterError(f"{name}: not a surface mesh (trimesh loaded a {type(loaded).__name__})")


def _geometry(name, mesh, source) -> Geometry:
    try:  # trimesh builds some arrays lazily: a malformed file can fail only here
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
    except (ValueError, TypeError, IndexError, OverflowError) as exc:
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ScatterError(f"{source}: malformed geometry '{name}' ({reason[:200]})") from None
    return checked_geometry(name, vertices, faces, source, mesh)


def checked_geometry(name, vertices, faces, source, mesh=None) -> Geometry:
    """A Geometry of ``vertices`` (V, 3) and ``faces`` (F, 3), after checking both shapes
    and that every index is a vertex (ScatterError naming ``source`` otherwise)."""
    if vertices.size == 0:
        vertices = vertices.reshape(0, 3)
    if faces.size == 0:
        faces = faces.reshape(0, 3)
    # Never reshape blindly: (V, 2) vertices read as (V * 2 / 3, 3) would be wrong points.
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise ScatterError(f"{source}: malformed geometry '{name}' (vertices {vertices.shape}, faces {faces.shape})")
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ScatterError(f"{source}: face indices out of range in geometry '{name}'")
    return Geometry(name, vertices, faces, mesh)


def _from_scene(scene, source, frames) -> Surface:
    import trimesh

    geometries, index, instances, unsampled = [], {}, [], []
    for node in scene.graph.nodes_geometry:
        name = frames.get(node, str(node))
        try:
            matrix, geom_name = scene.graph[node]
        except (ValueError, KeyError, AssertionError) as exc:  # a graph trimesh cannot walk, e.g. a cycle
            raise ScatterError(f"{source}: malformed scene graph at node '{node}' ({str(exc).strip()[:200]})") from None
        mesh = scene.geometry.get(geom_name)
        if not isinstance(mesh, trimesh.Trimesh):  # points, lines: no surface
            unsampled.append(Unsampled(name, f"a {type(mesh).__name__}, not a mesh"))
            continue
        if geom_name not in index:
            index[geom_name] = len(geometries)
            geometries.append(_geometry(geom_name, mesh, source))
        matrix = np.asarray(matrix, dtype=np.float64)
        instances.append(Instance(name, index[geom_name], None if np.array_equal(matrix, np.eye(4)) else matrix))
    return Surface(geometries, instances, source, is_scene=True, unsampled=unsampled)


# -- USD -----------------------------------------------------------------------------------


def _usd_surface(job):
    from .usd import load_usd

    # smooth normals: a stage's own (primvars:normals, normals) when it has them
    plain = job.plain and not (job.smooth or job.color or job.uv)
    return load_usd(job.path, job.format or None, objects=job.objects, plain=plain)


# -- the table -----------------------------------------------------------------------------

TRIMESH = Loader(_trimesh_surface)
FULL = {"trimesh": _trimesh_surface, "obj": _obj_surface, "usd": _usd_surface}  # the table's `full` names

LOADERS: dict[str, Loader] = {
    f.name: Loader(FULL[f.full], getattr(readers, f.fast) if f.fast else None, f.units) for f in TABLE
}
