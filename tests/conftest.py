"""Shared fixtures: small meshes built in code and the sample meshes of the repo."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples"


def triangles_mesh(tri):
    """A trimesh.Trimesh of separate triangles: tri (F, 3, 3) float64."""
    import trimesh

    tri = np.asarray(tri, dtype=np.float64)
    return trimesh.Trimesh(tri.reshape(-1, 3), np.arange(len(tri) * 3).reshape(-1, 3), process=False)


def spread_triangles(exponents, rng=None):
    """Right triangles with areas 10**e, one per exponent, each in its own plane z = index.

    Returns (tri (F, 3, 3), areas (F,)).
    """
    exponents = np.asarray(exponents, dtype=np.float64)
    legs = np.sqrt(2 * 10.0**exponents)
    tri = np.zeros((len(legs), 3, 3))
    tri[:, 1, 0] = legs
    tri[:, 2, 1] = legs
    tri[:, :, 2] = np.arange(len(legs))[:, None]
    return tri, 10.0**exponents


def run_scatter(*args, input=None, check=False, env=None, timeout=120):
    """Run the real command in a subprocess: returns CompletedProcess (bytes)."""
    full_env = dict(os.environ, **(env or {}))
    proc = subprocess.run(
        [sys.executable, "-m", "scatter_cli", *map(str, args)],
        input=input, capture_output=True, env=full_env, timeout=timeout,
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"scatter {' '.join(map(str, args))} failed: {proc.stderr.decode()}")
    return proc


@pytest.fixture
def sample_mesh():
    return lambda name: SAMPLES / name
