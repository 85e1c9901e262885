"""Benchmark scatter against its peers, all measured in the same run.

    python benchmarks/run.py [--quick] [--out DIR] [--mesh REAL_MESH] [--only SECTIONS]

Sections:
  uniform  in-process sampling time and peak memory: trimesh, pymeshlab, Open3D,
           point-cloud-utils, ours, and the numpy "floor" (3N random doubles
           written into an (N, 3) float32 array).
  e2e      wall time of whole commands: `scatter sample`, CloudCompare, a
           five-line trimesh script, and interpreter start-up baselines.
  poisson  Poisson-disk sampling: time, points returned, and
           rho = d_min / sqrt(2A / (sqrt(3) N)).

Every in-process measurement runs in its own child process (this script with
--child): the child loads the mesh, does one warm-up run, then times back-to-back
runs and reports the median. Peak memory is the child's VmHWM during a run minus
its RSS after loading (the peak is reset through /proc/self/clear_refs before
each run).

"Ours" is, with --ours checkout (the default), the scatter_cli package of the
checkout this script lives in: the repository root is put first on PYTHONPATH
for every child and command, and ours is skipped unless scatter_cli (and, for
the CLI rows, scatter_cli.cli) load from this checkout. With --ours installed it
is whatever scatter_cli the interpreter imports from a neutral directory. Every
peer, and ours, is optional: when it is missing its rows are skipped with a note.

Writes results.json and results.md into --out (default: bench-out/ in the repo)
and prints the Markdown to stdout.
"""

import argparse
import datetime
import gc
import json
import math
import os
import platform
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from importlib import metadata
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
DEFAULT_REAL_MESH = REPO / "samples" / "skull.ply"
FALLBACK_REAL_MESH = Path("/work/shared/meshes/skull.ply")

CONFIGS = {
    "full": {
        "ico_subdivisions": 8,  # 1,310,720 faces
        "uniform_counts": [1_000_000, 10_000_000],
        "repeats": 3,
        "run_budget_s": 90,  # fewer timed runs when one run is slower than budget/repeats
        "e2e_small": 1_000,
        "e2e_big": 10_000_000,
        "e2e_repeats": 5,
        "poisson_ico_counts": [100_000],
        "poisson_real_counts": [10_000, 100_000],
        "cc_poisson_points": 1_000_000,
        "cc_poisson_step": 0.0094,
    },
    "quick": {
        "ico_subdivisions": 5,  # 20,480 faces
        "uniform_counts": [10_000, 100_000],
        "repeats": 3,
        "run_budget_s": 20,
        "e2e_small": 1_000,
        "e2e_big": 100_000,
        "e2e_repeats": 3,
        "poisson_ico_counts": [10_000],
        "poisson_real_counts": [10_000],
        "cc_poisson_points": 100_000,
        "cc_poisson_step": 0.0094 * math.sqrt(10),  # same rho as the full run at 10x fewer points
    },
}

CHILD_TIMEOUT_S = 1800
OURS_MODE_VAR = "SCATTER_BENCH_OURS"  # "checkout" or "installed"


# ---------------------------------------------------------------------------
# Methods measured in a child process. Each has load(path) -> handle and
# sample(handle, n, **kw) -> (n, 3) array; reset(handle) runs untimed before
# every run.
# ---------------------------------------------------------------------------

def load_trimesh(path):
    import trimesh

    return trimesh.load(path, force="mesh")


def sample_trimesh(mesh, n):
    import trimesh

    points, _ = trimesh.sample.sample_surface(mesh, n)
    return points


def sample_trimesh_even(mesh, n):
    import trimesh

    points, _ = trimesh.sample.sample_surface_even(mesh, n)
    return points


def load_pymeshlab(path):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    return ms


def reset_pymeshlab(ms):
    """Drop the meshes earlier runs added, and make the input current again."""
    # each sampling filter adds one mesh and makes it current; the input has id 0
    while ms.current_mesh_id() != 0:
        newest = ms.current_mesh_id()
        ms.delete_current_mesh()
        ms.set_current_mesh(max(i for i in range(newest) if ms.mesh_id_exists(i)))
    if ms.mesh_number() != 1:
        raise RuntimeError("could not drop the meshes of earlier pymeshlab runs")
    ms.set_current_mesh(0)


