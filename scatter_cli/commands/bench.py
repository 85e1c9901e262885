"""``scatter bench``: what accuracy costs in time.

For each mesh, each sampler variant (method x warp x arithmetic precision, and the
peers that are installed) and each count, the points estimate three surface
integrals whose exact values follow from the triangles:

- ``centroid``: the area-weighted centroid c (closed form); error |c^ - c| / L, L the
  bounding-box diagonal;
- ``second``: the central second moments C = E[(x - c)(x - c)^T] (closed form);
  error |C^ - C|_F / |C|_F, C^ the mean of (x - c)(x - c)^T over the points;
- ``smooth``: the mean of :func:`surface_measures.smooth_test_function` (a Gauss rule of order 8
  per triangle, exact to degree 15); error |f^ - f| / sqrt(E f^2).

``error`` is the root mean square of the three. Each (variant, count) is run with
``repeats`` consecutive seeds: errors are the RMS over the seeds (so the same seed gives
the same errors) and the time is the median of the runs. The estimates are accumulated
in float64 whatever the sampler's precision. Writes ``bench.md``, ``bench.json`` and
``bench.png`` to the output directory.
"""

from __future__ import annotations

import json
import math
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ScatterError
from ..surface.model import corners

INSTALL_HINT = "the bench plot needs matplotlib: pip install matplotlib"
SAMPLES_DIR = Path(__file__).resolve().parents[2] / "samples"
FAR_OFFSET = 1e6
SMOOTH_ORDER = 8
FULL_COUNTS = [int(round(10 ** (k / 2))) for k in range(4, 15)]  # 1e2 .. 1e7, half decades
QUICK_COUNTS = [int(round(10 ** (k / 2))) for k in range(4, 9)]  # 1e2 .. 1e4
ERRORS = ("centroid", "second", "smooth")
POISSON_COUNTS, POISSON_COUNTS_QUICK = [10_000, 100_000], [1_000]


# ---------------------------------------------------------------------------
# Meshes and exact values


def icosphere(subdivisions=3, offset=0.0):
    """A unit icosphere (trimesh.Trimesh), translated by ``offset`` along every axis."""
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    if offset:
        mesh.apply_translation([offset] * 3)
    return mesh


def default_meshes(quick=False):
    """[(name, mesh or path)]: the icosphere, the skull sample (when present) and the
    icosphere far from the origin."""
    sub = 3 if quick else 4
    meshes = [("icosphere", icosphere(sub))]
    skull = SAMPLES_DIR / "skull.ply"
    if skull.exists():
        meshes.append(("skull", str(skull)))
    meshes.append((f"icosphere+{FAR_OFFSET:.0e}", icosphere(sub, FAR_OFFSET)))
    return meshes


@dataclass
class Exact:
    """Exact surface quantities of one mesh, and the scales the errors are relative to."""

    centroid: np.ndarray  # (3,)
    second: np.ndarray  # (3, 3) central second moments
    smooth: float  # mean of the smooth test function
    smooth_rms: float  # sqrt(E f^2)
    bounds: np.ndarray  # (2, 3)
    diagonal: float
    area: float


def exact_values(tri, areas, order=SMOOTH_ORDER) -> Exact:
    """Exact integrals over triangles ``tri`` (F, 3, 3) with areas ``areas`` (F,)."""
    from ..stats import measures as surface_measures

    flat = tri.reshape(-1, 3)
    bounds = np.stack([flat.min(0), flat.max(0)])
    centroid, second = surface_measures.surface_covariance(tri, areas)
    area = float(areas.sum())
    f = surface_measures.surface_integral(lambda p: _smooth_and_square(p, bounds), tri, areas, order=order) / area
    return Exact(centroid, second, float(f[0]), math.sqrt(float(f[1])), bounds,
                 float(np.linalg.norm(bounds[1] - bounds[0])), area)


def _smooth_and_square(p, bounds):
    from ..stats.measures import smooth_test_function

    v = smooth_test_function(p, bounds)
    return np.column_stack([v, v * v])


