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

from ..errors import ScatterError, ScatterUsageError
from ..loading.load import load_surface
from ..surface.model import Surface, corners, doubled_areas

ALPHA = 1e-3
MIN_COUNT = 2  # the fewest points a comparison takes
INSTALL_HINT = "scatter check needs pymeshlab and scipy: pip install pymeshlab scipy"


def world_triangles(surface: Surface):
    """(F, 3, 3) float64 world-space corners and (F,) areas of every face with a finite,
    non-zero area."""
    vertices, faces, areas = world_mesh(surface)
    return vertices[faces], areas


def world_mesh(surface: Surface):
    """The faces with a finite, non-zero area, in world space, as one mesh: vertices
    (V, 3) float64 (each instance's own), faces (F, 3) int32, areas (F,) float64."""
    vertices, faces, areas, base = [], [], [], 0
    for inst in surface.instances:
        g = surface.geometries[inst.geometry]
        v = surface.world_vertices(inst)
        with np.errstate(all="ignore"):
            a = 0.5 * doubled_areas(corners(v, g.faces))
        ok = np.isfinite(a) & (a > 0)
        vertices.append(v)
        faces.append(g.faces[ok] + base)
        areas.append(a[ok])
        base += len(v)
    return np.concatenate(vertices), np.concatenate(faces).astype(np.int32), np.concatenate(areas)


def scatter_sampler(surface, count, seed, poisson=False, radius=None):
    from ..api import sample

    return sample(surface, count, seed=seed, precision="float64", poisson=poisson, radius=radius).points


