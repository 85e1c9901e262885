"""Sharp-edge sampling (``--edges``) against the peers' way of doing it, in one run.

The mesh: the sample CAD part (samples/pediment_join_plate_12.stl) split in four six
times (516,096 faces), written as a binary STL (corners repeated per face, as CAD exports
them) and as an OBJ (welded, for Blender's importer). Measured, each in fresh processes,
one warm-up then the median of back-to-back runs, interleaved round by round:

- detection: ``EdgeTable`` of the loaded surface (face normals, the edges by corner position,
  the angle test, the edges placed in world space), in-process, median of 5;
- ``scatter sample MESH -n N -o out.ply`` plain, and with ``--edges 0.5``: their ratio;
- the trimesh script (what Hunyuan3D-2.1's sampling does with trimesh): load the mesh,
  ``face_adjacency_angles`` >= 15 degrees plus the boundary edges, N/2 points along them
  chosen by length, N/2 with ``trimesh.sample.sample_surface``, PLY written by trimesh;
- with ``--bpy PYTHON`` (a Python with ``pip install bpy``): Dora's steps, Blender's OBJ
  import and ``edges_select_sharp`` at 15 degrees, then the same sampling and writing.

    python benchmarks/edges.py [--count N] [--repeats R] [--bpy PYTHON] [--out DIR]

Figures: benchmarks/results/2026-12-04-edges.md.
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

TRIMESH_SCRIPT = r"""
import sys
import numpy as np
import trimesh
path, n, out = sys.argv[1], int(float(sys.argv[2])), sys.argv[3]
mesh = trimesh.load(path)
sharp = mesh.face_adjacency_edges[mesh.face_adjacency_angles >= np.radians(15)]
edges = mesh.edges_sorted
boundary = edges[trimesh.grouping.group_rows(edges, require_count=1)]
pairs = np.vstack([sharp, boundary])
a, b = mesh.vertices[pairs[:, 0]], mesh.vertices[pairs[:, 1]]
length = np.linalg.norm(b - a, axis=1)
rng = np.random.default_rng(0)
k = np.searchsorted(np.cumsum(length), rng.random(n // 2) * length.sum())
t = rng.random((n // 2, 1))
on_edges = a[k] + t * (b[k] - a[k])
on_faces, _ = trimesh.sample.sample_surface(mesh, n - n // 2)
trimesh.PointCloud(np.vstack([on_edges, on_faces])).export(out)
"""

BPY_SCRIPT = r"""
import math
import sys
import bpy
import numpy as np
import trimesh
path, n, out = sys.argv[1], int(float(sys.argv[2])), sys.argv[3]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.obj_import(filepath=path)
obj = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = obj
bpy.ops.object.mode_set(mode="EDIT")
bpy.ops.mesh.select_mode(type="EDGE")
bpy.ops.mesh.select_all(action="DESELECT")
bpy.ops.mesh.edges_select_sharp(sharpness=math.radians(15))
bpy.ops.object.mode_set(mode="OBJECT")
me = obj.data
selected = np.zeros(len(me.edges), bool)
me.edges.foreach_get("select", selected)
ends = np.zeros(2 * len(me.edges), np.int32)
me.edges.foreach_get("vertices", ends)
co = np.zeros(3 * len(me.vertices))
me.vertices.foreach_get("co", co)
co = co.reshape(-1, 3)
pairs = ends.reshape(-1, 2)[selected]
a, b = co[pairs[:, 0]], co[pairs[:, 1]]
length = np.linalg.norm(b - a, axis=1)
rng = np.random.default_rng(0)
k = np.searchsorted(np.cumsum(length), rng.random(n // 2) * length.sum())
t = rng.random((n // 2, 1))
on_edges = a[k] + t * (b[k] - a[k])
mesh = trimesh.load(path)
on_faces, _ = trimesh.sample.sample_surface(mesh, n - n // 2)
trimesh.PointCloud(np.vstack([on_edges, on_faces])).export(out)
print(int(selected.sum()), file=sys.stderr)
"""

DETECT_SCRIPT = r"""
import json, statistics, sys, time
from scatter_cli.loading.load import load_surface
from scatter_cli.sampling.edges import EdgeTable
surface = load_surface(sys.argv[1])
EdgeTable(surface)  # warm-up
times = []
for _ in range(5):
    t = time.perf_counter()
    table = EdgeTable(surface)
    times.append(time.perf_counter() - t)
print(json.dumps({"median_s": statistics.median(times), "times_s": times, "edges": len(table)}))
"""


def make_meshes(folder: Path):
    """(STL path, OBJ path, faces) of the benchmark mesh, written into ``folder``."""
    import trimesh

    part = trimesh.load(ROOT / "samples" / "pediment_join_plate_12.stl")
    for _ in range(6):
        part = part.subdivide()
    stl, obj = folder / "part.stl", folder / "part.obj"
    part.export(stl)
    part.export(obj)
    return stl, obj, len(part.faces)


def timed(cmd, env=None):
    t = time.perf_counter()
    proc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    seconds = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed: {proc.stderr.decode()[-400:]}")
    return seconds


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", default="1e6", help="points per run (default 1e6)")
    parser.add_argument("--repeats", type=int, default=5, help="timed rounds after one warm-up (default 5)")
    parser.add_argument("--bpy", metavar="PYTHON", help="a Python with bpy, for Dora's steps")
    parser.add_argument("--out", default="bench-out", help="folder for edges.json")
    args = parser.parse_args(argv)
    env = {**__import__("os").environ, "PYTHONPATH": str(ROOT), "NUMPY_MADVISE_HUGEPAGE": "0"}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        stl, obj, faces = make_meshes(tmp)
        detect = subprocess.run([sys.executable, "-c", DETECT_SCRIPT, str(stl)], capture_output=True, text=True,
                                env=env, check=True)
        detection = json.loads(detect.stdout.strip().splitlines()[-1])
        (tmp / "trimesh_peer.py").write_text(TRIMESH_SCRIPT)
        (tmp / "bpy_peer.py").write_text(BPY_SCRIPT)
        runs = {
            "scatter plain": [sys.executable, "-m", "scatter_cli", "sample", stl, "-n", args.count, "-q", "-o",
                              tmp / "plain.ply"],
            "scatter --edges 0.5": [sys.executable, "-m", "scatter_cli", "sample", stl, "-n", args.count, "--edges",
                                    "0.5", "-q", "-o", tmp / "edges.ply"],
            "trimesh script": [sys.executable, tmp / "trimesh_peer.py", stl, args.count, tmp / "trimesh.ply"],
        }
        if args.bpy:
            runs["Dora's steps (bpy)"] = [args.bpy, tmp / "bpy_peer.py", obj, args.count, tmp / "bpy.ply"]
        times = {name: [] for name in runs}
        for round_ in range(args.repeats + 1):
            for name, cmd in runs.items():
                seconds = timed(cmd, env)
                if round_:
                    times[name].append(seconds)
    median = {name: statistics.median(t) for name, t in times.items()}
    edges = median["scatter --edges 0.5"]
    report = {"faces": faces, "count": args.count, "detection": detection, "median_s": median, "times_s": times,
              "edges_over_plain": edges / median["scatter plain"],
              "peer_over_edges": {n: median[n] / edges for n in median if not n.startswith("scatter")}}
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "edges.json").write_text(json.dumps(report, indent=1))
    print(f"mesh: {faces:,} faces, {args.count} points, median of {args.repeats} rounds")
    print(f"detection (EdgeTable, in-process): {detection['median_s']:.3f} s, {detection['edges']:,} sharp edges")
    print("| run | median | ratio to scatter --edges 0.5 |")
    print("|---|---:|---:|")
    for name, m in median.items():
        print(f"| {name} | {m:.3f} s | {m / edges:.2f}x |")
    print(f"--edges 0.5 over plain: {report['edges_over_plain']:.2f}x")


if __name__ == "__main__":
    main()
