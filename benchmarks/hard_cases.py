"""Benchmark-scale hard cases (too heavy for CI): one command, prints results.

    PYTHONPATH=. python benchmarks/hard_cases.py [--faces 10000000] [--draws 100000000]

1. A mesh of --faces faces with areas log-uniform over 1e-12 .. 1e6: chi-square of the
   points per area decade (and per face, pooled) against the exact areas, at level 1e-3,
   beside an unweighted plan and a float32-CDF plan that must fail.
2. --draws points of the random method on the unit right triangle (the point is (b1, b2, 0)
   exactly) and on a triangle at 1e6: the number outside the triangle (exact TwoSum test
   on the first; exact rational check of a subset plus a float64 bound on the second).
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from testkit.benchargs import options  # noqa: E402

from scatter_cli.sampling.plan import SamplePlan  # noqa: E402
from scatter_cli.loading.load import load_surface  # noqa: E402
from testkit.hardcheck import (ALPHA, area_groups, exact_face_errors, pooled_pvalue,  # noqa: E402
                                  spread_triangles, triangles_mesh, two_sum_le_one)


def face_counts(plan, n, seed, block=1 << 22):
    """Points (n) per face (F,) of scatter's sampling plan."""
    counts = np.zeros(plan.surface.face_count)
    for a in range(0, n, block):
        counts += np.bincount(plan.draw(a, min(n, a + block), seed).face, minlength=len(counts))
    return counts


def unweighted_counts(areas, n, seed, block=1 << 22):
    """Broken on purpose: every face equally likely whatever its area."""
    rng = np.random.default_rng(seed)
    counts = np.zeros(len(areas))
    for a in range(0, n, block):
        counts += np.bincount(rng.integers(0, len(areas), min(block, n - a)), minlength=len(areas))
    return counts


def float32_cdf_counts(areas, n, seed, block=1 << 22):
    """Broken subtly: the area CDF accumulated in float32, so small faces round away."""
    cdf = np.cumsum(areas.astype(np.float32), dtype=np.float32).astype(np.float64)
    rng = np.random.default_rng(seed)
    counts = np.zeros(len(areas))
    for a in range(0, n, block):
        u = rng.random(min(block, n - a)) * cdf[-1]
        face = np.minimum(np.searchsorted(cdf, u, side="right"), len(areas) - 1)
        counts += np.bincount(face, minlength=len(areas))
    return counts


def wide(faces, n):
    t = time.perf_counter()
    exps = np.random.default_rng(5).uniform(-12, 6, faces)
    tri, areas = spread_triangles(exps)
    surface = load_surface(triangles_mesh(tri))
    del tri
    print(f"[1] {faces:,} faces, areas {areas.min():.3g} .. {areas.max():.3g}; built in {time.perf_counter() - t:.0f} s")
    samplers = (("scatter", lambda: face_counts(SamplePlan(surface), n, seed=6), True),
                ("unweighted", lambda: unweighted_counts(areas, n, seed=6), False),
                ("float32 CDF", lambda: float32_cdf_counts(areas, n, seed=6), False))
    for name, counts_of, must_pass in samplers:
        t = time.perf_counter()
        counts = counts_of()
        obs, exp = area_groups(areas, counts, n)
        p_dec = pooled_pvalue(obs, exp)
        p_face = pooled_pvalue(counts, n * areas / areas.sum())
        verdict = "pass" if min(p_dec, p_face) > ALPHA else "FAIL"
        ok = (verdict == "pass") == must_pass
        print(f"    {name:12s} {n:,} points: p(decades)={p_dec:.3g} p(faces, pooled)={p_face:.3g} -> {verdict}"
              f" ({'as expected' if ok else 'UNEXPECTED'}) [{time.perf_counter() - t:.0f} s]")


def draws(n):
    t = time.perf_counter()
    plan = SamplePlan(load_surface(triangles_mesh([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]])))
    outside = 0
    block = 1 << 23
    for a in range(0, n, block):
        p = plan.draw(a, min(n, a + block), seed=10).points
        outside += int(np.count_nonzero(~((p[:, 0] >= 0) & (p[:, 1] >= 0) & (p[:, 2] == 0) & two_sum_le_one(p[:, 0], p[:, 1]))))
    print(f"[2] unit triangle: {n:,} draws, {outside} outside the triangle (exact test) [{time.perf_counter() - t:.0f} s]")
    t = time.perf_counter()
    tri = np.array([[[1e6, 1e6, 1e6], [1e6 + 1, 1e6 + 0.3, 1e6], [1e6 + 0.2, 1e6 + 1, 1e6 + 0.5]]])
    plan = SamplePlan(load_surface(triangles_mesh(tri)))
    worst = 0.0
    sub = []
    for a in range(0, n, block):
        raw = plan.draw(a, min(n, a + block), seed=11, want_bary=True)
        worst = max(worst, float(-raw.bary.min()))
        sub.append(raw.points[:50])
    dist, over = exact_face_errors(np.concatenate(sub), np.repeat(tri, len(sub) * 50, axis=0), limit=2000)
    print(f"    triangle at 1e6: {n:,} draws, smallest barycentric {-worst:.3g}; exact check of 2000: "
          f"max plane distance {dist.max():.2f} and max overshoot {over.max():.2f} roundings [{time.perf_counter() - t:.0f} s]")


def main():
    args = options(faces=10_000_000, points=100_000_000, draws=100_000_000)
    wide(args.faces, args.points)
    draws(args.draws)


if __name__ == "__main__":
    main()
