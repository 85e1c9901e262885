"""The Python API that the command line wraps: ``sample`` and the streaming ``prepare``."""

from __future__ import annotations

import math
import time

import numpy as np

from .attributes import AttributeMaker
from .errors import ScatterError, ScatterUsageError
from .methods import DRAWS, SOBOL_MAX_COUNT
from .samples import ATTRIBUTES, Samples, column_layout, parse_attributes
from .sampling import DEFAULT_CHUNK, RawChunk, SamplePlan, chunk_ranges, in_blocks, run_chunks
from .surface import Surface, apply_matrix, load_surface

METHODS = ("random", "stratified", "sobol")
PLAIN_ATTRIBUTES = {"face", "bary", "normal", "object", "orient"}
PRECISIONS = ("auto", "float32", "float64")
# --precision auto keeps float32 while its rounding moves no point by more than this
# fraction of the bounding-box diagonal.
AUTO_PRECISION_TOLERANCE = 1e-6


class Run:
    """A prepared sampling job: the plan, the output layout and the point count.

    ``chunks()`` yields :class:`Samples` of at most ``chunk_size`` points, in output
    order, so a writer can stream any count in flat memory.
    """

    def __init__(self, surface, plan, count, seed, attributes, dtype, chunk_size, info, sampler=None,
                 method="random"):
        self.surface = surface
        self.method = method
        self.plan = plan
        self.sampler = sampler or plan  # a weighting's sampler, or the plain plan
        self.count = count
        self.seed = seed
        self.dtype = np.dtype(dtype)
        self.maker = AttributeMaker(surface, attributes, seed)
        self.chunk_size = chunk_size
        self.info = info
        self.layout = column_layout({ATTRIBUTES[a][0] for a in attributes}, self.dtype)
        self.kept = None  # RawChunk of the thinned set, when thinning
        self.source = None  # the exterior filter over the candidate stream, or the stable source
        self.shard = None  # (K, M): the run writes only that part of its points

    @property
    def span(self):
        """(start, stop): the points ``chunks()`` yields, all or a shard's share."""
        if self.shard is None:
            return 0, self.count
        k, m = self.shard
        return k * self.count // m, (k + 1) * self.count // m

    @property
    def size(self) -> int:
        """How many points ``chunks()`` yields: ``count``, or a shard's share of it."""
        start, stop = self.span
        return stop - start

    def draw(self, start, stop):
        """Points ``start .. stop - 1`` of the candidate stream, before any filter or thinning."""
        if self.method == "random":
            return self.sampler.draw(start, stop, self.seed, self.maker.needs_bary)
        used, b = DRAWS[self.method](self.plan, self.count, start, stop, self.seed)
        return self.plan.place(start, used, b, self.maker.needs_bary)

    def _job(self, start, stop):
        if self.kept is not None:
            raw = self.kept.slice(start, stop)
        elif self.source is not None:
            raw = self.source.draw(start, stop)
        else:
            raw = self.draw(start, stop)
        attrs = self.maker.make(raw, self.dtype)
        return Samples(raw.points.astype(self.dtype, copy=False), attrs)

    def thin(self, candidates, radius):
        """Replace the run's points by a Poisson-disk subset of ``candidates`` random points.

        ``radius`` None: exactly ``self.count`` points, spaced as far apart as reached.
        """
        from . import thinning

        t = time.perf_counter()
        draw = self.source.draw if self.source is not None else self.draw
        blocks = in_blocks(draw, candidates)
        points = np.concatenate([b.points for b in blocks]) if len(blocks) > 1 else blocks[0].points
        t1 = time.perf_counter()
        if radius is not None:
            index = thinning.thin_by_radius(points, radius)
            d_min = None
        else:
            index, d_min = thinning.thin_to_count(points, self.count, self._sampled_area())
        self.kept = _take(blocks, index)
        self.count = len(index)
        self.info.update(count=self.count, candidates=candidates, radius=radius)
        if d_min is not None:
            self.info.update(d_min=d_min, rho=thinning.relative_radius(d_min, self._sampled_area(), self.count))
        self.info["timings"].update(candidates=t1 - t, thinning=time.perf_counter() - t1)

    def _sampled_area(self):
        """The area the candidates are uniform over: the exterior area with --exterior."""
        return self.source.area if self.source is not None else self.info["area"]

    def exterior(self, count=None, candidates=None):
        """Filter the candidate stream to its exterior points: exactly ``count`` of them, or
        those among the first ``candidates``."""
        from .exterior import ExteriorSource
        from .visibility import Occluder

        t = time.perf_counter()
        occluder = Occluder(self.surface)
        t1 = time.perf_counter()
        self.source = ExteriorSource(_Candidates(self), occluder, self.seed, self.info["area"], count=count,
                                     candidates=candidates)
        self.count = self.source.count
        self.info.update(count=self.count, exterior=self.source.stats)
        self.info["timings"].update(ray_scene=t1 - t, exterior=time.perf_counter() - t1)

    def spacing(self):
        """d_min, mean nearest-neighbour distance and rho of the output (thinning runs)."""
        from .thinning import spacing_stats

        return spacing_stats(self.kept.points, self._sampled_area())

    def chunks(self, threads=None):
        """Samples chunks in output order: points ``start .. stop - 1`` of the run."""
        start, stop = self.span
        ranges = [(a + start, b + start) for a, b in chunk_ranges(stop - start, self.chunk_size)]
        yield from run_chunks(self._job, ranges, threads)

    def collect(self) -> Samples:
        """All points in one :class:`Samples` (memory grows with the count)."""
        n = self.size
        points = np.empty((n, 3), dtype=self.dtype)
        attributes = {}
        # Fill preallocated arrays chunk by chunk: no concatenation copy at the end. The
        # workers round to the output type; copying into the output on the workers instead
        # measured slower (0.37 s against 0.23 s for 10^7 points on the skull).
        pos = 0
        for chunk in self.chunks():
            k = len(chunk)
            points[pos : pos + k] = chunk.points
            for key, arr in chunk.attributes.items():
                if key not in attributes:
                    attributes[key] = np.empty((n,) + arr.shape[1:], dtype=arr.dtype)
                attributes[key][pos : pos + k] = arr
            pos += k
        for key, cols, dt in self.layout[1:]:  # count 0: no chunk, but every asked-for array
            if key not in attributes:
                attributes[key] = np.empty((n, len(cols)) if len(cols) > 1 else (n,), dtype=dt)
        return Samples(points, attributes, self.info)