def errors(points, exact: Exact):
    """Relative errors (dict of floats) of the integrals estimated from points (n, 3)."""
    from ..stats.measures import smooth_test_function

    x = np.asarray(points, dtype=np.float64)
    d = x - exact.centroid
    mean_d = d.mean(axis=0)
    second = d.T @ d / len(d)
    f = float(smooth_test_function(x, exact.bounds).mean())
    out = {
        "centroid": float(np.linalg.norm(mean_d) / exact.diagonal),
        "second": float(np.linalg.norm(second - exact.second) / np.linalg.norm(exact.second)),
        "smooth": abs(f - exact.smooth) / exact.smooth_rms,
    }
    out["error"] = math.sqrt(sum(out[k] ** 2 for k in ERRORS) / len(ERRORS))
    return out


# ---------------------------------------------------------------------------
# Samplers: each is sampler(count, seed) -> points (n, 3)


@dataclass
class Variant:
    name: str
    kind: str  # "method", "warp", "precision" or "peer"
    run: object
    note: str = ""
    seeded: bool = True


def _place_float32(plan, used, b):
    """Points from (used, b) in float32 arithmetic: float32 corners and weights,
    v0 + b1 (v1 - v0) + b2 (v2 - v0) rounded at each step. (n, 3) float32."""
    from ..sampling.plan import interpolate_corners

    part = plan.parts[0]
    tri32 = plan.__dict__.get("_tri32")
    if tri32 is None:
        tri = part.tri if part.tri is not None else corners(part.geometry.vertices, part.geometry.faces)
        tri32 = plan._tri32 = tri.astype(np.float32)
    face = used if part.faces is None else part.faces[used]
    t = np.take(tri32, face, axis=0).T
    b1, b2 = b[:, 0].astype(np.float32), b[:, 1].astype(np.float32)
    points = np.empty((len(used), 3), dtype=np.float32)
    interpolate_corners(t, b1, b2, points)
    return points


def our_sampler(surface, method="random", warp="sqrt", precision="float64"):
    """This tool's method with any warp, in float64 (as ``scatter sample``) or float32
    arithmetic; the sample plan is rebuilt on every call, as a command would."""
    from ..sampling.methods import DRAWS
    from ..sampling.plan import DEFAULT_CHUNK, SamplePlan, run_chunks
    from ..sampling.warps import WARPS

    draws, warp_fn = DRAWS[method], WARPS[warp][0]
    if precision == "float32" and (len(surface.instances) != 1 or surface.instances[0].matrix is not None):
        raise ScatterError("float32 arithmetic is benchmarked on single-object meshes only")
    dtype = np.float32 if precision == "float32" else np.float64

    def run(count, seed):
        plan = SamplePlan(surface)

        def job(a, b):
            used, bary = draws(plan, count, a, b, seed, warp_fn)
            if precision == "float32":
                return a, _place_float32(plan, used, bary)
            return a, plan.place(a, used, bary).points

        out = np.empty((count, 3), dtype=dtype)
        for a, pts in run_chunks(job, 0, count, DEFAULT_CHUNK):
            out[a : a + len(pts)] = pts
        return out

    return run


def trimesh_sampler(tri):
    import trimesh

    mesh = trimesh.Trimesh(tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3), process=False)

    def run(count, seed):
        return trimesh.sample.sample_surface(mesh, count, seed=seed)[0]

    return run


def pymeshlab_sampler(tri, kind):
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=tri.reshape(-1, 3), face_matrix=np.arange(3 * len(tri)).reshape(-1, 3)))

    def run(count, seed):
        ms.set_current_mesh(0)
        if kind == "montecarlo":
            ms.generate_sampling_montecarlo(samplenum=count)
        else:
            ms.generate_sampling_stratified_triangle(samplenum=count)
        points = ms.current_mesh().vertex_matrix()
        ms.delete_current_mesh()
        return points

    return run


def variants(surface, tri, notes):
    """The sampler variants for one mesh: [Variant]."""
    out = []
    for method in ("random", "stratified", "sobol"):
        for precision in ("float64", "float32"):
            kind = "method" if precision == "float64" else "precision"
            try:
                run = our_sampler(surface, method, "sqrt", precision)
            except ScatterError as exc:
                notes.append(f"{method}/{precision}: {exc}")
                continue
            out.append(Variant(f"{method}/sqrt/{precision[-2:]}", kind, run))
    for warp in ("fold", "lowdist", "naive"):
        note = "biased on purpose" if warp == "naive" else ""
        out.append(Variant(f"sobol/{warp}/64", "warp", our_sampler(surface, "sobol", warp), note))
    try:
        out.append(Variant("trimesh", "peer", trimesh_sampler(tri), "trimesh.sample.sample_surface (fold warp)"))
    except ImportError:
        notes.append("trimesh peer skipped: trimesh not importable")
    try:
        import pymeshlab  # noqa: F401

        out.append(Variant("pymeshlab/montecarlo", "peer", pymeshlab_sampler(tri, "montecarlo"),
                           "no seed parameter: repeats are not repeatable", seeded=False))
        out.append(Variant("pymeshlab/stratified", "peer", pymeshlab_sampler(tri, "stratified"),
                           "'Similar Triangle', deterministic; count approximate", seeded=False))
    except ImportError:
        notes.append("pymeshlab peers skipped: pip install pymeshlab")
    return out