def sample_pymeshlab(ms, n):
    ms.generate_sampling_montecarlo(samplenum=n)
    return ms.current_mesh().vertex_matrix()


def sample_pymeshlab_poisson(ms, n):
    ms.generate_sampling_poisson_disk(samplenum=n)
    return ms.current_mesh().vertex_matrix()


def load_open3d(path):
    import open3d as o3d

    return o3d.io.read_triangle_mesh(str(path))


def sample_open3d(mesh, n):
    return np.asarray(mesh.sample_points_uniformly(number_of_points=n).points)


def sample_open3d_poisson(mesh, n):
    return np.asarray(mesh.sample_points_poisson_disk(number_of_points=n).points)


def load_pcu(path):
    import point_cloud_utils as pcu

    return pcu.load_mesh_vf(str(path))


def sample_pcu(vf, n):
    import point_cloud_utils as pcu

    v, f = vf
    face_ids, bary = pcu.sample_mesh_random(v, f, n)
    return pcu.interpolate_barycentric_coords(f, face_ids, bary, v)


def sample_pcu_poisson(vf, n):
    import point_cloud_utils as pcu

    v, f = vf
    face_ids, bary = pcu.sample_mesh_poisson_disk(v, f, n)
    return pcu.interpolate_barycentric_coords(f, face_ids, bary, v)


def load_ours(path):
    import scatter_cli

    if not hasattr(scatter_cli, "sample"):
        raise ImportError(f"scatter_cli at {scatter_cli.__file__} has no sample()")
    return load_trimesh(path)  # ours gets a preloaded trimesh.Trimesh


def load_ours_numpy(path):
    os.environ["SCATTER_NUMPY"] = "1"  # read when scatter_cli is imported: its NumPy path only
    return load_ours(path)


def sample_ours(mesh, n, **kw):
    import scatter_cli

    return np.asarray(scatter_cli.sample(mesh, count=n, **kw).points)


def load_floor(path):
    return np.random.default_rng()


def sample_floor(rng, n):
    out = np.empty((n, 3), dtype=np.float32)
    out.reshape(-1)[:] = rng.random(3 * n)
    return out


# name -> (load, sample, reset, label of what is called)
UNIFORM_METHODS = {
    "ours": (load_ours, sample_ours, None, "scatter_cli.sample(mesh, count=N)"),
    "ours-numpy": (load_ours_numpy, sample_ours, None, "the same, SCATTER_NUMPY=1 (no compiled kernels)"),
    "trimesh": (load_trimesh, sample_trimesh, None, "trimesh.sample.sample_surface"),
    "pymeshlab": (load_pymeshlab, sample_pymeshlab, reset_pymeshlab,
                  "pymeshlab generate_sampling_montecarlo(samplenum=N)"),
    "open3d": (load_open3d, sample_open3d, None, "open3d sample_points_uniformly"),
    "pcu": (load_pcu, sample_pcu, None,
            "point_cloud_utils sample_mesh_random + interpolate_barycentric_coords"),
    "floor": (load_floor, sample_floor, None, "numpy: 3N random doubles into (N,3) float32"),
}

POISSON_METHODS = {
    "ours": (load_ours, sample_ours, None, "scatter_cli.sample(mesh, count=N, poisson=True)"),
    "ours-numpy": (load_ours_numpy, sample_ours, None, "the same, SCATTER_NUMPY=1 (no compiled kernels)"),
    "pymeshlab": (load_pymeshlab, sample_pymeshlab_poisson, reset_pymeshlab,
                  "pymeshlab generate_sampling_poisson_disk(samplenum=N)"),
    "open3d": (load_open3d, sample_open3d_poisson, None, "open3d sample_points_poisson_disk"),
    "pcu": (load_pcu, sample_pcu_poisson, None, "point_cloud_utils sample_mesh_poisson_disk"),
    "trimesh": (load_trimesh, sample_trimesh_even, None, "trimesh.sample.sample_surface_even"),
}


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


def child_main(spec):
    table = POISSON_METHODS if spec["section"] == "poisson" else UNIFORM_METHODS
    load, sample, reset, _ = table[spec["method"]]
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
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(spec)]
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


GNU_TIME = "/usr/bin/time"