def prepare(mesh, count=None, *, density=None, seed=0, method="random", attributes=(), poisson=False,
            radius=None, weight=None, objects=None, precision="auto", chunk_size=None, input_format=None,
            warn=None, oversampling=None, exterior=False, stable=False, shard=None) -> Run:
    """Load (if needed) and plan a sampling job; see :func:`sample` for the arguments.

    ``shard``: ``(K, M)``, the run keeps points floor(K*N/M) .. floor((K+1)*N/M) - 1 of
    the run without it, and draws only those.
    ``oversampling``: candidates per output point for Poisson thinning (default: 8, or
    15 for sets of up to 5,000 points); more buys a larger rho for more time.
    """
    t0 = time.perf_counter()
    names = parse_attributes(attributes)
    _check_options(count, density, seed, method, precision, chunk_size, radius)
    shard = check_shard(shard, poisson, radius)
    if stable and method != "random":
        raise ScatterUsageError(f"--stable does not combine with --method {method} (it is a random placement)")
    if stable and poisson:
        raise ScatterUsageError("--stable does not combine with --poisson (--radius gives a Poisson-disk set that "
                                "stays put)")
    if stable and exterior:
        raise ScatterUsageError("--stable does not combine with --exterior yet")
    # vertices and faces are all a job needs unless an attribute or weight reads the file's
    # colours, UVs or normals
    plain = not weight and set(names) <= PLAIN_ATTRIBUTES
    surface = mesh if isinstance(mesh, Surface) else load_surface(mesh, input_format=input_format, objects=objects,
                                                                  plain=plain)
    t1 = time.perf_counter()
    for message in surface._cache.pop("warnings", ()) if warn else ():
        warn(message)
    sampler = None
    if stable:
        run = _stable_run(surface, count, density, seed, names, weight, precision, chunk_size, radius, warn, t0, t1)
        return _with_shard(run, shard)
    if weight:
        from .weighting import weighted_plan

        plan, sampler = weighted_plan(surface, weight)
    else:
        plan = SamplePlan(surface)
    if plan.non_finite and warn:
        warn(f"{surface.source}: skipped {plan.non_finite:,} faces with non-finite vertices")
    area = plan.area if sampler is None else SamplePlan(surface).area  # weighted CDF total != area
    if density is not None:
        count = int(round(density * area))
    elif count is None:
        count = 10000
    if poisson and radius is not None:
        raise ScatterUsageError("give either --poisson (an exact count) or --radius, not both")
    if radius is not None and density is not None:
        raise ScatterUsageError("with --radius the count follows from R: drop --density")
    if method != "random" and (poisson or radius is not None or sampler is not None):
        raise ScatterUsageError(f"--method {method} does not combine with --poisson, --radius or --weight "
                                "(they work on the random method)")
    if exterior and method == "stratified":
        raise ScatterUsageError("--exterior does not combine with --method stratified (its strata are fixed by N); "
                                "use random or sobol")
    if method == "sobol" and count > SOBOL_MAX_COUNT:
        raise ScatterUsageError(f"--method sobol gives at most 2^32 = {SOBOL_MAX_COUNT:,} points per run, not {count:,}")
    dtype = choose_precision(plan, precision, warn)
    info = {
        "source": surface.source,
        "count": count,
        "area": area,
        "faces": surface.face_count,
        "faces_used": plan.faces_used,
        "seed": seed,
        "method": method,
        "precision": np.dtype(dtype).name,
        "timings": {"load": t1 - t0, "plan": time.perf_counter() - t1},
    }
    if sampler is not None:
        info["weight"] = weight
    run = Run(surface, plan, count, seed, names, dtype, chunk_size or plan.default_chunk, info, sampler, method)
    thinning = poisson or radius is not None
    if exterior and density is not None:  # the exterior points among the plain run's
        run.exterior(candidates=count)
        count = run.count
    candidates = candidate_count(area, count, radius, surface.source, oversampling) if thinning else None
    if exterior and thinning:  # thinning works on exterior candidates
        run.exterior(count=candidates)
        run.count = count
    elif exterior and density is None:
        run.exterior(count=count)
    if thinning:
        run.thin(candidates, radius)
    return _with_shard(run, shard)


