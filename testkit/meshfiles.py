"""Mesh files written by hand, for the readers' tests and benchmarks/attribute_loading.py:
PLY with any vertex columns, OBJ whose UV and normal references split vertices."""

import numpy as np

PLY_NAMES = {"f4": "float", "f8": "double", "u1": "uchar", "i1": "char", "u2": "ushort", "i2": "short",
             "i4": "int", "u4": "uint"}


def write_ply(path, columns, faces, fmt="ascii"):
    """A PLY of vertex ``columns`` [(name, NumPy type, (V,) values)] and ``faces`` (a list
    of index lists, any sizes for ASCII; triangles for binary), in ``fmt``: ascii,
    binary_little_endian or binary_big_endian."""
    n = len(columns[0][2])
    head = ["ply", f"format {fmt} 1.0", f"element vertex {n}"]
    head += [f"property {PLY_NAMES[t]} {name}" for name, t, _ in columns]
    head += [f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(head) + "\n").encode())
        if fmt == "ascii":
            cells = [[repr(float(x)) if t[0] == "f" else str(int(x)) for x in np.asarray(v, dtype=t)]
                     for _, t, v in columns]
            rows = [" ".join(r) for r in zip(*cells)] + [" ".join(map(str, [len(q), *q])) for q in faces]
            f.write(("\n".join(rows) + "\n").encode())
        else:
            order = "<" if fmt == "binary_little_endian" else ">"
            rec = np.zeros(n, dtype=[(name, order + t) for name, t, _ in columns])
            for name, _, values in columns:
                rec[name] = values
            frec = np.zeros(len(faces), dtype=[("n", "u1"), ("i", order + "i4", 3)])
            frec["n"], frec["i"] = 3, faces
            f.write(rec.tobytes() + frec.tobytes())
    return path


def obj_text(vertices, faces, form, seed=0, negative=False):
    """An OBJ of ``vertices`` and ``faces`` (index lists) whose vt and vn refs are drawn
    so that a vertex meets several UVs and normals (a split) and triples repeat."""
    rng = np.random.default_rng(seed)
    nt, nn = len(vertices) // 2 + 3, len(vertices) // 3 + 2
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, dtype=float).tolist()]
    if "vt" in form:
        lines += [f"vt {u!r} {v!r}" for u, v in rng.random((nt, 2)).tolist()]
    if "vn" in form:
        lines += [f"vn {a!r} {b!r} {c!r}" for a, b, c in rng.normal(size=(nn, 3)).tolist()]
    flat = np.concatenate([np.asarray(q) for q in faces])
    coin = rng.integers(0, 2, (2, len(flat)))
    refs = np.stack([flat, (flat * 7 + coin[0]) % nt, (flat * 5 + coin[1]) % nn])
    refs += np.array([[len(vertices)], [nt], [nn]]) * -1 if negative else 1
    pattern = {"v/vt/vn": "{0}/{1}/{2}", "v/vt": "{0}/{1}", "v//vn": "{0}//{2}"}[form]
    words = [pattern.format(*r) for r in refs.T.tolist()]
    at = np.cumsum([0] + [len(q) for q in faces]).tolist()
    lines += ["f " + " ".join(words[a:b]) for a, b in zip(at[:-1], at[1:])]
    return "\n".join(lines) + "\n"
