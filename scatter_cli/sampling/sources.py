"""Sources of points: one interface for every way a run makes its points.

A source is built once per run with everything it needs fixed (the sample plan, the
seed, the point count, whether barycentric weights are wanted, a weighting, the
candidates it thins) and then answers one question, "points ``start .. stop - 1``"::

    class Source(Protocol):
        count: int     # N: the source gives points 0 .. N - 1
        area: float    # area of the surface the points lie on (unweighted, world space)
        kept: RawChunk | None  # a thinned source's points, held whole (None: drawn on demand)
        stats: dict | None     # what a filter found (the exterior filter's areas), or None
        def draw(self, start: int, stop: int) -> RawChunk: ...

What ``draw(start, stop)`` must guarantee, for ``0 <= start <= stop <= count``:

- It is a pure function of ``(start, stop)``: it reads no state that an earlier call
  changed and changes none, so any chunking, order or thread (``draw`` is called from
  several worker threads at once) gives the same bytes: ``draw(a, b)`` followed by
  ``draw(b, c)`` equals ``draw(a, c)`` byte for byte, in every field.
  ``tests/test_sources.py`` checks this for every source; add a new source there.
- The chunk's ``start`` is the absolute index ``start``; ``points`` (n, 3) float64 in
  world space, ``face`` (n,) int64 (the face in its geometry), ``instance`` (n,) int64
  (the instance of the surface), ``bary`` (n, 3) float64 of the face's corners 0, 1, 2
  when the source was built with ``want_bary=True`` and None otherwise (computing them
  costs time: only attributes such as ``bary`` or ``color`` need them).
- Its cost follows ``stop - start``, not ``stop``: a random stream is advanced to
  ``start``, never drawn from 0 (``Run.chunks(start, stop)`` and ``--shard`` rely on
  it). The thinned source is the one exception: its candidates are drawn and thinned
  once, when it is built.

A source that filters or reorders another one (``--exterior``, thinning) is built from
that source as a new source; nothing is changed in place. :mod:`scatter_cli.run.pipeline`
composes them. The sources here: :class:`RandomSource`, :class:`StratifiedSource`,
:class:`SobolSource`; the weighted ones, :class:`~scatter_cli.sampling.weighting.VertexColorSource`
and :class:`~scatter_cli.sampling.weighting.TextureSource`, live with their weighting; the
stable one in :mod:`scatter_cli.sampling.stable.source`, the exterior ones in :mod:`scatter_cli.sampling.exterior.filter`,
the thinned one (:class:`~scatter_cli.sampling.poisson.thinning.ThinnedSource`) in :mod:`scatter_cli.sampling.poisson.thinning`.
"""

from __future__ import annotations

from typing import Protocol


from .methods import SOBOL_MAX_COUNT, sobol_draws, stratified_draws
from .plan import RawChunk, SamplePlan


class Source(Protocol):
    """The interface every source of points implements (see the module docstring)."""

    count: int
    area: float
    kept: RawChunk | None
    stats: dict | None

    def draw(self, start: int, stop: int) -> RawChunk: ...


class RandomSource:
    """The random method: i.i.d. points, point i from draws 3 i .. 3 i + 2 of the seed's
    stream (:meth:`SamplePlan.draw`), uniform over the plan's (area-weighted) faces."""

    kept = stats = None

    def __init__(self, plan: SamplePlan, count: int, seed: int, want_bary: bool = False):
        self.plan, self.count, self.seed, self.want_bary = plan, int(count), seed, want_bary
        self.area = plan.area

    def draw(self, start: int, stop: int) -> RawChunk:
        return self.plan.draw(start, stop, self.seed, self.want_bary)


class _PlacedSource:
    """A method that maps point indices to (used faces, barycentrics), placed by the plan."""

    kept = stats = None

    def __init__(self, plan: SamplePlan, count: int, seed: int, want_bary: bool = False):
        self.plan, self.count, self.seed, self.want_bary = plan, int(count), seed, want_bary
        self.area = plan.area

    def draw(self, start: int, stop: int) -> RawChunk:
        used, b = self.draws(self.plan, self.count, start, stop, self.seed)
        return self.plan.place(start, used, b, self.want_bary)


class StratifiedSource(_PlacedSource):
    """Systematic sampling over the area CDF (:func:`scatter_cli.sampling.methods.stratified_draws`):
    point i depends on the count too, so a run of N is not a prefix of a run of N + 1."""

    draws = staticmethod(stratified_draws)


class SobolSource(_PlacedSource):
    """Owen-scrambled Sobol points (:func:`scatter_cli.sampling.methods.sobol_draws`), at most 2^32."""

    draws = staticmethod(sobol_draws)

    def __init__(self, plan: SamplePlan, count: int, seed: int, want_bary: bool = False):
        if count > SOBOL_MAX_COUNT:
            raise ValueError(f"a Sobol source gives at most {SOBOL_MAX_COUNT:,} points, not {count:,}")
        super().__init__(plan, count, seed, want_bary)


METHOD_SOURCES = {"random": RandomSource, "stratified": StratifiedSource, "sobol": SobolSource}
"""--method name -> source class, each built as cls(plan, count, seed, want_bary)."""


def make_source(plan: SamplePlan, count: int, seed: int, want_bary: bool = False, *, method: str = "random",
                weighting=None, area: float | None = None) -> Source:
    """The source of ``count`` points of ``--method method``, or of a weighting (then
    ``plan`` is its :func:`~scatter_cli.sampling.weighting.weighted_plan` and ``area`` the
    surface's unweighted area)."""
    if weighting is not None:
        from .weighting import weighted_source

        return weighted_source(plan, weighting, count, seed, want_bary, area)
    return METHOD_SOURCES[method](plan, count, seed, want_bary)