def wait_command(cmd, env, cwd):
    """Run cmd; return (wall seconds, peak RSS MB or None, exit code, stderr tail).

    The peak RSS comes from GNU time wrapped around the command: the rusage of
    a child forked from this (large) interpreter would report our own RSS."""
    with tempfile.NamedTemporaryFile("r") as rss, tempfile.TemporaryFile() as err:
        wrapped = cmd
        if os.path.exists(GNU_TIME):
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
# Availability of the peers
# ---------------------------------------------------------------------------

PY_MODULES = {"trimesh": "trimesh", "pymeshlab": "pymeshlab", "open3d": "open3d",
              "pcu": "point_cloud_utils", "scipy": "scipy"}
DIST_NAMES = {"trimesh": "trimesh", "pymeshlab": "pymeshlab", "open3d": "open3d",
              "pcu": "point-cloud-utils", "scipy": "scipy", "numpy": "numpy"}


def probe_python(code):
    """Run code in a child interpreter (from a neutral directory).

    Return (None, stdout) when it works, else (error line, stdout)."""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=child_env(), cwd=tempfile.gettempdir())
    error = None if proc.returncode == 0 else (last_line(proc.stderr) or "failed")
    return error, proc.stdout.strip()


def probe_ours_module(module, attribute=None):
    """None when `module` (and its attribute) loads from the right place, else a note."""
    code = f"import {module} as m; print(m.__file__)"
    if attribute:
        code += f"; m.{attribute}"
    error, where = probe_python(code)
    if error:
        return error
    checkout = os.environ.get(OURS_MODE_VAR, "checkout") == "checkout"
    if checkout and not Path(where).resolve().is_relative_to(REPO):
        return f"{module} is not in this checkout (it loads from {where}; try --ours installed)"
    return None


def find_scatter():
    candidate = Path(sys.executable).parent / "scatter"
    return str(candidate) if candidate.exists() else shutil.which("scatter")


def detect_tools():
    """name -> {"ok": bool, "version"/"note": str}."""
    tools = {}
    for name, module in PY_MODULES.items():
        error, _ = probe_python(f"import {module}")
        tools[name] = {"ok": error is None, "note": error, "version": dist_version(name)}
    tools["floor"] = {"ok": True, "version": np.__version__}

    error = probe_ours_module("scatter_cli", "sample")
    _, where = probe_python("import scatter_cli as m; print(m.__file__)")
    tools["ours"] = {"ok": error is None, "note": error, "version": dist_version("ours"),
                     "path": where}
    _, kernels = probe_python("from scatter_cli import pairs, sampling; "
                              "print(sampling._kernel is not None and pairs._kernel is not None)")
    if error is None and kernels.strip() != "True":
        tools["ours"]["note"] = "compiled kernels NOT built: NumPy path only"
    tools["ours-numpy"] = dict(tools["ours"], note="SCATTER_NUMPY=1")

    scatter = find_scatter()
    cli_error = probe_ours_module("scatter_cli.cli")
    if scatter is None:
        tools["ours_cli"] = {"ok": False, "note": "`scatter` not on PATH"}
    elif cli_error:
        tools["ours_cli"] = {"ok": False, "note": cli_error}
    else:
        proc = subprocess.run([scatter, "sample", "--help"], capture_output=True, text=True,
                              env=child_env(), cwd=tempfile.gettempdir())
        tools["ours_cli"] = {"ok": proc.returncode == 0, "path": scatter,
                             "note": None if proc.returncode == 0 else
                             "`scatter sample --help` failed: " + last_line(proc.stderr)}

    cc = shutil.which("CloudCompare")
    tools["cloudcompare"] = {"ok": cc is not None, "path": cc, "version": debian_version("cloudcompare"),
                             "note": None if cc else "CloudCompare not on PATH"}
    return tools


def dist_version(name):
    if name == "ours":
        name = "scatter-cli"
    try:
        return metadata.version(DIST_NAMES.get(name, name))
    except metadata.PackageNotFoundError:
        return None


def debian_version(package):
    try:
        proc = subprocess.run(["dpkg-query", "-W", "-f=${Version}", package],
                              capture_output=True, text=True)
    except OSError:
        return None
    return proc.stdout.strip() or None


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
    if arg is None and FALLBACK_REAL_MESH.exists():
        return FALLBACK_REAL_MESH
    raise SystemExit(f"real mesh not found: {path}")


# ---------------------------------------------------------------------------
# Sections
# ---------------------------------------------------------------------------

def log(message):
    print(message, file=sys.stderr, flush=True)


