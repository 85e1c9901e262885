"""USD loading: what a point instancer's instances cost, and the loader's memory beyond
the arrays it returns.

    PYTHONPATH=. python benchmarks/usd_loading.py [--runs 3] [--instances 10000] [--dir DIR]

Part 1 (speed): a point instancer of K instances (two icospheres of 320 faces taken in
turn, random positions, orientations and scales, .usdc) against the same world triangles
baked into one binary PLY. Each file runs `scatter sample FILE -n 1000000 -o out.ply -q
--stats S` in a child process, the files taken in turn round after round; the table has
medians of the whole command and of the run's own load and plan times (`--stats`
timings). The instancer's load + plan beside the flat PLY's is what the instances cost
beyond their faces; the draw is the sampling.

Part 2 (memory), one child process per measurement, on .usdc and .usda stages of
triangle meshes (icospheres), a quad mesh (the polygon path) and the instancer:
- usd-core's fixed cost: resident memory added by importing it and opening a first
  (tiny) stage, paid once per process whatever the file;
- the loader: peak resident memory (VmHWM, reset through /proc/self/clear_refs) while
  `load_surface` reads the file, minus the arrays it returns (vertices and faces, plain
  job; and with the primvar tables, full job), against the file size;
- usd-core alone: the same peak for just handing over the arrays the loader asks for
  (faceVertexIndices, faceVertexCounts, points of every mesh, as numpy views of the Vt
  arrays), which any reader through usd-core pays.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from testkit.benchargs import options, work_folder  # noqa: E402

PROTO_SUBDIVISIONS = 2  # 320 faces


def child_env():
    return dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))


def run_child(code, *args):
    out = subprocess.run([sys.executable, "-c", code, *map(str, args)], env=child_env(), check=True,
                         stdout=subprocess.PIPE).stdout
    return json.loads(out.decode().strip().splitlines()[-1])


MAKE = r"""
import sys, numpy as np, trimesh
from pxr import Usd, UsdGeom, Vt

def mesh_prim(stage, path, v, f, counts=None):
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(v, np.float32)))
    f = np.asarray(f)
    counts = np.full(len(f), f.shape[1], np.int32) if counts is None else counts
    m.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(counts))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(f.ravel().astype(np.int32)))
    m.CreateSubdivisionSchemeAttr("none")

kind, path = sys.argv[1], sys.argv[2]
stage = Usd.Stage.CreateNew(path)
if kind == "ico":
    m = trimesh.creation.icosphere(subdivisions=int(sys.argv[3]))
    mesh_prim(stage, "/ico", m.vertices, m.faces)
elif kind == "quads":
    n = int(sys.argv[3])
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    v = np.stack([x.ravel(), y.ravel(), np.sin(x.ravel() / 7) * np.cos(y.ravel() / 5)], 1)
    i = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    q = np.stack([i[:-1, :-1], i[:-1, 1:], i[1:, 1:], i[1:, :-1]], -1).reshape(-1, 4)
    mesh_prim(stage, "/grid", v, q)
else:
    k = int(sys.argv[3])
    rng = np.random.default_rng(0)
    pi = UsdGeom.PointInstancer.Define(stage, "/W/trees")
    ico = trimesh.creation.icosphere(subdivisions=%d)
    for j in range(2):
        mesh_prim(stage, f"/W/trees/protos/p{j}", ico.vertices * (1 + j), ico.faces)
    pi.CreatePrototypesRel().SetTargets([f"/W/trees/protos/p{j}" for j in range(2)])
    pi.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy((np.arange(k) %% 2).astype(np.int32)))
    pi.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(rng.uniform(-100, 100, (k, 3)).astype(np.float32)))
    q = rng.normal(size=(k, 4))
    pi.CreateOrientationsAttr(Vt.QuathArray.FromNumpy((q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float16)))
    pi.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(rng.uniform(0.5, 2, (k, 3)).astype(np.float32)))
stage.GetRootLayer().Save()
print("{}")
""" % PROTO_SUBDIVISIONS

FLATTEN = r"""
import sys, numpy as np, trimesh
from scatter_cli.loading.load import load_surface
s = load_surface(sys.argv[1], plain=True)
v, f, o = [], [], 0
for inst in s.instances:
    g = s.geometries[inst.geometry]
    v.append(s.world_vertices(inst)); f.append(g.faces + o); o += len(g.vertices)
trimesh.Trimesh(np.concatenate(v), np.concatenate(f), process=False).export(sys.argv[2])
print("{}")
"""

MEMORY = r"""
import json, os, sys
def status(field):
    for line in open("/proc/self/status"):
        if line.startswith(field):
            return int(line.split()[1]) * 1024
