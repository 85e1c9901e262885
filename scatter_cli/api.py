"""The Python API that the command line wraps: ``sample``, the streaming ``prepare`` and ``write``.

A run flows one way: file -> surface -> source -> chunks -> writer. ``prepare`` checks
the options (:class:`~scatter_cli.run.options.SampleOptions`), loads the surface, builds its
source of points (:mod:`scatter_cli.run.pipeline`) and returns a :class:`Run`, whose
``chunks()`` a writer streams; :func:`write` writes a run to a file, as ``scatter
sample`` and every ``scatter batch`` worker do.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from .errors import ScatterError
from .run.attributes import AttributeMaker
from .run.bounds import choose_precision, in_frame, normal_frame, sampled_bounds
from .run.options import SampleOptions
from .run.pipeline import surface_source, volume_source
from .run.columns import ATTRIBUTES, Samples, column_layout
from .sampling.plan import run_chunks
from .sampling.sources import Source
from .loading.load import load_surface
from .surface.model import Surface

# attributes the fast readers give as trimesh would (else the file goes to trimesh)
FAST_READER_ATTRIBUTES = {"face", "bary", "normal", "object", "orient", "smooth-normal", "color", "uv"}


class Run:
    """A prepared sampling job: a source of points, the attributes and the output layout.

    ``chunks()`` yields :class:`Samples` of at most ``chunk_size`` points, in output
    order, so a writer can stream any count in flat memory.
    """

    def __init__(self, source: Source, maker: AttributeMaker, dtype, chunk_size: int, info: dict, plan,
                 shard=None, frame=None, box=None, warn=None):
        self.source = source
        self.maker = maker
        self.dtype = np.dtype(dtype)
        self.chunk_size = chunk_size
        self.info = info
        self.layout = column_layout({ATTRIBUTES[a][0] for a in maker.names}, self.dtype)
        self.plan = plan  # the used faces: bounds for LAS, the surface for USD
        self.surface = plan.surface
        self.shard = shard  # (K, M): the run writes only that part of its points
        self.frame = frame  # (offset (3,), scale): points written as (p - offset) * scale (--normalize)
        self.box = box  # (2, 3) world-space box of the points: the used faces' vertices, or the sampling box
        self.warn = warn

    @property
    def bounds(self):
        """(2, 3) float64 box the points lie in, in the output's frame."""
        return in_frame(self.box, self.frame)

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
        return self.source.kept

    def _job(self, start, stop):
        raw = self.source.draw(start, stop)
        points = raw.points if self.frame is None else (raw.points - self.frame[0]) * self.frame[1]
        return Samples(points.astype(self.dtype, copy=False), self.maker.make(raw, self.dtype))

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
        yield from run_chunks(self._job, start, stop, self.chunk_size, threads, self.maker.split_chunks)
        self._count_signs()

    def _count_signs(self):
        """Once the points are labelled: the share of the signs that rest on a winding
        number near 1/2 (``info["volume"]["near_half"]``), and a warning when many do."""
        tally = getattr(self.maker, "tally", None)
        if tally is None:
            return
        from .volume.signs import sign_warning

        points, near_half = tally.take()
        self.info["volume"]["near_half"] = near_half / points if points else 0.0
        message = sign_warning(self.surface.source, points, near_half)
        if message and self.warn:
            self.warn(message)

    def spacing(self):
        """d_min, mean nearest-neighbour distance and rho of the output (thinning runs)."""
        from .sampling.poisson.spacing import spacing_stats

        return spacing_stats(self.kept.points, self.source.area)

    def collect(self) -> Samples:
        """All the points of the run's span in one :class:`Samples` (memory grows with the count)."""
        n = self.size
        points = _hold(n, (n, 3), self.dtype)
        attributes = {}
        # Preallocated arrays filled chunk by chunk: no concatenation copy at the end
        # (docs/how-it-samples.md: collecting).
        pos = 0
        for chunk in self.chunks():
            k = len(chunk)
            points[pos : pos + k] = chunk.points
            for key, arr in chunk.attributes.items():
                if key not in attributes:
                    attributes[key] = _hold(n, (n,) + arr.shape[1:], arr.dtype)
                attributes[key][pos : pos + k] = arr
            pos += k
        for key, cols, dt in self.layout[1:]:  # count 0: no chunk, but every asked-for array
            if key not in attributes:
                attributes[key] = np.empty((n, len(cols)) if len(cols) > 1 else (n,), dtype=dt)
        return Samples(points, attributes, self.info)


def _hold(count, shape, dtype):
    """An empty array of ``shape`` for the ``count`` points of a run; one that memory
    cannot hold is a ScatterError that says what to do instead."""
    try:
        return np.empty(shape, dtype)
    except (MemoryError, ValueError):  # ValueError: more bytes than an array can have
        size = np.prod(shape, dtype=float) * np.dtype(dtype).itemsize
        raise ScatterError(f"{count:,} points do not fit in memory ({size / 1e9:,.0f} GB for one of their arrays): "
                           "write them to a file (scatter_cli.write) or sample fewer") from None


