"""The peers benchmarks/run.py measures, and whether they are installed.

Each method has load(path) -> handle and sample(handle, n, **kw) -> (n, 3) array;
reset(handle) runs untimed before every run. The command-line peers (CloudCompare, a
trimesh script) are commands built here and timed by the harness.
"""

import os
import shutil
import subprocess
import sys
import tempfile
from importlib import metadata
from pathlib import Path

import numpy as np

from harness import OURS_MODE_VAR, REPO, child_env, last_line

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
# Command-line peers
# ---------------------------------------------------------------------------

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
    _, kernels = probe_python("from scatter_cli.sampling.poisson import pairs; from scatter_cli.sampling import plan as sampling; "
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
        name = "mesh-scatter"
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
