"""The Python API that the command line wraps: ``sample`` and the streaming ``prepare``.

A run flows one way: file -> surface -> plan -> source -> chunks -> writer. ``prepare``
checks every option, loads the surface, builds its source of points (thinned into a new
source when asked) and returns a :class:`Run`, whose ``chunks()`` a writer streams.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .attributes import AttributeMaker
from .errors import ScatterUsageError
from .methods import SOBOL_MAX_COUNT
from .samples import ATTRIBUTES, Samples, column_layout, parse_attributes
from .sampling import SamplePlan, chunk_ranges, run_chunks
from .sources import Source, StratifiedSource, ThinnedSource, make_source, thinned
from .loaders import load_surface
from .surface import Surface, column_bounds, transformed_columns

METHODS = ("random", "stratified", "sobol")
PLAIN_ATTRIBUTES = {"face", "bary", "normal", "object", "orient"}
PRECISIONS = ("auto", "float32", "float64")
# --precision auto keeps float32 while its rounding moves no point by more than this
# fraction of the bounding-box diagonal.
AUTO_PRECISION_TOLERANCE = 1e-6
# Candidates drawn per output point before thinning: more buy a larger spacing (rho) for
# more time (docs/sampling.md: oversampling).
OVERSAMPLING = 8  # for --poisson -n N
SMALL_SET, SMALL_SET_OVERSAMPLING = 5_000, 15  # for --poisson sets of up to SMALL_SET points
RADIUS_OVERSAMPLING = 5  # for --radius: times the most points an R-spaced set can hold
MAX_CANDIDATES = 50_000_000  # a larger thinning job is refused


class Run:
    """A prepared sampling job: a source of points, the attributes and the output layout.

    ``chunks()`` yields :class:`Samples` of at most ``chunk_size`` points, in output
    order, so a writer can stream any count in flat memory.
    """

    def __init__(self, source: Source, maker: AttributeMaker, dtype, chunk_size: int, info: dict, plan,
                 shard=None):
        self.source = source
        self.maker = maker
        self.dtype = np.dtype(dtype)
        self.chunk_size = chunk_size
        self.info = info
        self.layout = column_layout({ATTRIBUTES[a][0] for a in maker.names}, self.dtype)
        self.plan = plan  # the used faces: bounds for LAS, the surface for USD
        self.surface = plan.surface
        self.shard = shard  # (K, M): the run writes only that part of its points

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

    @property
    def count(self) -> int:
        return self.source.count

    @property
    def kept(self):
        """The thinned points (a RawChunk), or None when the run is not thinned."""
        return self.source.kept if isinstance(self.source, ThinnedSource) else None

    def _job(self, start, stop):
        raw = self.source.draw(start, stop)
        return Samples(raw.points.astype(self.dtype, copy=False), self.maker.make(raw, self.dtype))

    def chunks(self, start=None, stop=None, *, threads=None):
        """Samples chunks of points ``start .. stop - 1`` (default: the run's span, all its
        points or its shard's) in output order.

        They are the slice ``start:stop`` of the whole run's points, byte for byte, and
        cost only their share of it.
        """
        start = self.span[0] if start is None else start
        stop = self.span[1] if stop is None else stop
        if not 0 <= start <= stop <= self.count:
            raise ValueError(f"points {start}..{stop} are outside the run's 0..{self.count}")
        yield from run_chunks(self._job, chunk_ranges(stop, self.chunk_size, start), threads)

    def spacing(self):
        """d_min, mean nearest-neighbour distance and rho of the output (thinning runs)."""
        from .spacing import spacing_stats

        return spacing_stats(self.kept.points, self.source.area)

    def collect(self) -> Samples:
        """All the points of the run's span in one :class:`Samples` (memory grows with the count)."""
        n = self.size
        points = np.empty((n, 3), dtype=self.dtype)
        attributes = {}
        # Preallocated arrays filled chunk by chunk: no concatenation copy at the end
        # (docs/sampling.md: collecting).
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
    """Check the options, load ``mesh`` (if a path) and prepare its run; see :func:`sample`.

    ``shard``: ``(K, M)``, the run keeps points floor(K*N/M) .. floor((K+1)*N/M) - 1 of
    the run without it, and draws only those.
    ``oversampling``: candidates per output point for Poisson thinning (default: 8, or
    15 for sets of up to 5,000 points); more buys a larger rho for more time.
    """
    t0 = time.perf_counter()
    names = parse_attributes(attributes)
    check_options(count, density, seed, method, precision, chunk_size, radius, poisson, weight, oversampling,
                  exterior, stable)
    shard = check_shard(shard, poisson, radius)
    # the fast readers may load it (smooth normals, colours and UVs too, where they read
    # them as trimesh does; else they hand the file to trimesh)
    plain = not weight and set(names) <= PLAIN_ATTRIBUTES | {"smooth-normal", "color", "uv"}
    surface = mesh if isinstance(mesh, Surface) else load_surface(mesh, input_format=input_format, objects=objects,
                                                                  plain=plain, smooth="smooth-normal" in names,
                                                                  color="color" in names, uv="uv" in names)
    t1 = time.perf_counter()
    for message in surface.warnings if warn else ():
        warn(message)
    maker = AttributeMaker(surface, names, seed)
    if stable:
        source, plan, dtype, info = _stable_source(surface, count, density, radius, weight, seed, maker, precision,
                                                   warn, t1 - t0, exterior)
        chunk_size = chunk_size or plan.default_chunk
    else:
        plan, weighting, area = plan_surface(surface, weight, warn)
        count = point_count(count, density, area, method)
        dtype = choose_precision(plan, precision, warn)
        info = {"source": surface.source, "count": count, "area": area, "faces": surface.face_count,
                "faces_used": plan.faces_used, "seed": seed, "method": method, "precision": dtype.name}
        if weighting is not None:
            info["weight"] = weight
        info["timings"] = {"load": t1 - t0, "plan": time.perf_counter() - t1}
        def source_of(n):
            return make_source(plan, n, seed, maker.needs_bary, method=method, weighting=weighting, area=area)

        source = _filtered_source(source_of, surface, area, info, count, density, poisson, radius, exterior, seed,
                                  oversampling)
        chunk_size = chunk_size or plan.default_chunk
    if shard is not None:
        info["shard"] = list(shard)
    return Run(source, maker, dtype, chunk_size, info, plan, shard)


def _filtered_source(source_of, surface, area, info, count, density, poisson, radius, exterior, seed,
                     oversampling):
    """The run's source: ``source_of(n)`` (the method's source of n points), its exterior
    points (``--exterior``), thinned to a Poisson-disk set (``--poisson``, ``--radius``)."""
    thin = poisson or radius is not None
    if exterior:
        occluder = _occluder(surface, info)
        base = source = source_of(count)
        if density is not None:  # the exterior points among the plain run's
            source = _exterior_source(base, occluder, seed, area, info, candidates=count)
            count = source.count
        elif isinstance(base, StratifiedSource):  # its strata are fixed by the count: no stream to filter
            return _exterior_source(source_of, occluder, seed, area, info, subset=count)
    n = candidate_count(area, count, radius, surface.source, oversampling) if thin else count
    if not exterior:
        source = source_of(n)
    elif thin or density is None:  # thinning works on exterior candidates
        source = _exterior_source(base, occluder, seed, area, info, count=n)
    if thin:
        source, thinning = thinned(source, count, radius)
        info["timings"].update(thinning.pop("timings"))
        info.update(thinning)
    return source


def _occluder(surface, info):
    from .visibility import Occluder

    t = time.perf_counter()
    occluder = Occluder(surface)
    info["timings"]["ray_scene"] = time.perf_counter() - t
    info["timings"]["bvh_build"] = occluder.build_seconds  # (Embree's tree: part of ray_scene)
    return occluder


def _exterior_source(base, occluder, seed, area, info, count=None, candidates=None, subset=None):
    """The exterior points of ``base``'s stream: exactly ``count``, or those among its
    first ``candidates``; or, ``base`` being ``source_of``, ``subset`` of the exterior
    points of one of its bounded runs (:class:`~scatter_cli.exterior.ExteriorSubset`)."""
    from .exterior import ExteriorSource, ExteriorSubset

    t = time.perf_counter()
    if subset is not None:
        source = ExteriorSubset(base, occluder, seed, area, subset)
    else:
        source = ExteriorSource(base, occluder, seed, area, count=count, candidates=candidates)
    info.update(count=source.count, exterior=source.stats)
    info["timings"]["exterior"] = time.perf_counter() - t
    info["timings"]["enclosure"] = source.enclosure_seconds
    return source


def _stable_source(surface, count, density, radius, weight, seed, maker, precision, warn, load_time, exterior):
    """(source, used faces, dtype, info) of ``--stable``: the points come from
    :class:`scatter_cli.stable.StableSource`; with ``--exterior``, its exterior arrivals
    (the N earliest, those before D, or the candidates of ``--radius``), in arrival order."""
    from .stable import StableSource, dart_thrown, stable_weight

    t = time.perf_counter()
    exact = density is None and radius is None
    n = 10000 if count is None else count
    source = StableSource(surface, seed, count=n if exact and not exterior else None, density=density, radius=radius,
                          stream=exact and exterior, want_bary=maker.needs_bary,
                          weight=stable_weight(surface, weight) if weight else None, max_candidates=MAX_CANDIDATES)
    plan = source.table  # the used faces, for the bounds that choose the precision
    if plan.non_finite and warn:
        warn(f"{surface.source}: skipped {plan.non_finite:,} faces with non-finite vertices")
    dtype = choose_precision(plan, precision, warn)
    info = {"source": surface.source, "count": source.count, "area": source.area, "faces": surface.face_count,
            "faces_used": len(plan), "seed": seed, "method": "random", "stable": True, "precision": dtype.name,
            "timings": {"load": load_time, "plan": time.perf_counter() - t}}
    if weight:
        info["weight"] = weight
    if exterior:
        occluder = _occluder(surface, info)
        source = _exterior_source(source, occluder, seed, source.area, info, count=n if exact else None,
                                  candidates=None if exact else source.count)
    if radius is not None:
        info["radius"] = radius
        source = dart_thrown(source, radius)
        info["count"] = source.count
    return source, plan, dtype, info


def plan_surface(surface: Surface, weight=None, warn=None):
    """(plan, weighting or None, area): the face table of ``surface`` (over area times the
    weight ``--weight weight`` reads from the file, if given) and its unweighted area."""
    weighting = None
    if weight:
        from .weighting import read_weight, weighted_plan

        weighting = read_weight(surface, weight)
        plan = weighted_plan(surface, weighting)
    else:
        plan = SamplePlan(surface)
    if plan.non_finite and warn:
        warn(f"{surface.source}: skipped {plan.non_finite:,} faces with non-finite vertices")
    area = plan.area if weighting is None else SamplePlan(surface).area  # a weighted CDF's total is no area
    return plan, weighting, area


def point_count(count, density, area, method="random") -> int:
    """The run's point count: ``count``, else ``density`` times ``area``, else 10,000."""
    if density is not None:
        count = int(round(density * area))
        _check_sobol_count(method, count)
    return 10000 if count is None else count


def candidate_count(area, count, radius, source, oversampling=None):
    """How many uniform candidates to draw before thinning (``area`` unused without ``radius``)."""
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


def check_options(count=None, density=None, seed=0, method="random", precision="auto", chunk_size=None,
                  radius=None, poisson=False, weight=None, oversampling=None, exterior=False, stable=False):
    """Raise ScatterUsageError for any option, or combination, that is wrong whatever the mesh."""
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
    if oversampling is not None and not (math.isfinite(oversampling) and oversampling > 0):
        raise ScatterUsageError(f"oversampling must be a positive number, not {oversampling!r}")
    if weight:
        from .weighting import parse_weight

        parse_weight(weight)
    if poisson and radius is not None:
        raise ScatterUsageError("give either --poisson (an exact count) or --radius, not both")
    if radius is not None and density is not None:
        raise ScatterUsageError("with --radius the count follows from R: drop --density")
    if method != "random" and (poisson or radius is not None or weight):
        raise ScatterUsageError(f"--method {method} does not combine with --poisson, --radius or --weight "
                                "(they work on the random method)")
    if stable and method != "random":
        raise ScatterUsageError(f"--stable does not combine with --method {method} (it is a random placement)")
    if stable and poisson:
        raise ScatterUsageError("--stable does not combine with --poisson (--radius gives a Poisson-disk set that "
                                "stays put)")
    if count is not None:
        _check_sobol_count(method, count)
        if poisson:
            candidate_count(None, count, None, None, oversampling)


def _check_sobol_count(method, count):
    if method == "sobol" and count > SOBOL_MAX_COUNT:
        raise ScatterUsageError(f"--method sobol gives at most 2^32 = {SOBOL_MAX_COUNT:,} points per run, not {count:,}")


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
    """(2, 3) float64 min and max over the world-space vertices of the faces that get points.

    The instances of a geometry that use all its faces are bounded together: its
    referenced vertices under all their matrices at once, (k, V) values at a time."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    whole = {}  # geometry -> matrices of the parts that use every face (None: identity)
    for part in plan.parts:
        if not part.count:  # an instance none of whose faces can get points
            continue
        gi = plan.surface.instances[part.instance].geometry
        if part.faces is None:
            whole.setdefault(gi, []).append(part.matrix)
            continue
        g = plan.surface.geometries[gi]
        box = _box(_referenced(g.vertices, g.faces[part.faces]), [part.matrix])
        lo, hi = np.minimum(lo, box[0]), np.maximum(hi, box[1])
    for gi, matrices in whole.items():
        g = plan.surface.geometries[gi]
        box = _box(_referenced(g.vertices, g.faces), matrices)
        lo, hi = np.minimum(lo, box[0]), np.maximum(hi, box[1])
    return np.stack([lo, hi])


def _referenced(vertices, faces):
    """The rows of ``vertices`` (V, 3) that ``faces`` (F, 3) use."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    return vertices if used.all() else vertices[used]


def _box(v, matrices):
    """(2, 3) min and max of points ``v`` (n, 3) under each of ``matrices`` ((4, 4) or
    None for identity), as :func:`surface.apply_matrix` places them, bit for bit."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    if any(m is None for m in matrices):
        lo, hi = column_bounds(v)
    moved = [m[:3] for m in matrices if m is not None]
    step = max(1, (1 << 20) // max(len(v), 1))
    for s in range(0, len(moved), step):
        cols = transformed_columns(np.stack(moved[s : s + step]), v)
        lo = np.minimum(lo, [c.min() for c in cols])
        hi = np.maximum(hi, [c.max() for c in cols])
    return lo, hi


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
