"""The memory a load takes beyond what it returns, measured in a fresh process.

Shared by tests/test_readers.py and benchmarks/loading.py. The child imports what a load
needs, notes its resident size, loads the file (``load_surface(path, plain=True)``) and
reports its peak resident size (the kernel's high-water mark, VmHWM: getrusage's
maximum would be the forking parent's when that was larger), the bytes of the arrays
the load returned and the file size. ``extra`` is the peak beyond the resident size
before, the returned arrays and the file's own bytes (the readers map the file and touch
all of it: that is the file, not a copy of it).
"""

import json
import sys

CHILD = r"""
import gc, json, os, sys
import numpy as np
import scatter_cli.loading.gltf, scatter_cli.loading.ply, scatter_cli.loading.fast
from scatter_cli.core.native import kernel
from scatter_cli.loading.load import load_surface
kernel("_creaders")
gc.collect()
with open("/proc/self/statm") as f:
    before = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
tables = sys.argv[2] == "1"  # with the tables the file's format has, counted as returned
ply, obj = (tables and sys.argv[1].endswith(s) for s in (".ply", ".obj"))
surface = load_surface(sys.argv[1], plain=True, smooth=tables, color=ply, uv=obj)
with open("/proc/self/status") as f:  # VmHWM: this process image's own high-water mark
    peak = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))
arrays = sum(g.vertices.nbytes + g.faces.nbytes for g in surface.geometries)
arrays += sum(getattr(g.mesh, k).nbytes for g in surface.geometries for k in ("normals", "vertex_colors", "uv")
              if getattr(g.mesh, k, None) is not None)
print(json.dumps({"before": before, "peak": peak, "arrays": arrays, "file": os.path.getsize(sys.argv[1])}))
"""


def load_memory(path, run, env=None, tables=False):
    """{before, peak, arrays, file, extra} in bytes for loading ``path`` in a child run by
    ``run`` (a function like conftest.run_user: (cmd, env=...) -> CompletedProcess).
    ``tables``: load the file's attribute tables too: a smooth-normal job, and color for
    a PLY, uv for an OBJ."""
    proc = run([sys.executable, "-c", CHILD, str(path), "1" if tables else "0"], env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"the load of {path} failed: {proc.stderr[-500:]}")
    got = json.loads(proc.stdout)
    got["extra"] = got["peak"] - got["before"] - got["arrays"] - got["file"]
    return got
