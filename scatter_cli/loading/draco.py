"""glTF meshes compressed with Draco (``KHR_draco_mesh_compression``).

trimesh (5.2 or later) decodes them with DracoPy: both come with the optional extra
``draco``. Without them trimesh loads placeholder zeros and the run fails with a
misleading "no area": so the glTF's JSON is looked at first (a substring test, then a
parse only when the name occurs) and a file that needs the decoder gets one line saying
what to install.
"""

from __future__ import annotations

import io
import json
import struct

from ..errors import ScatterError

EXTENSION = "KHR_draco_mesh_compression"
INSTALL_HINT = "pip install DracoPy"


def check_decoder(name, file_type, file_obj):
    """Raise ScatterError when the glTF/GLB ``file_obj`` (a path or a BytesIO) has
    Draco-compressed meshes and DracoPy cannot be imported."""
    text = gltf_json(file_obj, file_type)
    if text is None or EXTENSION.encode() not in text or not needs_decoder(text):
        return
    what = f"{name}: the glTF has Draco-compressed meshes ({EXTENSION}); reading them needs"
    try:
        import DracoPy  # noqa: F401
    except ImportError:
        raise ScatterError(f"{what} DracoPy: {INSTALL_HINT}") from None
    if not _trimesh_decodes():
        import trimesh

        raise ScatterError(f"{what} trimesh 5.2 or later (installed: {trimesh.__version__}): {INSTALL_HINT}")


def _trimesh_decodes() -> bool:
    """Whether the installed trimesh has a Draco handler for its glTF loader."""
    try:
        from trimesh.exchange.gltf import extensions
    except ImportError:
        return False
    return EXTENSION in getattr(extensions, "_handlers", {}).get("primitive_preprocess", {})


def gltf_json(file_obj, file_type):
    """The JSON bytes of a glTF (the whole file) or GLB (its first chunk), or None."""
    if isinstance(file_obj, io.BytesIO):
        data = file_obj.getbuffer()
        return bytes(data if file_type == "gltf" else _glb_json(data))
    with open(file_obj, "rb") as f:
        if file_type == "gltf":
            return f.read()
        head = f.read(20)
        if len(head) < 20 or head[:4] != b"glTF" or head[16:20] != b"JSON":
            return None
        return f.read(struct.unpack_from("<I", head, 12)[0])


def _glb_json(data):
    if len(data) < 20 or bytes(data[:4]) != b"glTF" or bytes(data[16:20]) != b"JSON":
        return b""
    size = struct.unpack_from("<I", data, 12)[0]
    return data[20 : 20 + size]


def needs_decoder(text) -> bool:
    """Whether a primitive is Draco-compressed without an uncompressed fallback (its
    POSITION accessor has no bufferView of its own)."""
    try:
        doc = json.loads(text)
        accessors = doc.get("accessors", [])
        for mesh in doc.get("meshes", []):
            for prim in mesh.get("primitives", []):
                if EXTENSION in (prim.get("extensions") or {}):
                    position = accessors[prim["attributes"]["POSITION"]]
                    if "bufferView" not in position:
                        return True
    except (ValueError, TypeError, KeyError, IndexError, AttributeError):
        return False  # malformed JSON: trimesh's own error says what is wrong
    return False
