"""A NumPy reader for GLB positions and indices, so a plain job need not import trimesh.

It gives what ``trimesh.load(path, process=False)`` gives for a GLB: one geometry per
mesh primitive, named as trimesh names them, placed by the scene's nodes in the order
trimesh's scene graph lists them, each with the world matrix trimesh computes for it
(the same NumPy operations in the same order, so the same bits). Anything it is not
sure of (Draco or any other primitive extension, sparse or bufferless accessors,
non-triangle modes, external buffers, cameras, a node with two parents, a malformed
field, ...) makes it return None, and the caller hands the file to trimesh, which also
words the error. The rules are in docs/loading.md.
"""

from __future__ import annotations

import json
import re
import struct
from collections import deque

import numpy as np

_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_INDEX_TYPES = (5121, 5123, 5125)
_TRIANGLES = 4
_BASE = "world"  # trimesh's base frame
_EYE = np.eye(4)
_EPS = np.finfo(float).eps * 4.0


class _Unsure(Exception):
    """Something the reader does not handle exactly as trimesh does: hand the file over."""


def read_glb(data, without_normals=False):
    """(geometries [(name, vertices (V, 3) float64, faces (F, 3) int64)], instances
    [(name, geometry index, (4, 4) float64 world matrix or None)]) of a GLB, or None.
    ``without_normals``: also None when a placed primitive has a NORMAL attribute."""
    try:
        doc, buffers = _chunks(data)
        return _Scene(doc, buffers).read(without_normals)
    except (_Unsure, ValueError, TypeError, KeyError, IndexError, AttributeError, OverflowError, RecursionError):
        return None


def _chunks(data):
    """The JSON document and the BIN chunks (memoryviews), read as trimesh's load_glb
    reads them."""
    if len(data) < 20:
        raise _Unsure
    magic, version, length, json_length, json_type = struct.unpack_from("<5I", data, 0)
    if magic != 0x46546C67 or version != 2 or json_type != 0x4E4F534A:
        raise _Unsure
    doc = json.loads(bytes(data[20 : 20 + json_length]).decode("utf-8"))
    if not isinstance(doc, dict):
        raise _Unsure
    if any(not isinstance(b, dict) or "uri" in b for b in _list(doc, "buffers")):
        raise _Unsure  # data in URIs: trimesh's resolver
    view = memoryview(data)
    start = pos = min(20 + json_length, len(data))
    buffers = []
    while pos - start < length:
        if len(data) - pos < 8:
            break
        size, kind = struct.unpack_from("<2I", data, pos)
        if len(data) - pos - 8 < size:
            raise _Unsure  # trimesh: "chunk was not expected length"
        if kind == 0x004E4942:
            buffers.append(view[pos + 8 : pos + 8 + size])
        pos += 8 + size
    return doc, buffers


def _list(doc, key):
    got = doc.get(key, [])
    if not isinstance(got, list):
        raise _Unsure
    return got


def _index(value, size):
    if type(value) is not int or not 0 <= value < size:
        raise _Unsure
    return value


def _numbers(value, n):
    if not isinstance(value, list) or len(value) != n or any(type(x) not in (int, float) for x in value):
        raise _Unsure
    return value


def _name(value):
    if not isinstance(value, str):
        raise _Unsure
    return value