def _with_shard(run, shard):
    """``run`` writing only shard ``(K, M)`` of its points (None: all of them)."""
    if shard is not None:
        run.shard = shard
        run.info["shard"] = list(shard)
    return run


def _stable_run(surface, count, density, seed, names, weight, precision, chunk_size, radius, warn, t0, t1):
    """The Run of ``--stable``: the plan only measures the surface, the points come from
    :class:`scatter_cli.stable.StableSource`."""
    from .stable import StableSource, stable_weight

    if radius is not None and density is not None:
        raise ScatterUsageError("with --radius the count follows from R: drop --density")
    run = Run(surface, None, 0, seed, names, np.float64, chunk_size or DEFAULT_CHUNK, None)
    source = StableSource(surface, seed, count=None if density is not None or radius is not None else (
        10000 if count is None else count), density=density, radius=radius, want_bary=run.maker.needs_bary,
        weight=stable_weight(surface, weight) if weight else None, max_candidates=MAX_CANDIDATES)
    plan = source.table  # the used faces, for the bounds that choose the precision
    if plan.non_finite and warn:
        warn(f"{surface.source}: skipped {plan.non_finite:,} faces with non-finite vertices")
    dtype = choose_precision(plan, precision, warn)
    info = {
        "source": surface.source,
        "count": source.count,
        "area": source.area,
        "faces": surface.face_count,
        "faces_used": len(plan),
        "seed": seed,
        "method": "random",
        "stable": True,
        "precision": np.dtype(dtype).name,
        "timings": {"load": t1 - t0, "plan": time.perf_counter() - t1},
    }
    if weight:
        info["weight"] = weight
    if radius is not None:
        info["radius"] = radius
    run.plan, run.count, run.info, run.source = plan, source.count, info, source
    run.dtype = np.dtype(dtype)
    run.layout = column_layout({ATTRIBUTES[a][0] for a in names}, run.dtype)
    return run