def prepare(mesh, count=None, *, options: SampleOptions | None = None, warn=None, **keywords) -> Run:
    """Check the options, load ``mesh`` (if a path) and prepare its run; see :func:`sample`.

    The options: ``options``, or ``count`` and the keyword arguments of
    :class:`~scatter_cli.run.options.SampleOptions` (``shard``: ``(K, M)``, the run keeps
    points floor(K*N/M) .. floor((K+1)*N/M) - 1 of the run without it, and draws only
    those; ``oversampling``: candidates per output point for Poisson thinning).
    ``warn(message)`` is called with each warning. Usage errors (ScatterUsageError) come
    before the file is read; what the mesh causes is a ScatterError.
    """
    if options is None:
        options = SampleOptions(count=count, **keywords)
    elif count is not None or keywords:
        raise TypeError("give either options or keyword arguments, not both")
    o = options.check()
    t0 = time.perf_counter()
    # the fast readers may load it (smooth normals, colours and UVs too, where they read
    # them as trimesh does; else they hand the file to trimesh)
    plain = not o.weight and set(o.attributes) <= FAST_READER_ATTRIBUTES
    surface = mesh if isinstance(mesh, Surface) else load_surface(
        mesh, input_format=o.input_format, objects=o.objects, plain=plain, smooth="smooth-normal" in o.attributes,
        color="color" in o.attributes, uv="uv" in o.attributes)
    info = {"timings": {"load": time.perf_counter() - t0}}
    for message in surface.warnings if warn else ():
        warn(message)
    if o.volume_run:
        source, maker, plan, frame, box = volume_source(surface, o, info, warn)
    else:
        maker = AttributeMaker(surface, o.attributes, o.seed)
        source, plan = surface_source(surface, o, maker.needs_bary, info, warn)
        frame, box = normal_frame(plan, o.normalize), sampled_bounds(plan)
    if frame is not None:
        info["normalize"] = {"mode": o.normalize, "offset": frame[0].tolist(), "scale": frame[1]}
    dtype = choose_precision(in_frame(box, frame), o.precision, surface.source, warn)
    info["precision"] = dtype.name
    if o.shard is not None:
        info["shard"] = list(o.shard)
    return Run(source, maker, dtype, o.chunk_size or plan.default_chunk, info, plan, o.shard, frame, box, warn)


def sample(mesh, count=None, **options) -> Samples:
    """Sample points uniformly over the surface of ``mesh``.

    mesh: a path, a ``trimesh.Trimesh`` or a ``trimesh.Scene``; ``count`` (default
    10,000) and the options: the keyword arguments of
    :class:`~scatter_cli.run.options.SampleOptions` (``exterior``: only the surface seen from
    outside, docs/exterior.md, needs embreex). Returns :class:`Samples` with ``.points``
    (count, 3) and one array per requested attribute. The result is a pure function of
    the mesh, the options and ``seed``, whatever ``chunk_size``.
    """
    run = prepare(mesh, count, **options)
    t = time.perf_counter()
    samples = run.collect()
    samples.info["timings"]["sample"] = time.perf_counter() - t
    return samples


def sample_to(mesh, options: SampleOptions, path, format=None, ascii=False, *, crs=None, warn=None,
              progress=False) -> Run:
    """Sample ``mesh`` with ``options`` and write the run to ``path`` (``None`` or ``-``:
    standard output): what ``scatter sample MESH -o PATH`` does, and a batch worker for
    each mesh. The output options are checked before the mesh is read. Returns the run
    (its ``info`` holds the writer's report)."""
    from .writers import output, run_precision

    out = output(path, format, ascii, crs)
    precision = run_precision(out.format, options.precision)
    if precision != options.precision:
        options = dataclasses.replace(options, precision=precision)
    run = prepare(mesh, options=options, warn=warn)
    t = time.perf_counter()
    _write(run, out, progress)
    run.info["timings"]["sample_and_write"] = time.perf_counter() - t
    return run


def write(run: Run, path, format=None, ascii=False, *, crs=None, progress=False):
    """Write the points of ``run`` to ``path`` (``None`` or ``-``: standard output) in
    ``format`` (default: from the suffix of ``path``), streamed chunk by chunk;
    ``crs``: LAS/LAZ's coordinate system; ``progress``: a progress line on standard
    error. Returns the writer's report (also in ``run.info["output"]`` when not empty)."""
    from .writers import output

    return _write(run, output(path, format, ascii, crs), progress)


def _write(run, out, progress):
    """:func:`write` to the output ``out``, already checked (:func:`~scatter_cli.writers.output`)."""
    from .core.progress import with_progress
    from .writers import write_output

    report = write_output(with_progress(run.chunks(), run.size, progress), out, run.layout, run.size,
                          **output_options(run, out.format))
    if report:
        run.info["output"] = report
    return report


def output_options(run: Run, fmt: str) -> dict:
    """What the writer of ``fmt`` takes from the run besides its points (keywords of
    :func:`~scatter_cli.writers.write_samples`), as the format table's row says."""
    from .writers.formats import BY_NAME

    return {name: RUN_FACTS[name](run) for name in BY_NAME[fmt].takes}


def _spacing(run):
    area = run.info["area"]
    return math.sqrt(area / run.count) if run.count and area > 0 else None


# What a writer may take from a run (a format's ``takes``): the sampled bounding box (LAS
# scale and offset), the input's up axis and units (when the surface carries them) and
# the point spacing (USD).
RUN_FACTS = {
    "bounds": lambda run: run.bounds,
    "up_axis": lambda run: getattr(run.surface, "up_axis", None),
    "meters_per_unit": lambda run: getattr(run.surface, "meters_per_unit", None),
    "spacing": _spacing,
}
