"""Volume samples' distances and signs against the peers, all given the same points.

For each mesh (the skull sample, 100k faces; a closed 327,680-face icosphere), 10^6
points uniform in the bounding box grown by 0.1 of its largest side, and for each method
its time (a warm-up on 10^4 points, then the median of back-to-back runs on all points,
building its tree or scene each time) and its ratio to the fastest peer of the same run:

- scatter: distance (distance.closest_points), parity (parity.parity_inside, 3 rays),
  distance + parity, and distance + winding when scatter_cli/volume/winding.py is present
  (`--sign winding`). One tree for distance and parity; distance + winding builds its two
  trees and queries them as a volume run does (source.label_trees, then
  source.distances_and_windings: both queries at once); queries in chunks of CHUNK points.
- peers: Open3D ``RaycastingScene.compute_signed_distance`` (float32, Embree), point-cloud-
  utils ``signed_distance_to_mesh`` (fast winding number signs), libigl
  ``signed_distance`` with ``SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER``; with
  ``--mesh-to-sdf PYTHON``, also mesh_to_sdf's ``mesh_to_sdf`` (its defaults: 100 scans
  of 400 x 400, signs from the normals of the nearest scan points) in that Python (an
  environment of its own: it pins old libraries; rendering headless through EGL), run
  once without a warm-up (minutes), its time the whole subprocess.

Then, on an open mesh (samples/hemisphere.off), each method's inside labels against the
exact winding number (libigl's ``winding_number``, a sum of solid angles) at 2*10^4
points of its padded box: the share of points labelled differently, over all points and
over those with |w - 0.5| >= 0.05.

    python benchmarks/volume.py [--points N] [--repeats R] [--peer-repeats R] [--meshes skull,sphere7]
        [--mesh-to-sdf PYTHON]

Figures: benchmarks/results/2026-12-03-volume-distance.md.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scatter_cli.volume import distance, parity  # noqa: E402
from scatter_cli.volume.source import distances_and_windings, label_trees  # noqa: E402

try:  # the winding numbers of --sign winding, when present
    from scatter_cli.volume import winding
except ImportError:
    winding = None

CHUNK = 1 << 18


def load(name):
    """(vertices (V, 3) float64, faces (F, 3) int64) of a benchmark mesh."""
    import trimesh

    if name == "skull":
        m = trimesh.load(ROOT / "samples" / "skull.ply", process=False)
    elif name == "sphere7":
        m = trimesh.creation.icosphere(subdivisions=7)
    elif name == "hemisphere":
        m = trimesh.load(ROOT / "samples" / "hemisphere.off", process=False)
    else:
        raise SystemExit(f"unknown mesh {name}")
    return np.ascontiguousarray(m.vertices, dtype=np.float64), np.ascontiguousarray(m.faces, dtype=np.int64)


def box_points(v, n, seed=1):
    lo, hi = v.min(axis=0), v.max(axis=0)
    pad = 0.1 * (hi - lo).max()
    return np.random.default_rng(seed).uniform(lo - pad, hi + pad, (n, 3))


# ---- methods: (vertices, faces, points) -> (distance or signed distance or None, inside or None) ----

def ours_distance(v, f, p):
    tree = distance.TriangleTree(v, f)
    return np.concatenate([distance.closest_points(tree, p[i:i + CHUNK])[0] for i in range(0, len(p), CHUNK)]), None


def ours_parity(v, f, p):
    tree = distance.TriangleTree(v, f)
    return None, np.concatenate([parity.parity_inside(tree, p[i:i + CHUNK]) for i in range(0, len(p), CHUNK)])


def ours_distance_parity(v, f, p):
    tree = distance.TriangleTree(v, f)
    d, inside = [], []
    for i in range(0, len(p), CHUNK):
        d.append(distance.closest_points(tree, p[i:i + CHUNK])[0])
        inside.append(parity.parity_inside(tree, p[i:i + CHUNK]))
    d, inside = np.concatenate(d), np.concatenate(inside)
    return np.where(inside, -d, d), inside


def ours_distance_winding(v, f, p):
    tree, wtree = label_trees(v[f], True, True)  # as a volume run builds them
    d, inside = [], []
    for i in range(0, len(p), CHUNK):  # and labels them: both queries at once
        found, w = distances_and_windings(tree, wtree, p[i:i + CHUNK])
        d.append(found[0])
        inside.append(w >= 0.5)
    d, inside = np.concatenate(d), np.concatenate(inside)
    return np.where(inside, -d, d), inside


def open3d_sdf(v, f, p):
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
    s = scene.compute_signed_distance(o3d.core.Tensor(p.astype(np.float32))).numpy()
    return s, s < 0


def pcu_sdf(v, f, p):
    import point_cloud_utils as pcu

    s = pcu.signed_distance_to_mesh(p, v, f)[0]
    return s, s < 0


def igl_sdf(v, f, p):
    import igl

    s = igl.signed_distance(p, v, f, sign_type=igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER)[0]
    return s, s < 0


M2S_SCRIPT = r"""
import os, sys
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
import numpy as np, trimesh
from mesh_to_sdf import mesh_to_sdf
d = np.load(sys.argv[1])
s = mesh_to_sdf(trimesh.Trimesh(d["v"], d["f"], process=False), d["p"])
np.save(sys.argv[2], np.asarray(s, dtype=np.float64))
"""


def mesh_to_sdf_in(python):
    """mesh_to_sdf's signed distances (negative inside), computed in ``python``."""

    def run(v, f, p):
        with tempfile.TemporaryDirectory() as tmp:
            np.savez(f"{tmp}/in.npz", v=v, f=f, p=p)
            subprocess.run([python, "-c", M2S_SCRIPT, f"{tmp}/in.npz", f"{tmp}/out.npy"], check=True,
                           stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
            s = np.load(f"{tmp}/out.npy")
        return s, s < 0

    return run


SLOW = ("mesh_to_sdf",)  # run once, without a warm-up

OURS = {"scatter distance": ours_distance, "scatter parity (3 rays)": ours_parity,
        "scatter distance + parity": ours_distance_parity}
if winding is not None:
    OURS["scatter distance + winding"] = ours_distance_winding
PEERS = {"Open3D compute_signed_distance": open3d_sdf, "point-cloud-utils signed_distance_to_mesh": pcu_sdf,
         "libigl signed_distance (fast winding)": igl_sdf}


def timed(fn, v, f, p, repeats, warm=True):
    """(median s, the runs' s, the last output) of ``repeats`` runs after a warm-up"""
    if warm:
        fn(v, f, p[:10000])
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn(v, f, p)
        times.append(time.perf_counter() - t)
    return statistics.median(times), times, out


def speed(name, n, repeats, peer_repeats):
    v, f = load(name)
    p = box_points(v, n)
    print(f"\n### {name}: {len(f)} faces, {n} points in the padded box, median of {repeats} runs "
          f"(peers: {peer_repeats})\n")
    rows, ref = [], None
    for label, fn in {**OURS, **PEERS}.items():
        try:
            slow = label.startswith(SLOW)
            med, times, out = timed(fn, v, f, p, 1 if slow else repeats if label in OURS else peer_repeats, not slow)
        except ImportError as e:
            print(f"- {label}: not installed ({e})")
            continue
        rows.append((label, med, times))
        if label == "scatter distance":
            ref = out[0]
        elif out[0] is not None and ref is not None:
            gap = np.abs(np.abs(out[0]) - ref).max()
            print(f"- {label}: largest | |sdf| - scatter's exact distance | = {gap:.3g}")
    fastest = min((m for label, m, _ in rows if label in PEERS), default=None)
    print("\n| method | median s | runs s | fastest peer / this |\n|---|---|---|---|")
    for label, med, times in rows:
        ratio = f"{fastest / med:.2f}x" if fastest else "-"
        print(f"| {label} | {med:.3f} | {', '.join(f'{t:.2f}' for t in times)} | {ratio} |")


def labels(n):
    try:
        import igl  # the exact winding number the labels are checked against
    except ImportError:
        print("\n(labels on the open hemisphere: skipped, libigl is not installed: pip install libigl)")
        return
    v, f = load("hemisphere")
    p = box_points(v, n, seed=2)
    w = igl.winding_number(v, f, p)
    exact = w >= 0.5
    sure = np.abs(w - 0.5) >= 0.05
    print(f"\n### labels on samples/hemisphere.off (open, {len(f)} faces), {n} points, against the exact winding number\n")
    print("| method | time s | differs (all points) | differs where abs(w - 0.5) >= 0.05 |\n|---|---|---|---|")
    for label, fn in {**OURS, **PEERS}.items():
        if label == "scatter distance":
            continue
        try:
            t = time.perf_counter()
            inside = fn(v, f, p)[1]
            t = time.perf_counter() - t
        except ImportError:
            continue
        bad = inside != exact
        print(f"| {label} | {t:.3f} | {bad.mean():.2%} | {bad[sure].mean():.2%} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10**6)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--peer-repeats", type=int, default=None, help="runs of each peer (default: --repeats)")
    ap.add_argument("--meshes", default="skull,sphere7")
    ap.add_argument("--label-points", type=int, default=20000)
    ap.add_argument("--threads", type=int, default=None, help="SCATTER_THREADS for ours (default: its default)")
    ap.add_argument("--mesh-to-sdf", metavar="PYTHON", help="a Python with mesh-to-sdf installed: run it too")
    args = ap.parse_args()
    if args.mesh_to_sdf:
        PEERS["mesh_to_sdf mesh_to_sdf (scans)"] = mesh_to_sdf_in(args.mesh_to_sdf)
    if args.threads:
        os.environ["SCATTER_THREADS"] = str(args.threads)
    print(f"load before: {open('/proc/loadavg').read().strip()}; cores: {os.cpu_count()}; "
          f"kernel: {'yes' if distance._kernel else 'no (NumPy path)'}; winding: {'yes' if winding else 'absent'}")
    for name in args.meshes.split(","):
        speed(name, args.points, args.repeats, args.peer_repeats or args.repeats)
    labels(args.label_points)
    print(f"\nload after: {open('/proc/loadavg').read().strip()}")


if __name__ == "__main__":
    main()