def pymeshlab_sampler(vertices, faces, count, poisson=False, radius=None):
    """pymeshlab's Montecarlo (or Poisson-disk) points on the mesh ``vertices`` (V, 3),
    ``faces`` (F, 3) (shared vertices: three times faster to hand over than a corner
    table)."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces))
    if radius is not None:
        ms.generate_sampling_poisson_disk(radius=pymeshlab.PureValue(radius))
    elif poisson:
        ms.generate_sampling_poisson_disk(samplenum=count)
    else:
        ms.generate_sampling_montecarlo(samplenum=count)
    return np.asarray(ms.current_mesh().vertex_matrix(), dtype=np.float64)


def run_check(mesh, count=100_000, seed=0, poisson=False, radius=None, sampler=None, out=None,
              progress=None) -> int:
    """Print the comparison table; return 0 when scatter passes, 1 when not.

    ``sampler(surface, count, seed)`` replaces this tool's sampler (the tests use it to
    show that a wrong sampler fails). ``progress(text)`` is told each stage; by default
    a line on standard error when it is a terminal.
    """
    out = out or (lambda line: print(line, file=sys.stdout))
    if count < MIN_COUNT:
        raise ScatterUsageError(f"-n must be at least {MIN_COUNT} (points of each sampler to compare), not {count}")
    try:
        import pymeshlab  # noqa: F401
        import scipy  # noqa: F401
    except ImportError:
        raise ScatterError(INSTALL_HINT) from None
    from ..stats import uniformity

    stage = progress or _Stage(sys.stderr)
    stage("loading")
    # Read as `scatter sample MESH` reads it (the fast readers where they apply: no
    # trimesh to import, a second or more).
    surface = mesh if isinstance(mesh, Surface) else load_surface(mesh, plain=True)
    vertices, faces, areas = world_mesh(surface)
    tri = vertices[faces]
    sampler = sampler or (lambda s, n, sd: scatter_sampler(s, n, sd, poisson, radius))
    stage("sampling with scatter")
    t = time.perf_counter()
    ours = sampler(surface, count, seed)
    t_ours = time.perf_counter() - t
    stage("sampling with pymeshlab")
    t = time.perf_counter()
    theirs = pymeshlab_sampler(vertices, faces, count, poisson, radius)
    t_theirs = time.perf_counter() - t
    if len(ours) < 2 or len(theirs) < 2:
        raise ScatterError(f"{surface.source}: too few points to compare ({len(ours)} and {len(theirs)})")

    k = _slab_count(min(len(ours), len(theirs)))
    regions = uniformity.Regions(tri, areas, k, progress=stage)
    stage("exact moments")
    moments = uniformity.ExactMoments(tri, areas)
    stage("testing")
    r_ours = uniformity.region_test(ours, tri, areas, regions=regions, moments=moments)
    r_theirs = uniformity.region_test(theirs, tri, areas, regions=regions, moments=moments)
    two = uniformity.two_sample_test(ours, theirs, tri, areas, regions=regions, moments=moments)
    stage(None)
    ok_ours, ok_theirs = r_ours["p"] >= ALPHA, r_theirs["p"] >= ALPHA
    differ = two["p"] < ALPHA
    worse_where_differ = differ and abs(two["worst"]["z_a"]) > abs(two["worst"]["z_b"])
    passed = ok_ours and not worse_where_differ

    mode = "radius" if radius is not None else ("poisson" if poisson else "uniform")
    out(f"scatter check {surface.source} ({mode}; {len(tri):,} faces, area {areas.sum():.6g})")
    out(f"exact-distribution tests: 7 directions x up to {k} equal-area slabs (chi-square) and 9 moments "
        f"(z), Bonferroni-combined; alpha = {ALPHA:g}")
    rows = [
        ("points", f"{len(ours):,}", f"{len(theirs):,}"),
        ("time (s)", f"{t_ours:.3f}", f"{t_theirs:.3f}"),
        ("slab chi-square p (Bonf.)", _p(r_ours["p_slabs"]), _p(r_theirs["p_slabs"])),
        ("moments p (Bonf.)", _p(r_ours["p_moments"]), _p(r_theirs["p_moments"])),
        ("|z| of mean (max)", f"{np.max(np.abs(r_ours['z_mean'])):.2f}", f"{np.max(np.abs(r_theirs['z_mean'])):.2f}"),
        ("points off the surface", f"{r_ours['off_surface']:,}", f"{r_theirs['off_surface']:,}"),
        ("combined p", _p(r_ours["p"]), _p(r_theirs["p"])),
        ("consistent with exact", _yes(ok_ours), _yes(ok_theirs)),
    ]
    if poisson or radius is not None:
        rows += _spacing_rows(ours, theirs, areas.sum())
    width = max(len(r[0]) for r in rows)
    out(f"{'':{width}}  {'scatter':>14}  {'pymeshlab':>14}")
    for name, a, b in rows:
        out(f"{name:{width}}  {a:>14}  {b:>14}")
    out(f"two-sample test, scatter vs pymeshlab: p = {_p(two['p'])}{' (the sets differ)' if differ else ''}")
    if differ:
        for line in _where_they_differ(two["worst"]):
            out(line)
    verdict = "PASS" if passed else "FAIL"
    if not ok_ours:
        reason = "scatter's points are NOT consistent with the exact distribution"
    elif worse_where_differ:
        reason = "scatter and pymeshlab differ, and where they differ scatter's count is the one off the exact area"
    elif differ:
        reason = "scatter is consistent with the exact distribution; the sets differ where pymeshlab's count is off"
    elif not ok_theirs:
        reason = "scatter is consistent with the exact distribution; pymeshlab is not"
    else:
        reason = "scatter is consistent with the exact distribution, as is pymeshlab"
    out(f"{verdict}: {reason}")
    return 0 if passed else 1


def _where_they_differ(w):
    """Lines saying where two samples differ most and which one fits the exact area there."""
    d = ", ".join(f"{c:.3g}" for c in w["direction"])
    fit = [("scatter", w["count_a"], w["expected_a"], w["z_a"]), ("pymeshlab", w["count_b"], w["expected_b"], w["z_b"])]
    lines = [f"  most different: the slab {w['low']:.9g} .. {w['high']:.9g} along ({d}), exact share {w['share']:.4g}"]
    for name, c, e, z in fit:
        lines.append(f"  {name}: {c:,} points there, {e:,.1f} expected from the exact area (z = {z:.2f})")
    better = min(fit, key=lambda f: abs(f[3]))[0]
    worse = max(fit, key=lambda f: abs(f[3]))[0]
    lines.append(f"  {better} fits the exact area there; {worse} does not")
    return lines


class _Stage:
    """``stage(text)``: ``check: text`` on a terminal's line, redrawn in place;
    ``stage(None)`` clears it. Nothing when ``stream`` is not a terminal."""

    def __init__(self, stream):
        self.stream = stream
        self.on = hasattr(stream, "isatty") and stream.isatty()
        self.width = 0

    def __call__(self, text):
        if not self.on:
            return
        line = "" if text is None else f"check: {text}..."
        self.stream.write("\r" + line.ljust(self.width) + ("\r" if text is None else ""))
        self.stream.flush()
        self.width = len(line)


def _slab_count(n):
    """Slabs per direction: 32, fewer for small samples so each expects >= 20 points."""
    return int(max(4, min(32, n // 20)))


def _spacing_rows(ours, theirs, area):
    from ..sampling.poisson.spacing import spacing_stats

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