def measure_in_children(section, methods, tools, mesh, n, cfg, kw_by_method=None):
    rows = []
    for name, (_, _, _, label) in methods.items():
        row = {"section": section, "mesh": mesh["name"], "n": n, "method": name, "call": label}
        if not tools[name]["ok"]:
            row["skipped"] = tools[name]["note"] or "not installed"
        else:
            spec = {"section": section, "method": name, "mesh": mesh["path"], "n": n,
                    "repeats": cfg["repeats"], "run_budget_s": cfg["run_budget_s"],
                    "area": mesh["area"], "kw": (kw_by_method or {}).get(name, {})}
            row.update(run_child(spec))
        log(f"  {section} {mesh['name']} N={n:,} {name}: {brief(row)}")
        rows.append(row)
    return rows


def brief(row):
    if "skipped" in row:
        return "skipped (" + row["skipped"] + ")"
    if "error" in row:
        return "error: " + row["error"]
    return f"{row['median_s']:.3f} s x{row['runs']}"


def section_uniform(cfg, meshes, tools):
    rows = []
    for mesh in meshes:
        for n in cfg["uniform_counts"]:
            rows += measure_in_children("uniform", UNIFORM_METHODS, tools, mesh, n, cfg)
    return rows


def cloudcompare_cmd(mesh_path, n, out_file, extra=()):
    return ["CloudCompare", "-SILENT", "-NO_TIMESTAMP", "-AUTO_SAVE", "OFF",
            "-O", str(mesh_path), "-SAMPLE_MESH", "POINTS", str(n), *extra,
            "-C_EXPORT_FMT", "PLY", "-SAVE_CLOUDS", "FILE", str(out_file)]


def cloudcompare_env(tmp):
    env = child_env()
    runtime = Path(tmp) / "xdg-runtime"
    runtime.mkdir(mode=0o700, exist_ok=True)
    env["XDG_RUNTIME_DIR"] = str(runtime)  # silences a Qt warning
    return env


def trimesh_script(mesh_path, n, out_file):
    return ("import trimesh; m = trimesh.load(%r); "
            "p, _ = trimesh.sample.sample_surface(m, %d); "
            "trimesh.PointCloud(p).export(%r)" % (str(mesh_path), n, str(out_file)))


def section_e2e(cfg, small, big, tools, tmp):
    rows = []
    py = sys.executable
    repeats = cfg["e2e_repeats"]
    for mesh, n in [(small, cfg["e2e_small"]), (big, cfg["e2e_big"])]:
        out = Path(tmp) / "e2e-out.ply"
        jobs = [
            ("ours", "ours_cli", [find_scatter() or "scatter", "sample", mesh["path"], "-n", str(n),
                                  "-o", str(out)], {"cwd": tmp}),
            ("cloudcompare", "cloudcompare", cloudcompare_cmd(mesh["path"], n, out),
             {"env": cloudcompare_env(tmp), "cwd": tmp}),
            ("trimesh script", "trimesh", [py, "-c", trimesh_script(mesh["path"], n, out)],
             {"cwd": tmp}),
        ]
        for name, tool, cmd, opts in jobs:
            row = {"section": "e2e", "mesh": mesh["name"], "n": n, "method": name,
                   "call": shlex.join(cmd)}
            if tools[tool]["ok"]:
                row.update(time_command(cmd, repeats, out_file=out, **opts))
            else:
                row["skipped"] = tools[tool]["note"] or "not installed"
            log(f"  e2e {mesh['name']} N={n:,} {name}: {brief(row)}")
            rows.append(row)
    for name, code in [("python -c pass", "pass"), ("python -c 'import numpy'", "import numpy"),
                       ("python -c 'import trimesh'", "import trimesh")]:
        cmd = [py, "-c", code]
        row = {"section": "e2e", "mesh": "-", "n": 0, "method": name, "call": shlex.join(cmd)}
        row.update(time_command(cmd, repeats, cwd=tmp))
        log(f"  e2e {name}: {brief(row)}")
        rows.append(row)
    return rows


