"""The measuring harness of benchmarks/run.py: children that time one method in a fresh
interpreter, whole commands timed with their peak memory, and the meshes measured."""

import gc
import json
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
RUN_SCRIPT = Path(__file__).resolve().with_name("run.py")  # runs a child with --child SPEC
DEFAULT_REAL_MESH = REPO / "samples" / "skull.ply"
CHILD_TIMEOUT_S = 1800
OURS_MODE_VAR = "SCATTER_BENCH_OURS"  # "checkout" or "installed"


# ---------------------------------------------------------------------------
# Child side
# ---------------------------------------------------------------------------

def read_status_kb(field):
    with open("/proc/self/status") as f:
        return int(re.search(field + r":\s+(\d+)", f.read()).group(1))


def reset_peak_rss():
    """Reset VmHWM to the current RSS; False where the kernel does not allow it."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def one_run(sample, reset, handle, n, kw):
    """Time one run; return (seconds, points, peak RSS in kB during the run)."""
    if reset:
        reset(handle)
    gc.collect()
    reset_peak_rss()
    t0 = time.perf_counter()
    points = sample(handle, n, **kw)
    seconds = time.perf_counter() - t0
    return seconds, points, read_status_kb("VmHWM")


def min_spacing(points):
    from scipy.spatial import cKDTree

    distances, _ = cKDTree(points).query(points, k=2)
    return float(distances[:, 1].min())


def child_main(spec, methods):
    """One measurement (``spec`` from run_child) of one of ``methods`` (name -> (load,
    sample, reset, label)): a warm-up run, then back-to-back timed runs."""
    load, sample, reset, _ = methods[spec["method"]]
    n, kw = spec["n"], spec.get("kw", {})

    handle = load(spec["mesh"])
    gc.collect()
    baseline_kb = read_status_kb("VmRSS")

    first_s, points, peak_kb = one_run(sample, reset, handle, n, kw)
    repeats = spec["repeats"]
    if first_s * repeats > spec["run_budget_s"]:
        repeats = max(1, int(spec["run_budget_s"] // max(first_s, 1e-9)))
    times = []
    for _ in range(repeats):
        points = None
        seconds, points, kb = one_run(sample, reset, handle, n, kw)
        times.append(seconds)
        peak_kb = max(peak_kb, kb)

    result = {
        "first_s": first_s,
        "times_s": times,
        "median_s": statistics.median(times),
        "runs": len(times),
        "count": int(len(points)),
        "out_dtype": str(np.asarray(points).dtype),
        "rss_after_load_mb": baseline_kb / 1024,
        "peak_extra_mb": (peak_kb - baseline_kb) / 1024,
    }
    if spec["section"] == "poisson":
        result.update(spacing_stats(np.asarray(points, dtype=np.float64), spec["area"]))
    return result


POISSON_RHO_FLOOR = 0.3  # uniform random samples of 10k+ points score far below this


def spacing_stats(points, area):
    n = len(points)
    d_min = min_spacing(points) if n > 1 else float("nan")
    stats = {"d_min": d_min, "rho": rho(d_min, area, n)}
    if not stats["rho"] >= POISSON_RHO_FLOOR:
        stats["warning"] = f"rho below {POISSON_RHO_FLOOR}: not Poisson-disk"
    return stats


def rho(d_min, area, n):
    """d_min relative to the spacing of a hexagonal packing of n points on area."""
    return d_min / math.sqrt(2 * area / (math.sqrt(3) * n))


# ---------------------------------------------------------------------------
# Parent side: running children and commands
# ---------------------------------------------------------------------------

def child_env():
    env = dict(os.environ)
    env["NUMPY_MADVISE_HUGEPAGE"] = "0"
    if env.get(OURS_MODE_VAR, "checkout") == "checkout":
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    env["QT_QPA_PLATFORM"] = "offscreen"
    return env


def run_child(spec):
    """Run one measurement in a fresh interpreter; return its result or an error note."""
    cmd = [sys.executable, str(RUN_SCRIPT), "--child", json.dumps(spec)]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=child_env(),
                              timeout=CHILD_TIMEOUT_S, cwd=tempfile.gettempdir())
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {CHILD_TIMEOUT_S} s"}
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        return {"error": last_line(proc.stderr) or f"exit code {proc.returncode}"}
    return json.loads(lines[-1])


def last_line(text):
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1].strip() if lines else ""


GNU_TIME = shutil.which("time")  # GNU time, for the peak RSS of a command; None: not measured


def wait_command(cmd, env, cwd):
    """Run cmd; return (wall seconds, peak RSS MB or None, exit code, stderr tail).

    The peak RSS comes from GNU time wrapped around the command: the rusage of
    a child forked from this (large) interpreter would report our own RSS."""
    with tempfile.NamedTemporaryFile("r") as rss, tempfile.TemporaryFile() as err:
        wrapped = cmd
        if GNU_TIME:
            wrapped = [GNU_TIME, "-f", "%M", "-o", rss.name, *cmd]
        t0 = time.perf_counter()
        code = subprocess.run(wrapped, stdout=subprocess.DEVNULL, stderr=err, env=env,
                              cwd=cwd).returncode
        seconds = time.perf_counter() - t0
        err.seek(0)
        tail = last_line(err.read().decode(errors="replace"))
        peak_kb = re.findall(r"^(\d+)$", rss.read(), re.M)
    return seconds, int(peak_kb[-1]) / 1024 if peak_kb else None, code, tail


def time_command(cmd, repeats, out_file=None, env=None, cwd=None):
    """One warm-up, then `repeats` back-to-back runs; median wall time."""
    env = env or child_env()
    times, peak = [], 0.0  # peak stays None once GNU time is missing
    for i in range(repeats + 1):
        if out_file:
            Path(out_file).unlink(missing_ok=True)
        seconds, mb, code, tail = wait_command(cmd, env, cwd)
        if code != 0:
            return {"error": tail or f"exit code {code}"}
        if i > 0:
            times.append(seconds)
        peak = max(peak, mb) if mb is not None else None
    result = {"median_s": statistics.median(times), "times_s": times, "runs": len(times),
              "peak_rss_mb": peak}
    if out_file:
        result["count"] = ply_vertex_count(out_file)
    return result


def ply_vertex_count(path):
    try:
        with open(path, "rb") as f:
            header = f.read(4096).split(b"end_header")[0].decode(errors="replace")
    except OSError:
        return None
    match = re.search(r"element vertex (\d+)", header)
    return int(match.group(1)) if match else None


# ---------------------------------------------------------------------------
# Meshes
# ---------------------------------------------------------------------------

def mesh_info(path):
    import trimesh

    mesh = trimesh.load(path, force="mesh")
    return {"path": str(path), "faces": len(mesh.faces), "vertices": len(mesh.vertices),
            "area": float(mesh.area),
            "mesh_arrays_mb": (mesh.vertices.nbytes + mesh.faces.nbytes) / 2**20}


def make_icosphere(tmp, subdivisions, name):
    import trimesh

    path = Path(tmp) / name
    trimesh.creation.icosphere(subdivisions=subdivisions).export(path)  # binary PLY
    return path


def real_mesh_path(arg):
    path = Path(arg) if arg else DEFAULT_REAL_MESH
    if not path.is_absolute():
        path = REPO / path
    if path.exists():
        return path
    raise SystemExit(f"real mesh not found: {path}")


def log(message):
    print(message, file=sys.stderr, flush=True)
