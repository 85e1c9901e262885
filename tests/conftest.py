"""Shared fixtures: small meshes built in code and the sample meshes of the repo."""

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

from testkit.hardcheck import awkward_mesh, spread_triangles, triangles_mesh  # noqa: F401 (the tests' mesh builders)

# pytest keeps each test module as it rewrote its asserts (in tests/__pycache__) unless
# PYTHONDONTWRITEBYTECODE says not to, and rewriting them all again costs each test process
# some 5 CPU seconds: the test processes keep them whatever that says (the commands the
# tests start still follow it).
sys.dont_write_bytecode = False

# Property tests explore a fixed sequence of examples: a CI run is reproducible.
settings.register_profile("scatter", derandomize=True, database=None, deadline=None)
settings.load_profile("scatter")

# A user's shell starts a command with SIGINT at its default. A test run started in the
# background (``pytest &``) ignores SIGINT, and its children would inherit that; with
# Python's own handler here, each child starts with the default again.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples"


def pytest_configure(config):
    """Compile the package's bytecode once, before the test processes start (in the main
    process only, not in pytest-xdist's workers). An editable install leaves the checkout
    uncompiled, and where PYTHONDONTWRITEBYTECODE is set (as on CI's machines) every
    ``scatter`` the tests start (hundreds in a run) would compile the modules it imports
    again, about 0.08 s each time; a plain ``pip install .`` compiles them at install."""
    if not hasattr(config, "workerinput"):
        import compileall

        for package in ("scatter_cli", "testkit"):
            compileall.compile_dir(ROOT / package, quiet=2)  # (a read-only checkout: nothing said)


def pytest_collection_modifyitems(config, items):
    """The heavy tests first, in file order otherwise: pytest-xdist hands out tests in
    collection order, and a heavy test left for the end keeps one worker busy while the
    others have nothing left (CI keeps no timings from run to run to order them by)."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def user_env(env=None):
    """The environment of a user's shell: this one without PYTHONUNBUFFERED (so standard
    output is block-buffered, as in a terminal session) and without CI, plus ``env``.
    PYTHONPATH is kept: it is how the child finds this tree."""
    full = {k: v for k, v in os.environ.items() if k not in ("PYTHONUNBUFFERED", "CI")}
    full.update(env or {})
    return full


def numpy_baseline_env():
    """The environment that holds NumPy to its baseline code: every dispatched CPU feature
    this machine has (AVX2, AVX-512, ...) switched off with NPY_DISABLE_CPU_FEATURES; {}
    where NumPy dispatches nothing beyond its baseline here."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # NumPy 1
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    found = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    return {"NPY_DISABLE_CPU_FEATURES": " ".join(found)} if found else {}


def scatter_command(*args):
    """The argv that runs the real command: ``python -m scatter_cli ARGS``."""
    return [sys.executable, "-m", "scatter_cli", *map(str, args)]


def run_user(cmd, *, input=None, env=None, timeout=120, **kwargs):
    """subprocess.run as a user's shell would run ``cmd``: a user's environment, standard
    input closed unless ``input`` is given, output captured unless redirected."""
    if input is None:
        kwargs.setdefault("stdin", subprocess.DEVNULL)
    if "stdout" not in kwargs and "stderr" not in kwargs:
        kwargs["capture_output"] = True
    return subprocess.run(cmd, input=input, env=user_env(env), timeout=timeout, **kwargs)


def popen_user(cmd, *, env=None, **kwargs):
    """subprocess.Popen with a user's environment and standard input closed."""
    kwargs.setdefault("stdin", subprocess.DEVNULL)
    return subprocess.Popen(cmd, env=user_env(env), **kwargs)


def run_scatter(*args, input=None, check=False, env=None, timeout=120, stdout=None):
    """Run the real command in a subprocess: returns CompletedProcess (bytes).

    ``stdout``: a file to write standard output to instead of capturing it."""
    redirect = {} if stdout is None else {"stdout": stdout, "stderr": subprocess.PIPE}
    proc = run_user(scatter_command(*args), input=input, env=env, timeout=timeout, **redirect)
    if check and proc.returncode != 0:
        raise AssertionError(f"scatter {' '.join(map(str, args))} failed: {proc.stderr.decode()}")
    return proc


def scatter_in_process(*args, env=None, check=False):
    """``scatter ARGS`` through the command's entry point in this process, for checks of
    what a command says, returns and writes: a CompletedProcess like run_scatter's, its
    standard output and error captured as bytes; ``env``: variables set for the run (as
    SCATTER_THREADS), then put back. Each family of such checks keeps one case in a real
    subprocess (run_scatter) for what only a process shows."""
    import contextlib
    import io
    from unittest import mock

    from .batchtools import command_in_process

    out, err = io.BytesIO(), io.BytesIO()
    text_out = io.TextIOWrapper(out, encoding="utf-8", write_through=True)
    text_err = io.TextIOWrapper(err, encoding="utf-8", write_through=True)
    with mock.patch.dict(os.environ, env or {}), contextlib.redirect_stdout(text_out), \
            contextlib.redirect_stderr(text_err):
        code = command_in_process([str(a) for a in args])
    if check and code != 0:
        raise AssertionError(f"scatter {' '.join(map(str, args))} failed: {err.getvalue().decode()}")
    return subprocess.CompletedProcess(["scatter", *map(str, args)], code, out.getvalue(), err.getvalue())


@pytest.fixture
def sample_mesh():
    return lambda name: SAMPLES / name


def scaled_scene():
    """A trimesh.Scene: one icosphere placed three times (identity, non-uniform scale with a
    rotation, a mirror with translation) and a box once."""
    import trimesh

    rock = trimesh.creation.icosphere(subdivisions=1)
    box = trimesh.creation.box(extents=[1, 2, 0.5])
    rot = trimesh.transformations.rotation_matrix(0.7, [1, 1, 0])
    stretch = rot @ np.diag([3.0, 1.0, 0.25, 1.0])
    stretch[:3, 3] = [5, 0, 0]
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    mirror[:3, 3] = [0, 4, 0]
    scene = trimesh.Scene()
    scene.add_geometry(rock, geom_name="rock", node_name="rock_a")
    # Instances: more graph nodes that place the same geometry (no copy of its vertices).
    scene.graph.update(frame_to="rock_stretched", frame_from=scene.graph.base_frame, matrix=stretch, geometry="rock")
    scene.graph.update(frame_to="rock_mirrored", frame_from=scene.graph.base_frame, matrix=mirror, geometry="rock")
    box_at = np.eye(4)
    box_at[:3, 3] = [0, -4, 1]
    scene.add_geometry(box, geom_name="slab", node_name="slab", transform=box_at)
    return scene


def terrain(n=48, size=100.0, relief=5.0):
    """A trimesh.Trimesh: an open height field, as a terrain TIN is: an n x n grid of
    ``size`` on a side, rolling hills of ``relief``, faces turned up (+Z)."""
    import trimesh

    x, y = np.meshgrid(np.linspace(0.0, size, n), np.linspace(0.0, size, n))
    z = relief * np.sin(x / 10.0) * np.cos(y / 13.0)
    grid = np.arange(n * n).reshape(n, n)
    a, b, c, d = grid[:-1, :-1].ravel(), grid[:-1, 1:].ravel(), grid[1:, :-1].ravel(), grid[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, d], axis=1), np.stack([a, d, c], axis=1)])
    return trimesh.Trimesh(np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1), faces, process=False)