class _Candidates:
    """A run's candidate stream as a source: ``draw(start, stop) -> RawChunk``."""

    def __init__(self, run):
        self.draw = run.draw


def _take(blocks, index):
    """Rows ``index`` (k,) ascending of the chunks ``blocks`` end to end, as one chunk."""
    ends = np.cumsum([len(b.points) for b in blocks])
    cuts = np.searchsorted(index, ends)
    return RawChunk.join([b.take(part - (end - len(b.points)))
                          for b, part, end in zip(blocks, np.split(index, cuts[:-1]), ends)])


# Candidates per output point for thinning: the spacing reachable grows with it and so
# does the time (the radius that keeps exactly N on the skull at 10,000 points: 0.750 d_hex
# at 6, 0.771 at 8, 0.786 at 10, 0.804 at 15; the search aims 1 to 2 % lower). Small
# sets have relatively more boundary and need more choice to reach rho 0.75 (at 2,000
# points and 8 candidates: skull 0.761, CAD plate 0.752; at 1,000, skull 0.747).
OVERSAMPLING = 8
SMALL_SET, SMALL_SET_OVERSAMPLING = 5_000, 15
# --radius fixes d_min, so more candidates only add points (rho 0.710, 0.745, 0.778, 0.810
# at 2, 3, 5, 10 times the hexagonal count on the 1.3M-face icosphere at R = 0.0094) while
# the pair graph grows with the square of the factor (0.07, 0.13, 0.23, 0.66 s of thinning).
RADIUS_OVERSAMPLING = 5
MAX_CANDIDATES = 50_000_000


def candidate_count(area, count, radius, source, oversampling=None):
    """How many uniform candidates to draw before thinning."""
    if radius is not None:
        # no R-spaced set holds more than the hexagonal packing of spacing R
        bound = area / (math.sqrt(3) / 2 * radius * radius)
        if bound < 1:
            return RADIUS_OVERSAMPLING
        need = (oversampling or RADIUS_OVERSAMPLING) * bound
        what = f"--radius {radius:g} is too small for {source} (area {area:.6g})"
    else:
        need = (oversampling or (SMALL_SET_OVERSAMPLING if count <= SMALL_SET else OVERSAMPLING)) * count
        what = f"--poisson -n {count:,} is too many points"
    if need > MAX_CANDIDATES:
        raise ScatterUsageError(f"{what}: thinning would need {need:,.0f} candidates, more than {MAX_CANDIDATES:,}")
    return max(1, int(math.ceil(need)))


def sample(mesh, count=10000, *, density=None, seed=0, method="random", attributes=(), poisson=False,
           radius=None, weight=None, objects=None, precision="auto", chunk_size=None, exterior=False,
           stable=False, shard=None) -> Samples:
    """Sample points uniformly over the surface of ``mesh``.

    mesh: a path, a ``trimesh.Trimesh`` or a ``trimesh.Scene``. ``exterior``: only the
    surface seen from outside (docs/exterior.md; needs embreex). Returns :class:`Samples`
    with ``.points`` (count, 3) and one array per requested attribute. The result is a
    pure function of the mesh, the options and ``seed``, whatever ``chunk_size``.
    """
    run = prepare(mesh, count, density=density, seed=seed, method=method, attributes=attributes,
                  poisson=poisson, radius=radius, weight=weight, objects=objects, precision=precision,
                  chunk_size=chunk_size, exterior=exterior, stable=stable, shard=shard)
    t = time.perf_counter()
    samples = run.collect()
    samples.info["timings"]["sample"] = time.perf_counter() - t
    return samples


