"""-a orient: unit quaternions that turn +Z onto the normal, spun uniformly about it."""

import numpy as np
import pytest
from scipy import stats

import scatter_cli
from scatter_cli.run.orient import align_z, orientations, spin_uniforms

from .conftest import SAMPLES

KS_LEVEL = 1e-3


def rotate(q, v):
    """Rotate v (3,) by unit quaternions q (m, 4) qx qy qz qw -> (m, 3), written out independently."""
    u, w = q[:, :3], q[:, 3:]
    t = 2.0 * np.cross(u, np.broadcast_to(v, u.shape))
    return v + w * t + np.cross(u, t)


def spin_angles(q, n):
    """(m,) angle in (-pi, pi] of q's image of +X about n, from a tangent fixed per normal."""
    e = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    ref = np.cross(n, e)
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    x = rotate(q, np.array([1.0, 0, 0]))
    return np.arctan2(np.einsum("ij,ij->i", np.cross(ref, x), n), np.einsum("ij,ij->i", ref, x))


def box():
    import trimesh

    return trimesh.creation.box((1.0, 2.0, 3.0))


@pytest.mark.parametrize("smooth", [False, True])
def test_unit_and_turns_z_onto_the_normal(smooth):
    names = ("smooth-normal" if smooth else "normal", "orient")
    s = scatter_cli.sample(SAMPLES / "koala.obj", 3000, attributes=names, seed=5, precision="float64")
    assert np.abs(np.linalg.norm(s.orient, axis=1) - 1).max() < 1e-6
    assert np.abs(rotate(s.orient, np.array([0, 0, 1.0])) - s.normal).max() < 1e-6


def test_alignment_holds_at_and_near_minus_z():
    d = np.array([0.0, 1e-300, 1e-12, 1e-8, 1e-4, 0.5])
    n = np.stack([np.sin(d), np.zeros_like(d), -np.cos(d)], axis=1)
    n = np.concatenate([n, -n, [[0, 0, -1.0], [0, 0, 1.0], [1.0, 0, 0]]])
    q = align_z(n)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1, atol=1e-15)
    assert np.abs(rotate(q, np.array([0, 0, 1.0])) - n).max() < 1e-12


def test_spin_is_uniform_and_a_fixed_angle_fails():
    s = scatter_cli.sample(box(), 4000, attributes=("normal", "orient"), seed=11, precision="float64")
    good = spin_angles(s.orient, s.normal)
    assert stats.kstest(good, stats.uniform(-np.pi, 2 * np.pi).cdf).pvalue > KS_LEVEL
    fixed = orientations(s.normal, np.full(len(s), 1.0))
    bad = spin_angles(fixed, s.normal)
    assert stats.kstest(bad, stats.uniform(-np.pi, 2 * np.pi).cdf).pvalue < KS_LEVEL


def test_spin_stream_is_uniform_and_seeded():
    u = spin_uniforms(3, 10**12, 20000)
    assert stats.kstest(u, "uniform").pvalue > KS_LEVEL
    assert not np.array_equal(u, spin_uniforms(4, 10**12, 20000))
    np.testing.assert_array_equal(u[5:9], spin_uniforms(3, 10**12 + 5, 4))


@pytest.mark.parametrize("extra", [{}, {"poisson": True}, {"method": "stratified"}])
def test_orient_moves_no_point(extra):
    plain = scatter_cli.sample(SAMPLES / "koala.obj", 1500, seed=2, **extra)
    with_orient = scatter_cli.sample(SAMPLES / "koala.obj", 1500, seed=2, attributes=("orient",), **extra)
    np.testing.assert_array_equal(plain.points, with_orient.points)


@pytest.mark.slow
@pytest.mark.parametrize("extra", [{}, {"poisson": True}])
def test_same_bytes_for_any_chunk_size_and_threads(extra, monkeypatch):
    ref = scatter_cli.sample(SAMPLES / "koala.obj", 1000, seed=8, attributes=("orient", "smooth-normal"), **extra)
    monkeypatch.setenv("SCATTER_THREADS", "3")
    for chunk in (7, 333):
        other = scatter_cli.sample(SAMPLES / "koala.obj", 1000, seed=8, attributes=("orient", "smooth-normal"),
                                   chunk_size=chunk, **extra)
        assert other.orient.tobytes() == ref.orient.tobytes()
    assert ref.layout()[1][0] == "normal" and ref.layout()[2][0] == "orient"
