"""``scatter check``: this tool's samples and pymeshlab's against the exact distribution.

Both samplers draw N points from the same world-space triangles. Each set is tested
against the exact surface distribution (counts in equal-area slabs along seven
directions, chi-square; surface moments, z-scores; Bonferroni-combined), and the two
sets against each other (two-sample chi-square on the same slabs).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from .errors import ScatterError
from .loaders import load_surface
from .surface import Surface, corners, doubled_areas

ALPHA = 1e-3
INSTALL_HINT = "scatter check needs pymeshlab and scipy: pip install 'scatter-cli[check]' (or: pip install pymeshlab scipy)"


def world_triangles(surface: Surface):
    """(F, 3, 3) float64 world-space corners and (F,) areas of every finite face."""
    tris, areas = [], []
    for inst in surface.instances:
        g = surface.geometries[inst.geometry]
        tri = corners(surface.world_vertices(inst), g.faces)
        with np.errstate(all="ignore"):
            a = 0.5 * doubled_areas(tri)
        ok = np.isfinite(a) & (a > 0)
        tris.append(tri[ok].reshape(-1, 3, 3))
        areas.append(a[ok])
    return np.concatenate(tris), np.concatenate(areas)


def scatter_sampler(surface, count, seed, poisson=False, radius=None):
    from .api import sample

    return sample(surface, count, seed=seed, precision="float64", poisson=poisson, radius=radius).points


def pymeshlab_sampler(tri, count, poisson=False, radius=None):
    """pymeshlab's Montecarlo (or Poisson-disk) points on the triangles ``tri`` (F, 3, 3)."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=tri.reshape(-1, 3), face_matrix=np.arange(3 * len(tri)).reshape(-1, 3)))
    if radius is not None:
        ms.generate_sampling_poisson_disk(radius=pymeshlab.PureValue(radius))
    elif poisson:
        ms.generate_sampling_poisson_disk(samplenum=count)
    else:
        ms.generate_sampling_montecarlo(samplenum=count)
    return np.asarray(ms.current_mesh().vertex_matrix(), dtype=np.float64)


def run_check(mesh, count=100_000, seed=0, poisson=False, radius=None, sampler=None, out=None) -> int:
    """Print the comparison table; return 0 when scatter passes, 1 when not.

    ``sampler(surface, count, seed)`` replaces this tool's sampler (the tests use it to
    show that a wrong sampler fails).
    """
    out = out or (lambda line: print(line, file=sys.stdout))
    try:
        import pymeshlab  # noqa: F401
        import scipy  # noqa: F401
    except ImportError:
        raise ScatterError(INSTALL_HINT) from None
    from . import uniformity

    surface = mesh if isinstance(mesh, Surface) else load_surface(mesh)
    tri, areas = world_triangles(surface)
    sampler = sampler or (lambda s, n, sd: scatter_sampler(s, n, sd, poisson, radius))
    t = time.perf_counter()
    ours = sampler(surface, count, seed)
    t_ours = time.perf_counter() - t
    t = time.perf_counter()
    theirs = pymeshlab_sampler(tri, count, poisson, radius)
    t_theirs = time.perf_counter() - t
    if len(ours) < 2 or len(theirs) < 2:
        raise ScatterError(f"{surface.source}: too few points to compare ({len(ours)} and {len(theirs)})")

    k = _slab_count(min(len(ours), len(theirs)))
    r_ours = uniformity.region_test(ours, tri, areas, k=k)
    r_theirs = uniformity.region_test(theirs, tri, areas, k=k)
    two = uniformity.two_sample_test(ours, theirs, tri, areas, k=k)
    ok_ours, ok_theirs = r_ours["p"] >= ALPHA, r_theirs["p"] >= ALPHA
    passed = ok_ours

    mode = "radius" if radius is not None else ("poisson" if poisson else "uniform")
    out(f"scatter check {surface.source} ({mode}; {len(tri):,} faces, area {areas.sum():.6g})")
    out(f"exact-distribution tests: 7 directions x {k} equal-area slabs (chi-square) and 9 moments "
        f"(z), Bonferroni-combined; alpha = {ALPHA:g}")
    rows = [
        ("points", f"{len(ours):,}", f"{len(theirs):,}"),
        ("time (s)", f"{t_ours:.3f}", f"{t_theirs:.3f}"),
        ("slab chi-square p (Bonf.)", _p(r_ours["p_slabs"]), _p(r_theirs["p_slabs"])),
        ("moments p (Bonf.)", _p(r_ours["p_moments"]), _p(r_theirs["p_moments"])),
        ("|z| of mean (max)", f"{np.max(np.abs(r_ours['z_mean'])):.2f}", f"{np.max(np.abs(r_theirs['z_mean'])):.2f}"),
        ("combined p", _p(r_ours["p"]), _p(r_theirs["p"])),
        ("consistent with exact", _yes(ok_ours), _yes(ok_theirs)),
    ]
    if poisson or radius is not None:
        rows += _spacing_rows(ours, theirs, areas.sum())
    width = max(len(r[0]) for r in rows)
    out(f"{'':{width}}  {'scatter':>14}  {'pymeshlab':>14}")
    for name, a, b in rows:
        out(f"{name:{width}}  {a:>14}  {b:>14}")
    out(f"two-sample test, scatter vs pymeshlab: p = {_p(two['p'])}"
        f"{' (the sets differ)' if two['p'] < ALPHA else ''}")
    verdict = "PASS" if passed else "FAIL"
    if passed and not ok_theirs:
        reason = "scatter is consistent with the exact distribution; pymeshlab is not"
    elif passed:
        reason = "scatter is consistent with the exact distribution, as is pymeshlab"
    else:
        reason = "scatter's points are NOT consistent with the exact distribution"
    out(f"{verdict}: {reason}")
    return 0 if passed else 1


def _slab_count(n):
    """Slabs per direction: 32, fewer for small samples so each expects >= 20 points."""
    return int(max(4, min(32, n // 20)))


def _spacing_rows(ours, theirs, area):
    from .spacing import spacing_stats

    a, b = spacing_stats(ours, area), spacing_stats(theirs, area)
    return [
        ("min distance", f"{a['d_min']:.6g}", f"{b['d_min']:.6g}"),
        ("relative radius rho", f"{a['rho']:.3f}", f"{b['rho']:.3f}"),
        ("mean NN distance", f"{a['mean_nn']:.6g}", f"{b['mean_nn']:.6g}"),
    ]


def _p(p):
    return "-" if p is None else (f"{p:.3g}" if p >= 1e-4 else f"{p:.1e}")


def _yes(ok):
    return "yes" if ok else "NO"