def section_poisson(cfg, ico, real, tools, tmp):
    """Poisson-disk peers, plus ours (skipped until scatter_cli supports poisson/radius)."""
    rows = []
    for mesh, counts in [(ico, cfg["poisson_ico_counts"]), (real, cfg["poisson_real_counts"])]:
        for n in counts:
            rows += measure_in_children("poisson", POISSON_METHODS, tools, mesh, n, cfg,
                                        kw_by_method={"ours": {"poisson": True}, "ours-numpy": {"poisson": True}})
    step = cfg["cc_poisson_step"]
    rows.append(ours_radius_row(cfg, ico, step, tools))
    rows.append(cloudcompare_poisson_row(cfg, ico, step, tools, tmp))
    rows += ours_poisson_cli_rows(cfg, ico, step, tools, tmp)
    return rows


def ours_radius_row(cfg, mesh, radius, tools):
    """API with radius=R, R the CloudCompare spatial step, so the two compare."""
    row = {"section": "poisson", "mesh": mesh["name"], "n": 0, "method": f"ours radius={radius:.4g}",
           "call": f"scatter_cli.sample(mesh, radius={radius:.4g})"}
    if not tools["ours"]["ok"]:
        row["skipped"] = tools["ours"]["note"]
    else:
        # the child times count=0 plus radius: n is only passed through as count
        spec = {"section": "poisson", "method": "ours", "mesh": mesh["path"], "n": None,
                "repeats": cfg["repeats"], "run_budget_s": cfg["run_budget_s"],
                "area": mesh["area"], "kw": {"radius": radius}}
        row.update(run_child(spec))
    log(f"  poisson {mesh['name']} {row['method']}: {brief(row)}")
    return row


def cloudcompare_poisson_row(cfg, mesh, step, tools, tmp):
    n = cfg["cc_poisson_points"]
    out = Path(tmp) / "cc-poisson.ply"
    cmd = cloudcompare_cmd(mesh["path"], n, out, extra=("-SS", "SPATIAL", f"{step:.6g}"))
    row = {"section": "poisson", "mesh": mesh["name"], "n": n,
           "method": f"cloudcompare SS SPATIAL {step:.4g}", "call": shlex.join(cmd)}
    if not tools["cloudcompare"]["ok"]:
        row["skipped"] = tools["cloudcompare"]["note"]
    else:
        row.update(time_command(cmd, max(1, cfg["repeats"]), out_file=out,
                                env=cloudcompare_env(tmp), cwd=tmp))
        if "error" not in row:
            row.update(spacing_stats(read_ply_points(out), mesh["area"]))
    log(f"  poisson {mesh['name']} {row['method']}: {brief(row)}")
    return row


def ours_poisson_cli_rows(cfg, mesh, step, tools, tmp):
    rows = []
    out = Path(tmp) / "ours-poisson.ply"
    scatter = find_scatter() or "scatter"
    n = cfg["poisson_ico_counts"][0]
    variants = [("ours CLI --poisson", [scatter, "sample", mesh["path"], "--poisson", "-n", str(n),
                                        "-o", str(out)]),
                ("ours CLI --radius", [scatter, "sample", mesh["path"], "--radius", f"{step:.6g}",
                                       "-o", str(out)])]
    for name, cmd in variants:
        row = {"section": "poisson", "mesh": mesh["name"], "n": n if "--poisson" in cmd else 0,
               "method": name, "call": shlex.join(cmd)}
        if not tools["ours_cli"]["ok"]:
            row["skipped"] = tools["ours_cli"]["note"]
        else:
            row.update(time_command(cmd, cfg["repeats"], out_file=out, cwd=tmp))
            if "error" not in row:
                row.update(spacing_stats(read_ply_points(out), mesh["area"]))
        log(f"  poisson {mesh['name']} {name}: {brief(row)}")
        rows.append(row)
    return rows


def read_ply_points(path):
    import trimesh

    return np.asarray(trimesh.load(path).vertices, dtype=np.float64)


# ---------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------

def fmt_s(seconds):
    if seconds is None:
        return "-"
    return f"{seconds * 1000:.1f} ms" if seconds < 1 else f"{seconds:.2f} s"


def fmt_mb(mb):
    return f"{mb:.0f}" if mb is not None else "-"


def fmt_count(count):
    return f"{count:,}" if count is not None else "-"


def ratio(a, b):
    if a is None or b is None or b == 0:
        return "-"
    return f"{a / b:.2f}x"


def find_row(rows, mesh, n, method):
    for row in rows:
        if row["mesh"] == mesh and row["n"] == n and row["method"] == method and "median_s" in row:
            return row
    return None


