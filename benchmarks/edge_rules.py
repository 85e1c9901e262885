"""Hunyuan3D-2.1's sharp-edge rule against the dihedral angle of ``--sharp-angle``.

Hunyuan3D-2.1's ``watertight_and_sample.py`` marks a vertex sharp when its normal (trimesh's
``vertex_normals``) and one of its faces' normals have a cosine under 0.985 (8.8 degrees),
and samples the edges whose two ends are sharp vertices. That is a rule on vertices, not
on edges: an edge between two sharp vertices across a flat face counts too. For each mesh
(loaded with trimesh, vertices merged), this compares that edge set with the sharp edges of
``--sharp-angle A`` (every boundary and non-manifold edge, and the edges whose faces meet at
A degrees or more) for A from 1 to 90 degrees, and prints the angle whose set differs least
(edges in one set only) and how many differ there.

    python benchmarks/edge_rules.py [MESH ...]

Figures: benchmarks/results/2026-12-04-edges.md.
"""

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scatter_cli.sampling import sharp  # noqa: E402
from scatter_cli.surface.topology import welded  # noqa: E402

MESHES = ["pediment_join_plate_12.stl", "cesiummilktruck.glb", "spot_triangulated.obj", "koala.obj", "skull.ply"]


def hunyuan_edges(mesh, position):
    """{(i, j)} undirected edges (position numbers ``position`` (V,) of their ends, i < j)
    marked by Hunyuan3D-2.1's rule."""
    faces, normals, vn = mesh.faces, mesh.face_normals, mesh.vertex_normals
    lowest = np.ones(len(mesh.vertices))
    for k in range(3):
        np.minimum.at(lowest, faces[:, k], np.einsum("ij,ij->i", vn[faces[:, k]], normals))
    on = lowest < 0.985
    a = faces.reshape(-1)
    b = faces[:, [1, 2, 0]].reshape(-1)
    keep = on[a] & on[b]
    a, b = position[a[keep]], position[b[keep]]
    return set(zip(np.minimum(a, b).tolist(), np.maximum(a, b).tolist()))


def dihedral_edges(mesh, angle, normals, position):
    """{(i, j)} undirected sharp edges at ``angle`` degrees (scatter's rule), by position numbers."""
    found = sharp.sharp_edges(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), normals, angle)
    f, k = mesh.faces[found.face], found.corner
    a, b = position[f[np.arange(len(f)), k]], position[f[np.arange(len(f)), (k + 1) % 3]]
    return set(zip(np.minimum(a, b).tolist(), np.maximum(a, b).tolist()))


def compare(path):
    import trimesh

    mesh = trimesh.load(path, force="mesh")
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    normals = np.asarray(mesh.face_normals, float)
    position = welded(v, np.arange(len(v))[:, None])[:, 0]  # one number per distinct position
    theirs = hunyuan_edges(mesh, position)
    best = None
    for angle in range(1, 91):
        ours = dihedral_edges(mesh, angle, normals, position)
        differ = len(ours ^ theirs)
        if best is None or differ < best[1]:
            best = (angle, differ, len(ours), len(ours - theirs), len(theirs - ours))
    at15 = dihedral_edges(mesh, 15, normals, position)
    return {"mesh": Path(path).name, "faces": len(f), "hunyuan": len(theirs), "best_angle": best[0],
            "differ": best[1], "ours_at_best": best[2], "ours_only": best[3], "theirs_only": best[4],
            "ours_at_15": len(at15), "differ_at_15": len(at15 ^ theirs)}


def main(paths):
    paths = paths or [ROOT / "samples" / m for m in MESHES]
    print("| mesh | faces | Hunyuan's edges | closest angle | edges there | differ (ours only / theirs only) "
          "| at 15 degrees: edges, differ |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for path in paths:
        r = compare(path)
        print(f"| {r['mesh']} | {r['faces']:,} | {r['hunyuan']:,} | {r['best_angle']} | {r['ours_at_best']:,} "
              f"| {r['differ']:,} ({r['ours_only']:,} / {r['theirs_only']:,}) | {r['ours_at_15']:,}, "
              f"{r['differ_at_15']:,} |")


if __name__ == "__main__":
    main(sys.argv[1:])
