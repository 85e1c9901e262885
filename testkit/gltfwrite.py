"""A minimal GLB writer for tests: meshes (positions and indices), nodes placing them, and
optionally the meshes compressed with DracoPy (``KHR_draco_mesh_compression``).

Written here rather than by trimesh's exporter so that the reader is checked against
files it did not make itself.
"""

import json
import struct

import numpy as np

DRACO = "KHR_draco_mesh_compression"


def glb_bytes(meshes, nodes, *, draco=False, quantization_bits=14, preserve_order=True):
    """meshes: [(vertices (V, 3), faces (F, 3))]; nodes: [(mesh index, (4, 4) matrix or None)]
    with matrices acting on column vectors. Returns the bytes of a GLB file."""
    blob, views, accessors, gltf_meshes = bytearray(), [], [], []

    def view(data):
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
        blob.extend(data)
        return len(views) - 1

    for vertices, faces in meshes:
        v = np.ascontiguousarray(vertices, dtype=np.float32)
        f = np.ascontiguousarray(faces, dtype=np.uint32)
        pos = {"componentType": 5126, "count": len(v), "type": "VEC3",
               "min": v.min(0).tolist(), "max": v.max(0).tolist()}
        idx = {"componentType": 5125, "count": f.size, "type": "SCALAR"}
        primitive = {"attributes": {"POSITION": len(accessors)}, "indices": len(accessors) + 1, "mode": 4}
        if draco:
            import DracoPy

            data = DracoPy.encode(v, f, quantization_bits=quantization_bits, preserve_order=preserve_order)
            decoded = DracoPy.decode(data)
            pid = next(a["unique_id"] for a in decoded.attributes
                       if a["attribute_type"] == DracoPy.AttributeType.POSITION)
            pos["count"], idx["count"] = len(decoded.points), np.asarray(decoded.faces).size
            primitive["extensions"] = {DRACO: {"bufferView": view(data), "attributes": {"POSITION": pid}}}
        else:
            pos["bufferView"] = view(v.tobytes())
            idx["bufferView"] = view(f.tobytes())
        accessors += [pos, idx]
        gltf_meshes.append({"primitives": [primitive]})
    gltf_nodes = []
    for k, (mesh, matrix) in enumerate(nodes):
        node = {"mesh": mesh, "name": f"node{k}"}
        if matrix is not None:
            node["matrix"] = np.asarray(matrix, dtype=np.float64).T.ravel().tolist()  # column-major
        gltf_nodes.append(node)
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": list(range(len(nodes)))}],
           "nodes": gltf_nodes, "meshes": gltf_meshes, "accessors": accessors, "bufferViews": views,
           "buffers": [{"byteLength": len(blob)}]}
    if draco:
        doc["extensionsUsed"] = doc["extensionsRequired"] = [DRACO]
    return pack_glb(doc, bytes(blob))


class GLB:
    """A GLB built field by field, for the fast reader's tests: ``add`` puts an array in
    the binary chunk (optionally interleaved behind ``pad`` bytes per row, so the view
    has a byteStride) and returns its accessor's index; ``doc`` is the JSON to complete."""

    def __init__(self):
        self.blob = bytearray()
        self.doc = {"asset": {"version": "2.0"}, "bufferViews": [], "accessors": [], "buffers": [{}]}

    def add(self, array, component, kind, pad=0):
        a = np.ascontiguousarray(array)
        rows = a.reshape(len(a), -1).view(np.uint8).reshape(len(a), -1)
        while len(self.blob) % 4:
            self.blob.append(0)
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(a) * (rows.shape[1] + pad)}
        if pad:
            view["byteStride"] = rows.shape[1] + pad
            rows = np.hstack([rows, np.full((len(a), pad), 0xAB, dtype=np.uint8)])
        self.blob.extend(rows.tobytes())
        self.doc["bufferViews"].append(view)
        self.doc["accessors"].append({"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": component,
                                      "count": len(a), "type": kind})
        return len(self.doc["accessors"]) - 1

    def primitive(self, vertices, faces=None, index_component=5125, pad=0):
        prim = {"attributes": {"POSITION": self.add(np.asarray(vertices, dtype="<f4"), 5126, "VEC3", pad)}}
        if faces is not None:
            dtype = {5121: "<u1", 5123: "<u2", 5125: "<u4"}[index_component]
            prim["indices"] = self.add(np.asarray(faces, dtype=dtype).ravel(), index_component, "SCALAR")
        return prim

    def bytes(self):
        self.doc["buffers"][0]["byteLength"] = len(self.blob)
        return pack_glb(self.doc, bytes(self.blob))


def pack_glb(doc, blob):
    """A GLB file of JSON ``doc`` and one binary chunk ``blob``."""
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob = blob + b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(text), b"JSON") + text
            + struct.pack("<I4s", len(blob), b"BIN\0") + blob)
