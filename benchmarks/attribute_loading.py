"""Attribute loads on the fast readers against trimesh: PLY colours and normals, OBJ UVs
and normals, on the icosphere (1.31M faces by default), one command.

    NUMPY_MADVISE_HUGEPAGE=0 PYTHONPATH=. python benchmarks/attribute_loading.py [--runs 5] [--subdivisions 8] [--dir DIR]

Files: binary and ASCII PLY with float normals and RGBA uchar colours; an OBJ with
v/vt/vn refs drawn so that vertices split (tests/test_reader_attributes.py's builders).
Part 1: whole commands `scatter sample FILE -n 1000000 -a ATTRS -o out.ply -q`, ATTRS
`color,smooth-normal` (PLY) or `uv,smooth-normal` (OBJ), on the fast path and through
trimesh (SCATTER_NUMPY=1: no compiled readers, so the ASCII PLY and the OBJ go to
trimesh; the binary PLY is read with NumPy either way and is left out of part 1), in
turn round after round, medians and the ratio. Part 2: the load alone in one process
after a warm-up, `load_surface(path, plain=True, smooth=True, color|uv=True)` against
`load_surface(path)` (trimesh), medians of --runs.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from testkit.benchargs import options, work_folder  # noqa: E402

ATTRS = {"ply": "color,smooth-normal", "obj": "uv,smooth-normal"}


def build(folder, subdivisions):
    """{label: path} of the three files, written once."""
    import numpy as np
    import trimesh

    from testkit.meshfiles import obj_text, write_ply

    paths = {label: folder / f"ico{subdivisions}-{label.replace(' ', '-').lower()}.{label.split()[-1].lower()}"
             for label in ("binary PLY", "ASCII PLY", "OBJ")}
    if all(p.exists() for p in paths.values()):
        return paths
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    columns = [(a, "f4", v[:, k]) for k, a in enumerate("xyz")] + [(a, "f4", v[:, k]) for k, a in enumerate(("nx", "ny", "nz"))]
    columns += [(a, "u1", (np.arange(len(v)) * (k + 3)) % 256) for k, a in enumerate(("red", "green", "blue", "alpha"))]
    write_ply(paths["binary PLY"], columns, f, "binary_little_endian")
    write_ply(paths["ASCII PLY"], columns, f, "ascii")
    paths["OBJ"].write_text(obj_text(v, f.tolist(), "v/vt/vn"))
    return paths


def env(extra=None):
    e = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    e.update(extra or {})
    return e


def whole_commands(paths, runs, work):
    cases = [(label, path, way) for label, path in paths.items() if label != "binary PLY" for way in ("fast", "trimesh")]
    times = {(label, way): [] for label, _, way in cases}
    for r in range(runs + 1):  # round 0: warm-up
        for label, path, way in cases:
            out = work / "out.ply"
            cmd = [sys.executable, "-m", "scatter_cli", "sample", str(path), "-n", "1000000", "-a",
                   ATTRS[path.suffix[1:]], "-o", str(out), "-q"]
            t = time.perf_counter()
            subprocess.run(cmd, env=env({"SCATTER_NUMPY": "1"} if way == "trimesh" else None), check=True)
            if r:
                times[label, way].append(time.perf_counter() - t)
            out.unlink()
    print("part 1: whole commands, median s")
    for label in dict.fromkeys(label for label, _, _ in cases):
        fast, slow = (statistics.median(times[label, w]) for w in ("fast", "trimesh"))
        print(f"  {label:11s} fast {fast:6.2f}  trimesh {slow:6.2f}  trimesh / fast {slow / fast:5.2f}")


def loads(paths, runs):
    from scatter_cli.loading.load import load_surface

    print("part 2: load only, one process, median s")
    for label, path in paths.items():
        wants = {"color": True} if path.suffix == ".ply" else {"uv": True}
        ways = {"fast": lambda: load_surface(path, plain=True, smooth=True, **wants), "trimesh": lambda: load_surface(path)}
        got = {}
        for way, load in ways.items():
            load()  # warm-up (and trimesh's import)
            samples = []
            for _ in range(runs):
                t = time.perf_counter()
                load()
                samples.append(time.perf_counter() - t)
            got[way] = statistics.median(samples)
        print(f"  {label:11s} fast {got['fast']:6.3f}  trimesh {got['trimesh']:6.3f}  trimesh / fast "
              f"{got['trimesh'] / got['fast']:5.2f}")


def main():
    args = options(runs=5, subdivisions=8, dir=None)
    with work_folder(args.dir) as (folder, tmp):
        paths = build(folder, args.subdivisions)
        print(f"load average before: {open('/proc/loadavg').read().split()[:3]}")
        whole_commands(paths, args.runs, tmp)
        loads(paths, args.runs)
        print(f"load average after: {open('/proc/loadavg').read().split()[:3]}")


if __name__ == "__main__":
    main()