def reset_peak():
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
import numpy as np
from scatter_cli.loading.load import load_surface
path, tiny, what = sys.argv[1], sys.argv[2], sys.argv[3]
r0 = status("VmRSS")
from pxr import Usd, UsdGeom
r1 = status("VmRSS")
load_surface(tiny, plain=True)  # USD's plugins, schemas and first stage, once per process
r2 = status("VmRSS")
reset_peak()
base = status("VmRSS")
out = {"file": os.path.getsize(path), "import": r1 - r0, "first_stage": r2 - r1}
if what == "usd-alone":
    stage = Usd.Stage.Open(path)
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            m = UsdGeom.Mesh(prim)
            held = [np.asarray(a.Get()) for a in (m.GetFaceVertexIndicesAttr(), m.GetFaceVertexCountsAttr(),
                                                  m.GetPointsAttr())]
            del held
    out["peak"] = status("VmHWM") - base
else:
    s = load_surface(path, plain=what == "plain")
    out["peak"] = status("VmHWM") - base
    arrays = {}
    for g in s.geometries:
        for a in [g.vertices, g.faces] + ([] if g.mesh is None else
                                          [x for x in vars(g.mesh).values() if isinstance(x, np.ndarray)]):
            arrays[id(a)] = a.nbytes
    out["arrays"] = sum(arrays.values())
print(json.dumps(out))
"""


def make(kind, path, size):
    if not path.exists():
        run_child(MAKE, kind, path, size)
    return path


def part_speed(folder, instances, runs, work):
    stage = make("instancer", folder / f"instancer-{instances}.usdc", instances)
    flat = folder / f"instancer-{instances}-flat.ply"
    if not flat.exists():
        run_child(FLATTEN, stage, flat)
    files = {f"point instancer, {instances:,} instances (.usdc)": stage, "the same triangles, one binary PLY": flat}
    rows = {label: [] for label in files}
    for _ in range(runs):
        for label, path in files.items():
            stats = Path(work) / "stats.json"
            t = time.perf_counter()
            subprocess.run([sys.executable, "-m", "scatter_cli", "sample", str(path), "-n", "1000000", "-o",
                            str(Path(work) / "out.ply"), "-q", "--stats", str(stats)], env=child_env(), check=True)
            wall = time.perf_counter() - t
            timings = json.loads(stats.read_text())["timings"]
            rows[label].append((wall, timings["load"], timings["plan"], timings["sample_and_write"]))
    faces = 320 * instances
    print(f"\nPart 1: scatter sample FILE -n 1000000 -o out.ply ({faces:,} world faces), medians of {runs} rounds")
    print("| input | whole command s | load s | plan s | load + plan s | draw + write s |\n|---|---:|---:|---:|---:|---:|")
    med = {}
    for label, r in rows.items():
        wall, load, plan, draw = (statistics.median(x) for x in zip(*r))
        med[label] = load + plan
        print(f"| {label} | {wall:.2f} | {load:.3f} | {plan:.3f} | {load + plan:.3f} | {draw:.2f} |")
    a, b = med.values()
    print(f"instancer load + plan - flat PLY load + plan = {a - b:+.3f} s")


def part_memory(folder):
    tiny = make("ico", folder / "tiny.usdc", 0)
    files = [("ico", 7, "usdc"), ("ico", 8, "usdc"), ("ico", 7, "usda"), ("quads", 1000, "usdc"),
             ("instancer", 10000, "usdc")]
    print("\nPart 2: memory (MB = 10^6 bytes); beyond = peak - arrays returned")
    print("| file | size | usd-core alone: peak | plain: peak | arrays | beyond | beyond / size "
          "| full: peak | arrays | beyond |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    fixed = []
    for kind, size, suffix in files:
        path = make(kind, folder / f"{kind}-{size}.{suffix}", size)
        alone = run_child(MEMORY, path, tiny, "usd-alone")
        plain = run_child(MEMORY, path, tiny, "plain")
        full = run_child(MEMORY, path, tiny, "full")
        fixed.append((plain["import"], plain["first_stage"]))
        mb = 1e6
        beyond = plain["peak"] - plain["arrays"]
        print(f"| {path.name} | {plain['file'] / mb:.1f} | {alone['peak'] / mb:.1f} | {plain['peak'] / mb:.1f} | "
              f"{plain['arrays'] / mb:.1f} | {beyond / mb:.1f} | {beyond / plain['file']:.2f} | "
              f"{full['peak'] / mb:.1f} | {full['arrays'] / mb:.1f} | {(full['peak'] - full['arrays']) / mb:.1f} |")
    imp, first = (statistics.median(x) for x in zip(*fixed))
    print(f"usd-core fixed cost per process: import {imp / 1e6:.1f} MB, first stage {first / 1e6:.1f} MB")


def main():
    args = options(runs=3, instances=10000, dir=None, skip_speed=False, skip_memory=False)
    with work_folder(args.dir) as (folder, work):
        print(f"load average at start: {os.getloadavg()[0]:.1f}")
        if not args.skip_speed:
            part_speed(folder, args.instances, args.runs, work)
        if not args.skip_memory:
            part_memory(folder)


if __name__ == "__main__":
    main()
