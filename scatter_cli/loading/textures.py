"""The textures a mesh file names, found without decoding them.

Pillow decodes textures, and without it trimesh loads a textured mesh as if it had none.
So when Pillow is missing, a job that needs a texture (``-a color``, ``--weight
texture:``) and ``scatter info`` look in the file itself for the images it names: a
glTF's ``images``, the ``map_Kd`` maps of an OBJ's material libraries.
"""

from __future__ import annotations

import json
import os
import re
import struct

from ..errors import ScatterError

INSTALL = "pip install pillow"
_MTLLIB = re.compile(rb"^[ \t]*mtllib[ \t]+(\S[^\r\n]*)", re.MULTILINE)
_MAP_KD = re.compile(rb"^[ \t]*map_Kd[ \t]+(\S[^\r\n]*)", re.MULTILINE | re.IGNORECASE)


def pillow_missing() -> bool:
    try:
        import PIL  # noqa: F401
    except ImportError:
        return True
    return False


def named_textures(path) -> list:
    """The names of the texture images the mesh file at ``path`` names (its glTF
    images, its OBJ's map_Kd files); [] for other files and for files that cannot be read."""
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    try:
        if suffix in (".glb", ".gltf"):
            return _gltf_images(path)
        if suffix == ".obj":
            return _obj_maps(path)
    except (OSError, ValueError, struct.error):
        return []
    return []


def require_pillow(source) -> None:
    """A ScatterError, when Pillow is missing and the mesh file ``source`` names a
    texture: the job cannot read it (else trimesh would drop it without a word)."""
    if not isinstance(source, (str, os.PathLike)) or not pillow_missing():
        return
    names = named_textures(source)
    if names:
        raise ScatterError(f"{source}: reading its texture ({names[0]}) needs Pillow: {INSTALL}")


def _gltf_images(path) -> list:
    with open(path, "rb") as f:
        head = f.read(20)
        if head[:4] == b"glTF":
            length = struct.unpack_from("<I", head, 12)[0]
            doc = json.loads(f.read(length))
        else:
            doc = json.loads(head + f.read())
    images = doc.get("images", []) if isinstance(doc, dict) else []
    return [str(image.get("name") or image.get("uri") or f"image {k}") if isinstance(image, dict) else f"image {k}"
            for k, image in enumerate(images if isinstance(images, list) else [])]


def _obj_maps(path) -> list:
    with open(path, "rb") as f:
        libraries = [m.group(1).decode("utf-8", "replace").strip() for m in _MTLLIB.finditer(f.read())]
    folder = os.path.dirname(os.path.abspath(path))
    maps = []
    for name in libraries:
        try:
            with open(os.path.join(folder, name), "rb") as f:
                maps += [m.group(1).decode("utf-8", "replace").split()[-1] for m in _MAP_KD.finditer(f.read())]
        except OSError:
            continue  # a library that is not there: trimesh's loader words that
    return maps