def status_cell(row):
    return "skipped: " + row["skipped"] if "skipped" in row else "error: " + row.get("error", "?")


def uniform_table(rows, meshes):
    out = ["| mesh | N | method | median | runs | first run | / ours | / floor | "
           "peak extra MB | out MB (f32) + mesh MB |",
           "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
    mesh_mb = {m["name"]: m["mesh_arrays_mb"] for m in meshes}
    for row in rows:
        if "median_s" not in row:
            out.append(f"| {row['mesh']} | {row['n']:,} | {row['method']} | {status_cell(row)} "
                       "| | | | | | |")
            continue
        ours = find_row(rows, row["mesh"], row["n"], "ours")
        floor = find_row(rows, row["mesh"], row["n"], "floor")
        target = row["n"] * 12 / 2**20 + mesh_mb[row["mesh"]]
        out.append(f"| {row['mesh']} | {row['n']:,} | {row['method']} | {fmt_s(row['median_s'])} "
                   f"| {row['runs']} | {fmt_s(row['first_s'])} "
                   f"| {ratio(row['median_s'], ours and ours['median_s'])} "
                   f"| {ratio(row['median_s'], floor and floor['median_s'])} "
                   f"| {row['peak_extra_mb']:.0f} | {target:.0f} |")
    return out


def e2e_table(rows):
    out = ["| mesh | N | command | median wall | runs | / ours | peak RSS MB | points written |",
           "|---|---:|---|---:|---:|---:|---:|---:|"]
    for row in rows:
        n = f"{row['n']:,}" if row["n"] else "-"
        if "median_s" not in row:
            out.append(f"| {row['mesh']} | {n} | {row['method']} | {status_cell(row)} | | | | |")
            continue
        ours = find_row(rows, row["mesh"], row["n"], "ours")
        out.append(f"| {row['mesh']} | {n} | {row['method']} | {fmt_s(row['median_s'])} "
                   f"| {row['runs']} | {ratio(row['median_s'], ours and ours['median_s'])} "
                   f"| {fmt_mb(row['peak_rss_mb'])} | {fmt_count(row.get('count'))} |")
    return out


def poisson_table(rows):
    out = ["| mesh | N asked | method | median | runs | points returned | rho | peak extra MB |",
           "|---|---:|---|---:|---:|---:|---:|---:|"]
    for row in rows:
        n = f"{row['n']:,}" if row["n"] else "-"
        if "median_s" not in row:
            out.append(f"| {row['mesh']} | {n} | {row['method']} | {status_cell(row)} | | | | |")
            continue
        peak = row.get("peak_extra_mb", row.get("peak_rss_mb"))
        rho_cell = f"{row['rho']:.3f}" if row.get("rho") is not None else "-"
        if row.get("warning"):
            rho_cell += " (" + row["warning"] + ")"
        out.append(f"| {row['mesh']} | {n} | {row['method']} | {fmt_s(row['median_s'])} "
                   f"| {row['runs']} | {fmt_count(row.get('count'))} | {rho_cell} "
                   f"| {fmt_mb(peak)} |")
    return out


def markdown_report(report):
    lines = [f"# scatter benchmarks vs peers ({report['config_name']})", "",
             f"- date: {report['date']}",
             f"- command: `{report['command']}`",
             f"- machine: {report['machine']}",
             f"- all figures from this one run; medians of back-to-back warm runs after one "
             "warm-up run (\"first run\" is the warm-up)", ""]
    lines += ["## Tools", "", "| tool | available | version | note |", "|---|---|---|---|"]
    for name, tool in report["tools"].items():
        lines.append(f"| {name} | {'yes' if tool['ok'] else 'no'} | {tool.get('version') or '-'} "
                     f"| {tool.get('note') or ''} |")
    lines += ["", "## Meshes", "", "| name | faces | vertices | area | mesh arrays MB | path |",
              "|---|---:|---:|---:|---:|---|"]
    for m in report["meshes"]:
        lines.append(f"| {m['name']} | {m['faces']:,} | {m['vertices']:,} | {m['area']:.4g} "
                     f"| {m['mesh_arrays_mb']:.1f} | {m['path']} |")
    sections = report["sections"]
    if "uniform" in sections:
        lines += ["", "## a. Uniform sampling, in-process (mesh loaded once, not timed)", "",
                  "Times to get an (N, 3) array. `/ ours` and `/ floor`: this method's median "
                  "divided by ours / the floor (above 1 = slower). Peak extra MB: peak RSS during "
                  "a run minus RSS after loading, max over runs. Last column: the memory target, "
                  "an (N, 3) float32 output plus the mesh's vertex and face arrays.", ""]
        lines += uniform_table(sections["uniform"], report["meshes"])
    if "e2e" in sections:
        lines += ["", "## b. End to end, whole commands (wall time)", "",
                  "Output written to a temp dir; `points written` read back from the PLY header.",
                  ""]
        lines += e2e_table(sections["e2e"])
    if "poisson" in sections:
        lines += ["", "## c. Poisson-disk sampling", "",
                  "rho = d_min / sqrt(2A / (sqrt(3) N)), N = points returned, A = mesh area "
                  "(1 = hexagonal packing). CloudCompare and CLI rows are whole commands "
                  "(wall time, peak RSS of the process).", ""]
        lines += poisson_table(sections["poisson"])
    lines += ["", "## Calls", ""]
    seen = set()
    for rows in sections.values():
        for row in rows:
            key = (row["section"], row["method"], row["call"] if row["section"] != "e2e" else "")
            if row["section"] != "e2e" and key not in seen:
                seen.add(key)
                lines.append(f"- {row['section']} / {row['method']}: `{row['call']}`")
    for row in sections.get("e2e", []):
        lines.append(f"- e2e / {row['method']} N={row['n']}: `{row['call']}`")
    return "\n".join(lines) + "\n"


def machine_summary():
    return (f"{os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}, "
            f"numpy {np.__version__}")


# ---------------------------------------------------------------------------
# Main
# ---------------------------------------------------------------------------

def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small, fast configuration")
    parser.add_argument("--out", default=str(REPO / "bench-out"), help="directory for JSON + Markdown")
    parser.add_argument("--mesh", default=None,
                        help="real mesh (default samples/skull.ply, else /work/shared/meshes/skull.ply)")
    parser.add_argument("--ours", choices=["checkout", "installed"], default="checkout",
                        help="measure scatter_cli from this checkout (default) or as installed")
    parser.add_argument("--only", default="uniform,e2e,poisson",
                        help="comma-separated sections to run")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv=None):
    args = parse_args(argv)
    if args.child:
        print(json.dumps(child_main(json.loads(args.child))))
        return
    os.environ["NUMPY_MADVISE_HUGEPAGE"] = "0"
    os.environ[OURS_MODE_VAR] = args.ours
    config_name = "quick" if args.quick else "full"
    cfg = CONFIGS[config_name]
    only = set(args.only.split(","))
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)

    tools = detect_tools()
    for name, tool in tools.items():
        log(f"{name}: {'ok' if tool['ok'] else 'MISSING'} {tool.get('version') or ''} "
            f"{tool.get('note') or ''}")

    with tempfile.TemporaryDirectory(prefix="scatter-bench-") as tmp:
        sub = cfg["ico_subdivisions"]
        ico = mesh_info(make_icosphere(tmp, sub, f"icosphere{sub}.ply"))
        ico["name"] = f"icosphere{sub}"
        small = mesh_info(make_icosphere(tmp, 3, "icosphere3.ply"))
        small["name"] = "icosphere3"
        real = mesh_info(real_mesh_path(args.mesh))
        real["name"] = Path(real["path"]).stem
        meshes = [ico, real, small]

        sections = {}
        if "uniform" in only:
            log("== uniform")
            sections["uniform"] = section_uniform(cfg, [ico, real], tools)
        if "e2e" in only:
            log("== e2e")
            sections["e2e"] = section_e2e(cfg, small, ico, tools, tmp)
        if "poisson" in only:
            log("== poisson")
            sections["poisson"] = section_poisson(cfg, ico, real, tools, tmp)

    report = {
        "config_name": config_name,
        "config": cfg,
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "command": shlex.join(["python", "benchmarks/run.py", *(argv or sys.argv[1:])]),
        "machine": machine_summary(),
        "tools": tools,
        "meshes": meshes,
        "sections": sections,
    }
    (out_dir / "results.json").write_text(json.dumps(report, indent=2) + "\n")
    markdown = markdown_report(report)
    (out_dir / "results.md").write_text(markdown)
    print(markdown)


if __name__ == "__main__":
    main()
