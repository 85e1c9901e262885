"""What attributes cost, and instanced scenes against flattened ones.

    NUMPY_MADVISE_HUGEPAGE=0 PYTHONPATH=. python benchmarks/attributes.py [--runs 5] [--count 1000000]

1. `scatter sample` (the real command, in a subprocess, NPY output) of N points with xyz
   only on samples/cesiummilktruck.glb (textured, 4 materials, instanced wheel) against the
   same scene stripped to bare triangles (no UVs, normals, materials, images).
2. The added cost of each attribute (-a) and of --weight texture:a on the truck's textured
   objects (--object Cesium_Milk_Truck --object Wheels, which have UVs).
3. One 100k-face geometry (koala.obj) placed 40 times as instances, against the same scene
   flattened by trimesh (scene.to_mesh()): time and peak traced memory of scatter_cli.sample.
Times are medians of back-to-back warm runs (alternating the variants being compared).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc

os.environ["NUMPY_MADVISE_HUGEPAGE"] = "0"
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
from testkit.benchargs import options  # noqa: E402

import numpy as np  # noqa: E402
import trimesh  # noqa: E402

TRUCK = os.path.join(ROOT, "samples", "cesiummilktruck.glb")
SUBSET = ["--object", "Cesium_Milk_Truck", "--object", "Wheels"]


def cli_time(args, out):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""), NUMPY_MADVISE_HUGEPAGE="0")
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "scatter_cli", "sample", *args, "-q", "-o", out], check=True, env=env)
    return time.perf_counter() - t


def medians(variants, runs, out):
    """{name: median seconds} running the variants back to back, alternating, after a warm-up."""
    times = {name: [] for name in variants}
    for name, args in variants.items():
        cli_time(args, out)  # warm the page cache and the bytecode
    for _ in range(runs):
        for name, args in variants.items():
            times[name].append(cli_time(args, out))
    return {name: statistics.median(t) for name, t in times.items()}


def stripped_copy(path, dest):
    """The same scene graph and triangles with every visual removed, as a GLB."""
    scene = trimesh.load(path, process=False)
    bare = trimesh.Scene()
    for name, g in scene.geometry.items():
        bare.add_geometry(trimesh.Trimesh(g.vertices, g.faces, process=False), geom_name=name, node_name=f"_{name}")
    bare.graph.clear()
    for node in scene.graph.nodes_geometry:
        m, g = scene.graph[node]
        bare.graph.update(frame_to=node, frame_from=bare.graph.base_frame, matrix=m, geometry=g)
    bare.export(dest)
    return dest


def traced(fn):
    tracemalloc.start()
    t = time.perf_counter()
    fn()
    dt = time.perf_counter() - t
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return dt, peak


def main():
    a = options(runs=5, count=1_000_000, instances=40)
    n = str(a.count)
    tmp = tempfile.mkdtemp(prefix="scatter-bench-")
    out = os.path.join(tmp, "out.npy")
    bare = stripped_copy(TRUCK, os.path.join(tmp, "truck-bare.glb"))
    try:
        import PIL
        pil = f"Pillow {PIL.__version__} installed"
    except ImportError:
        pil = "Pillow not installed"
    print(f"# scatter attribute costs: N = {a.count:,}, medians of {a.runs} warm runs, {pil}, "
          f"numpy {np.__version__}, trimesh {trimesh.__version__}, {os.cpu_count()} CPUs\n")

    m = medians({"textured": [TRUCK, "-n", n], "bare": [bare, "-n", n]}, a.runs, out)
    print("## xyz only: textured, coloured GLB vs the same geometry as bare triangles\n")
    print("| input | median s | vs bare |\n|---|---:|---:|")
    for k in ("bare", "textured"):
        print(f"| {k} | {m[k]:.3f} | {100 * (m[k] / m['bare'] - 1):+.1f}% |")

    rows = {"xyz only": []}
    for attr in ("normal", "smooth-normal", "face", "bary", "uv", "color", "object"):
        rows[f"-a {attr}"] = ["-a", attr]
    rows["--weight texture:a"] = ["--weight", "texture:a"]
    rows["-a color --weight texture:a"] = ["-a", "color", "--weight", "texture:a"]
    rows["-a normal,face,bary,color,uv,object"] = ["-a", "normal,face,bary,color,uv,object"]
    m = medians({k: [TRUCK, "-n", n, *SUBSET, *v] for k, v in rows.items()}, a.runs, out)
    base = m["xyz only"]
    print(f"\n## added cost of each attribute ({os.path.basename(TRUCK)} {' '.join(SUBSET)})\n")
    print("| options | median s | added s | added % |\n|---|---:|---:|---:|")
    for k in rows:
        print(f"| {k} | {m[k]:.3f} | {m[k] - base:+.3f} | {100 * (m[k] / base - 1):+.1f}% |")

    import scatter_cli

    koala = trimesh.load(os.path.join(ROOT, "samples", "koala.obj"), process=False)
    scene = trimesh.Scene()
    scene.add_geometry(koala, geom_name="koala", node_name="k0")
    rng = np.random.default_rng(0)
    for i in range(1, a.instances):
        mat = trimesh.transformations.random_rotation_matrix(rng.random(3)) @ np.diag([*rng.uniform(0.5, 2, 3), 1])
        mat[:3, 3] = rng.uniform(-50, 50, 3)
        scene.graph.update(frame_to=f"k{i}", frame_from=scene.graph.base_frame, matrix=mat, geometry="koala")
    t = time.perf_counter()
    flat = scene.to_mesh()
    t_flatten = time.perf_counter() - t
    res = {"instanced scene": [], "flattened by trimesh": []}
    for _ in range(a.runs):
        res["instanced scene"].append(traced(lambda: scatter_cli.sample(scene, a.count, precision="float64")))
        res["flattened by trimesh"].append(traced(lambda: scatter_cli.sample(flat, a.count, precision="float64")))
    print(f"\n## {a.instances} instances of koala.obj ({len(koala.faces):,} faces) vs the flattened mesh "
          f"({len(flat.faces):,} faces; trimesh to_mesh took {t_flatten:.3f} s, the flat mesh holds "
          f"{(flat.vertices.nbytes + flat.faces.nbytes) / 2**20:.0f} MiB of arrays)\n")
    print("| input | median s (sample, N points) | median peak traced MiB |\n|---|---:|---:|")
    for k, v in res.items():
        print(f"| {k} | {statistics.median(x[0] for x in v):.3f} | {statistics.median(x[1] for x in v) / 2**20:.0f} |")


if __name__ == "__main__":
    main()