class _Scene:
    def __init__(self, doc, buffers):
        self.doc, self.buffers = doc, buffers
        self.views = [self._view(v) for v in _list(doc, "bufferViews")]
        self.accessors = [self._accessor(a) for a in _list(doc, "accessors")]
        self.primitives = []  # per mesh: [(geometry name, POSITION, indices or None, has NORMAL)]
        used = {}
        counts = {}
        for mesh in _list(doc, "meshes"):
            if not isinstance(mesh["primitives"], list):
                raise _Unsure
            self.primitives.append([self._primitive(mesh, p, used, counts) for p in mesh["primitives"]])

    def _view(self, v):
        """(buffer memoryview, start, length) of a bufferView."""
        buffer = self.buffers[_index(v["buffer"], len(self.buffers))]
        start, length = v.get("byteOffset", 0), v["byteLength"]
        if type(start) is not int or type(length) is not int or start < 0 or length < 0:
            raise _Unsure
        if start + length > len(buffer):
            raise _Unsure  # trimesh asserts the length
        stride = v.get("byteStride")
        if stride is not None and (type(stride) is not int or stride <= 0):
            raise _Unsure
        return buffer, start, length, stride

    def _accessor(self, a):
        """(dtype, count, width, view index, byte offset), every field checked as trimesh
        would read it (it reads every accessor, used or not)."""
        if not isinstance(a, dict) or "sparse" in a or "bufferView" not in a:
            raise _Unsure
        dtype = np.dtype(_DTYPES[a["componentType"]])
        count, width = a["count"], _WIDTHS[a["type"]]
        view = _index(a["bufferView"], len(self.views))
        offset = a.get("byteOffset", 0)
        if type(count) is not int or type(offset) is not int or count <= 0 or offset < 0:
            raise _Unsure
        _, _, length, stride = self.views[view]
        row = width * dtype.itemsize
        end = offset + (count * row if stride is None else (count - 1) * stride + row)
        if end > length:
            raise _Unsure
        return dtype, count, width, view, offset

    def _primitive(self, mesh, p, used, counts):
        if not isinstance(p, dict) or p.get("extensions") or p.get("mode", _TRIANGLES) != _TRIANGLES:
            raise _Unsure  # Draco and other decoders; lines, points and strips
        attributes = p["attributes"]
        for k in attributes.values():  # trimesh reads NORMAL, COLOR_0, TEXCOORD_0 and `_` ones
            _index(k, len(self.accessors))
        position = attributes["POSITION"]
        dtype, count, width, _, _ = self.accessors[position]
        if dtype != np.float32 or width != 3:
            raise _Unsure
        indices = _index(p["indices"], len(self.accessors)) if "indices" in p else None
        if indices is None:
            if count % 3:
                raise _Unsure
        else:
            dtype, count, width, _, _ = self.accessors[indices]
            if dtype.kind != "u" or width != 1 or count % 3:
                raise _Unsure
        if "material" in p:
            _index(p["material"], len(_list(self.doc, "materials")))
            if "TEXCOORD_0" in attributes and self.accessors[attributes["TEXCOORD_0"]][2] < 2:
                raise _Unsure  # trimesh flips the second column
        name = unique_name(_name(mesh.get("name", "GLTF")), used, counts)
        used[name] = True
        return name, position, indices, "NORMAL" in attributes

    def _array(self, k):
        """Accessor k as an (count, width) array viewing the file."""
        dtype, count, width, view, offset = self.accessors[k]
        buffer, start, _, stride = self.views[view]
        if stride is None:
            return np.frombuffer(buffer, dtype, count * width, start + offset).reshape(count, width)
        raw = np.frombuffer(buffer, np.uint8, (count - 1) * stride + width * dtype.itemsize, start + offset)
        rows = np.lib.stride_tricks.as_strided(raw, (count, width * dtype.itemsize), (stride, 1))
        return np.ascontiguousarray(rows).view(dtype)

    def read(self, without_normals=False):
        edges = self._edges()
        geometries, index, instances = [], {}, []
        parent = {to: (frm, m) for frm, to, m, _ in edges}
        for frm, to, m, primitive in edges:
            if primitive is None:
                continue
            name, position, indices, normals = primitive
            if normals and without_normals:
                raise _Unsure  # trimesh keeps the file's normals
            if name not in index:
                index[name] = len(geometries)
                vertices = self._array(position).astype(np.float64)
                if indices is None:
                    faces = np.arange(len(vertices), dtype=np.int64).reshape(-1, 3)
                else:
                    faces = self._array(indices).astype(np.int64).reshape(-1, 3)
                geometries.append((name, vertices, faces))
            matrix = _world(to, parent)
            instances.append((to, index[name], None if np.array_equal(matrix, _EYE) else matrix))
        if not instances:
            raise _Unsure
        return geometries, instances

    def _edges(self):
        """The scene graph's edges (parent frame, frame, matrix, primitive or None) in the
        order trimesh's loader makes them: a depth-first walk popping the last queued edge.
        Geometry frames come in this order in trimesh's nodes_geometry."""
        nodes = _list(self.doc, "nodes")
        names, counts = {}, {}
        for i, n in enumerate(nodes):
            if not isinstance(n, dict) or "camera" in n:
                raise _Unsure
            name = unique_name(_name(n.get("name", str(i))), names, counts)
            names[name] = i
        frames = {i: name for name, i in names.items()}
        if _BASE in names:
            raise _Unsure
        scenes = self.doc["scenes"]
        scene = scenes[_index(self.doc.get("scene", 0), len(scenes))]
        queue = deque((None, _index(root, len(nodes))) for root in _list(scene, "nodes"))
        seen, edges = set(), []
        while queue:
            a, b = queue.pop()
            if b in seen:
                raise _Unsure  # a node placed twice, or a cycle
            seen.add(b)
            child = nodes[b]
            queue.extend((b, _index(i, len(nodes))) for i in _list(child, "children"))
            frm = _BASE if a is None else frames[a]
            matrix = _node_matrix(child)
            if "mesh" not in child:
                edges.append((frm, frames[b], matrix, None))
                continue
            prims = self.primitives[_index(child["mesh"], len(self.primitives))]
            if len(prims) == 1:
                edges.append((frm, frames[b], matrix, prims[0]))
            elif prims:  # the node, then one identity child per primitive
                edges.append((frm, frames[b], matrix, None))
                for k, p in enumerate(prims):
                    frame = primitive_frame(frames[b], k)
                    if frame in names:
                        raise _Unsure
                    edges.append((frames[b], frame, _EYE, p))
            else:
                raise _Unsure
        return edges


def _node_matrix(node):
    """A node's local matrix as trimesh's loader composes it: matrix, then T, R, S."""
    if "matrix" in node:
        m = np.array(_numbers(node["matrix"], 16), dtype=np.float64).reshape((4, 4)).T
    else:
        m = _EYE
    if "translation" in node:
        t = np.eye(4)
        t[:3, 3] = _numbers(node["translation"], 3)
        m = np.dot(m, t)
    if "rotation" in node:
        m = np.dot(m, _quaternion_matrix(np.reshape(_numbers(node["rotation"], 4), 4)[[3, 0, 1, 2]]))
    if "scale" in node:
        m = np.dot(m, np.diag(np.concatenate((_numbers(node["scale"], 3), [1.0]))))
    return np.array(m, dtype=np.float64)