# ---------------------------------------------------------------------------
# The runs


@dataclass
class Result:
    mesh: str
    variant: str
    kind: str
    rows: list = field(default_factory=list)  # dicts: count, n, time, errors...
    slope: dict = field(default_factory=dict)
    note: str = ""


def repeats_for(count, repeats):
    """Fewer repeats for the largest counts, where one run already takes seconds."""
    return max(3, repeats // 2) if count >= 10**6 else repeats


def measure(variant: Variant, exact: Exact, counts, repeats, seed) -> list:
    """One row per count: median time and RMS errors over ``repeats`` seeds."""
    variant.run(min(counts), seed)  # warm-up: imports, caches
    rows = []
    for count in counts:
        times, errs, n = [], [], 0
        for r in range(repeats_for(count, repeats)):
            t = time.perf_counter()
            pts = variant.run(count, seed + r)
            times.append(time.perf_counter() - t)
            n = len(pts)
            errs.append(errors(pts, exact))
        row = {"count": count, "n": n, "time": statistics.median(times), "runs": len(times)}
        for key in ERRORS + ("error",):
            row[key] = math.sqrt(sum(e[key] ** 2 for e in errs) / len(errs))
        rows.append(row)
    return rows


def fit_slope(rows, key="error"):
    """Least-squares slope of log10(error) against log10(points)."""
    x = np.log10([r["n"] for r in rows if r[key] > 0])
    y = np.log10([r[key] for r in rows if r[key] > 0])
    if len(x) < 2:
        return float("nan")
    return float(np.polyfit(x, y, 1)[0])


POISSON_OVERSAMPLING = (3, 5, 8, 10, 15)


def poisson_hook(surface, counts, seed):
    """Relative radius rho and time of exact-count Poisson thinning against the
    oversampling factor (candidates per output point): the spacing that time buys."""
    from ..api import prepare

    rows = []
    for count in counts:
        for k in POISSON_OVERSAMPLING:
            t = time.perf_counter()
            run = prepare(surface, count, seed=seed, poisson=True, precision="float64", oversampling=k)
            elapsed = time.perf_counter() - t
            rows.append({"count": count, "n": run.count, "oversampling": k, "time": elapsed, "rho": run.info["rho"]})
    return rows


# ---------------------------------------------------------------------------
# Outputs


def markdown(results, counts, notes, poisson):
    show = sorted({counts[0], min(counts, key=lambda c: abs(math.log10(c) - 3)),
                   min(counts, key=lambda c: abs(math.log10(c) - 5)), counts[-1]})
    lines = ["# scatter bench", "",
             "Relative error (RMS over seeds of the centroid, central second moments and smooth-function "
             "errors) and median time; slope: least-squares fit of log error against log points.", ""]
    for mesh in dict.fromkeys(r.mesh for r in results):
        lines += [f"## {mesh}", ""]
        head = ["variant", "slope"] + [f"error @ {c:.0e}" for c in show] + [f"ms @ {c:.0e}" for c in show]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for res in (r for r in results if r.mesh == mesh):
            by = {row["count"]: row for row in res.rows}
            cells = [res.variant, f"{res.slope['error']:+.2f}"]
            cells += [f"{by[c]['error']:.2e}" if c in by else "" for c in show]
            cells += [f"{1e3 * by[c]['time']:.3g}" if c in by else "" for c in show]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    if poisson:
        lines += ["## Poisson thinning (exact count)", "", "| mesh | points | candidates per point | rho | ms |",
                  "|---|---|---|---|---|"]
        lines += [f"| {p['mesh']} | {p['n']} | {p['oversampling']} | {p['rho']:.3f} | {1e3 * p['time']:.3g} |"
                  for p in poisson]
        lines.append("")
    if notes:
        lines += ["Notes:", ""] + [f"- {n}" for n in notes] + [""]
    return "\n".join(lines)


def plot(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meshes = list(dict.fromkeys(r.mesh for r in results))
    fig, axes = plt.subplots(2, len(meshes), figsize=(5.2 * len(meshes), 8.5), squeeze=False)
    styles = {"method": "-", "precision": ":", "warp": "--", "peer": "-."}
    names = list(dict.fromkeys(r.variant for r in results))
    colours = {v: plt.get_cmap("tab20")(i % 20) for i, v in enumerate(names)}
    for col, mesh in enumerate(meshes):
        for res in (r for r in results if r.mesh == mesh):
            c = colours[res.variant]
            n = [row["n"] for row in res.rows]
            e = [row["error"] for row in res.rows]
            t = [row["time"] for row in res.rows]
            label = f"{res.variant} ({res.slope['error']:+.2f})"
            axes[0, col].loglog(n, e, styles[res.kind], color=c, marker="o", ms=3, label=label)
            axes[1, col].loglog(t, e, styles[res.kind], color=c, marker="o", ms=3, label=res.variant)
        axes[0, col].set_title(mesh)
        axes[0, col].set_xlabel("points")
        axes[1, col].set_xlabel("time (s, median)")
        for ax in axes[:, col]:
            ax.set_ylabel("relative error (RMS)")
            ax.grid(True, which="major", alpha=0.3)
        axes[0, col].legend(fontsize=6, title="variant (slope)", title_fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------


def run_bench(meshes=None, out="bench-out", quick=False, counts=None, repeats=None, seed=0,
              want_plot=True, log=None) -> dict:
    """Run the bench and write bench.md, bench.json and bench.png to ``out``."""
    from .check import world_triangles
    from ..loading.load import load_surface

    log = log or (lambda msg: print(msg, file=sys.stderr))
    if want_plot:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise ScatterError(INSTALL_HINT + " (or run with --no-plot)") from None
    counts = sorted(counts or (QUICK_COUNTS if quick else FULL_COUNTS))
    repeats = repeats or (3 if quick else 5)
    named = default_meshes(quick) if not meshes else [(Path(str(m)).name, m) for m in meshes]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    notes, results, poisson = [], [], []
    started = time.perf_counter()
    for name, mesh in named:
        surface = load_surface(mesh)
        tri, areas = world_triangles(surface)
        exact = exact_values(tri, areas)
        log(f"{name}: {len(tri):,} faces, area {exact.area:.6g}")
        mesh_notes = []
        for v in variants(surface, tri, mesh_notes):
            t = time.perf_counter()
            rows = measure(v, exact, counts, repeats, seed)
            res = Result(name, v.name, v.kind, rows, {k: fit_slope(rows, k) for k in ERRORS + ("error",)}, v.note)
            results.append(res)
            log(f"  {v.name:24s} slope {res.slope['error']:+.2f}  error@{rows[-1]['n']:.0e} "
                f"{rows[-1]['error']:.2e}  ({time.perf_counter() - t:.1f} s)")
        for row in poisson_hook(surface, POISSON_COUNTS_QUICK if quick else POISSON_COUNTS, seed):
            poisson.append(dict(row, mesh=name))
        notes += [f"{name}: {n}" for n in dict.fromkeys(mesh_notes)]
    notes += [f"{r.variant}: {r.note}" for r in {r.variant: r for r in results if r.note}.values()]
    report = {
        "counts": counts,
        "repeats": repeats,
        "seed": seed,
        "errors": "relative; RMS over seeds; 'error' = RMS of centroid, second, smooth",
        "time": "median seconds per run (plan build + sampling), warm",
        "results": [{"mesh": r.mesh, "variant": r.variant, "kind": r.kind, "slope": r.slope, "rows": r.rows,
                     "note": r.note} for r in results],
        "poisson": poisson,
        "notes": notes,
        "elapsed": time.perf_counter() - started,
    }
    text = markdown(results, counts, notes, poisson)
    (out / "bench.md").write_text(text)
    (out / "bench.json").write_text(json.dumps(report, indent=1) + "\n")
    if want_plot:
        plot(results, out / "bench.png")
    report["markdown"] = text
    return report