def _check_options(count, density, seed, method, precision, chunk_size, radius):
    if count is not None and density is not None:
        raise ScatterUsageError("give either a count (-n) or a --density, not both")
    if count is not None and (not isinstance(count, (int, np.integer)) or count < 0):
        raise ScatterUsageError(f"the count must be a non-negative integer, not {count!r}")
    if density is not None and not (math.isfinite(density) and density > 0):
        raise ScatterUsageError(f"--density must be a positive number, not {density!r}")
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ScatterUsageError(f"--seed must be a non-negative integer, not {seed!r}")
    if method not in METHODS:
        raise ScatterUsageError(f"unknown method '{method}' (choose from: {', '.join(METHODS)})")
    if precision not in PRECISIONS:
        raise ScatterUsageError(f"unknown precision '{precision}' (choose from: {', '.join(PRECISIONS)})")
    if chunk_size is not None and (not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1):
        raise ScatterUsageError(f"--chunk-size must be a positive integer, not {chunk_size!r}")
    if radius is not None and not (math.isfinite(radius) and radius > 0):
        raise ScatterUsageError(f"--radius must be a positive number, not {radius!r}")


def output_options(run: Run, fmt: str) -> dict:
    """What the writer of ``fmt`` needs from the run besides its points (keywords of
    :func:`~scatter_cli.writers.write_samples`): LAS the sampled bounding box, USD the
    input's up axis and units (when the surface carries them) and the point spacing."""
    if fmt in ("las", "laz"):
        return {"bounds": sampled_bounds(run.plan)}
    if fmt == "usd":
        area = run.info["area"]
        return {"up_axis": getattr(run.surface, "up_axis", None),
                "meters_per_unit": getattr(run.surface, "meters_per_unit", None),
                "spacing": math.sqrt(area / run.count) if run.count and area > 0 else None}
    return {}


def check_shard(shard, poisson=False, radius=None):
    """``(K, M)`` or ``"K/M"`` -> ``(K, M)`` ints with 0 <= K < M; None stays None."""
    if shard is None:
        return None
    try:
        k, m = (int(x) for x in (shard.split("/") if isinstance(shard, str) else shard))
    except (TypeError, ValueError):
        raise ScatterUsageError(f"--shard must be K/M (shard K of M, 0-based), not {shard!r}") from None
    if not 0 <= k < m:
        raise ScatterUsageError(f"--shard K/M needs 0 <= K < M, not {k}/{m}")
    if poisson or radius is not None:
        raise ScatterUsageError("--shard does not combine with --poisson or --radius (thinning is global)")
    return k, m


def sampled_bounds(plan: SamplePlan):
    """(2, 3) float64 min and max over the world-space vertices of the faces that get points."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for part in plan.parts:
        if not part.count:  # an instance none of whose faces can get points
            continue
        g = plan.surface.geometries[plan.surface.instances[part.instance].geometry]
        faces = g.faces if part.faces is None else g.faces[part.faces]
        referenced = np.zeros(len(g.vertices), dtype=bool)
        referenced[faces.ravel()] = True
        v = g.vertices if referenced.all() else g.vertices[referenced]
        if part.matrix is not None:
            v = apply_matrix(part.matrix, v)
        lo = np.minimum(lo, [v[:, c].min() for c in range(3)])
        hi = np.maximum(hi, [v[:, c].max() for c in range(3)])
    return np.stack([lo, hi])


def float32_error_bound(bounds) -> float:
    """Largest distance rounding to float32 can move a point inside ``bounds`` (2, 3)."""
    biggest = np.abs(bounds).max(axis=0)
    if not (biggest <= np.finfo(np.float32).max).all():  # would round to inf (spacing: NaN)
        return math.inf
    half_ulp = np.spacing(biggest.astype(np.float32)).astype(np.float64) / 2
    return float(np.sqrt(np.sum(half_ulp**2)))


def choose_precision(plan, precision, warn=None):
    bounds = sampled_bounds(plan)
    if precision == "float32" and math.isinf(float32_error_bound(bounds)):
        raise ScatterUsageError(f"{plan.surface.source}: coordinates beyond the float32 range; use --precision float64 or auto")
    if precision != "auto":
        return np.dtype(precision)
    with np.errstate(over="ignore"):
        diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    err = float32_error_bound(bounds)
    if math.isinf(err) or err > AUTO_PRECISION_TOLERANCE * diag:
        if warn:
            warn(f"writing float64 coordinates: float32 would move points by up to {err:.3g}, "
                 f"more than 1e-6 of the bounding-box diagonal ({diag:.6g})")
        return np.dtype(np.float64)
    return np.dtype(np.float32)