def _quaternion_matrix(quaternion):
    """trimesh.transformations.quaternion_matrix for one (w, x, y, z) quaternion."""
    q = np.array(quaternion, dtype=np.float64).reshape((-1, 4))
    n = np.dot(q * q, [1.0] * 4)
    identities = n < _EPS
    q[~identities, :] *= np.sqrt(2.0 / n[~identities, None])
    q = q[:, None, :] * q[:, :, None]
    ret = np.zeros((1, 4, 4))
    ret[:, 0, 0] = 1.0 - q[:, 2, 2] - q[:, 3, 3]
    ret[:, 0, 1] = q[:, 1, 2] - q[:, 3, 0]
    ret[:, 0, 2] = q[:, 1, 3] + q[:, 2, 0]
    ret[:, 1, 0] = q[:, 1, 2] + q[:, 3, 0]
    ret[:, 1, 1] = 1.0 - q[:, 1, 1] - q[:, 3, 3]
    ret[:, 1, 2] = q[:, 2, 3] - q[:, 1, 0]
    ret[:, 2, 0] = q[:, 1, 3] - q[:, 2, 0]
    ret[:, 2, 1] = q[:, 2, 3] + q[:, 1, 0]
    ret[:, 2, 2] = 1.0 - q[:, 1, 1] - q[:, 2, 2]
    ret[:, 3, 3] = 1.0
    ret[identities] = np.eye(4)[None, ...]
    return ret.squeeze()


def _world(frame, parent):
    """The world matrix of ``frame`` as trimesh's SceneGraph.get computes it: the edge's
    own matrix for a child of the base frame, else the product of the path's matrices
    that are not within 1e-8 of identity; then its rigid repair."""
    frm, matrix = parent[frame]
    if frm != _BASE:
        chain = [matrix]
        while frm != _BASE:
            frm, m = parent[frm]
            chain.append(m)
        chain = [m for m in reversed(chain) if np.abs(m - _EYE).max() > 1e-8]
        if not chain:
            matrix = _EYE
        elif len(chain) == 1:
            matrix = chain[0]
        else:
            matrix = np.linalg.multi_dot(chain)
    return _fix_rigid(matrix)


def _fix_rigid(matrix, max_deviance=1e-5):
    """trimesh.transformations.fix_rigid: a nearly rigid matrix restored by SVD."""
    check = np.abs(np.dot(matrix[:3, :3], matrix[:3, :3].T) - _EYE[:3, :3]).max()
    if 1e-13 < check < max_deviance:
        u, _, v = np.linalg.svd(matrix[:3, :3])
        repaired = np.eye(4)
        repaired[:3, :3] = np.dot(u, v)
        repaired[:3, 3] = matrix[:3, 3]
        if not np.allclose(repaired, matrix, atol=max_deviance):
            raise _Unsure  # trimesh's assertion fails
        return repaired
    return matrix


def primitive_frame(node, k):
    """The frame of primitive ``k`` of the node named ``node`` whose mesh has several
    primitives: named by its place in the file. (trimesh names it ``node_`` and six
    random hex digits, another name on every load.)"""
    return f"{node}_{k}"


_TRIMESH_SUFFIX = re.compile(r"_[0-9a-f]{6}")  # what trimesh appends to a primitive's frame


def primitive_frames(graph) -> dict:
    """{frame: name} for the primitive frames of a glTF scene that trimesh loaded
    (``graph``: its SceneGraph), named as this reader names them (:func:`primitive_frame`):
    the children trimesh hangs under a node without geometry, one per primitive of the
    node's mesh, numbered in the order it placed them."""
    data = graph.transforms.node_data
    taken, counts, renamed = set(data), {}, {}
    for node, children in graph.transforms.children.items():
        if "geometry" in data.get(node, {}):
            continue
        frames = [c for c in children if c.startswith(node) and _TRIMESH_SUFFIX.fullmatch(c[len(node):])
                  and "geometry" in data[c]]
        for k, frame in enumerate(frames):
            renamed[frame] = unique_name(primitive_frame(node, k), taken, counts)
            taken.add(renamed[frame])
    return renamed


def unique_name(start, contains, counts):
    """trimesh.util.unique_name: ``start``, or ``start_N`` with the next free N."""
    if start and start not in contains:
        return start
    increment = counts.get(start, 0)
    if start:
        formatter = start + "_{}"
        split = start.rsplit("_", 1)
        if len(split) == 2 and increment == 0:
            try:
                increment = int(split[1])
                formatter = split[0] + "_{}"
            except ValueError:
                pass
    else:
        formatter = "geometry_{}"
    for i in range(increment + 1, 2 + increment + len(contains)):
        check = formatter.format(i)
        if check not in contains:
            counts[start] = i
            return check
    raise _Unsure
