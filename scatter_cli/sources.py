"""Sources of points: one interface for every way a run makes its points.

A source is built once per run with everything it needs fixed (the sample plan, the
seed, the point count, whether barycentric weights are wanted, a weighting, the
candidates it thins) and then answers one question, "points ``start .. stop - 1``"::

    class Source(Protocol):
        count: int     # N: the source gives points 0 .. N - 1
        area: float    # area of the surface the points lie on (unweighted, world space)
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

A source that filters or reorders another one (thinning, and next ``--exterior``) is
built from that source by a function returning a new source; nothing is changed in
place. The sources here: :class:`RandomSource`, :class:`StratifiedSource`,
:class:`SobolSource`, :class:`ThinnedSource` (from :func:`thinned`); the weighted ones,
:class:`~scatter_cli.weighting.VertexColorSource` and
:class:`~scatter_cli.weighting.TextureSource`, live with their weighting.
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np

from .methods import SOBOL_MAX_COUNT, sobol_draws, stratified_draws
from .sampling import RawChunk, SamplePlan, in_blocks


class Source(Protocol):
    """The interface every source of points implements (see the module docstring)."""

    count: int
    area: float

    def draw(self, start: int, stop: int) -> RawChunk: ...


class RandomSource:
    """The random method: i.i.d. points, point i from draws 3 i .. 3 i + 2 of the seed's
    stream (:meth:`SamplePlan.draw`), uniform over the plan's (area-weighted) faces."""

    def __init__(self, plan: SamplePlan, count: int, seed: int, want_bary: bool = False):
        self.plan, self.count, self.seed, self.want_bary = plan, int(count), seed, want_bary
        self.area = plan.area

    def draw(self, start: int, stop: int) -> RawChunk:
        return self.plan.draw(start, stop, self.seed, self.want_bary)


class _PlacedSource:
    """A method that maps point indices to (used faces, barycentrics), placed by the plan."""

    def __init__(self, plan: SamplePlan, count: int, seed: int, want_bary: bool = False):
        self.plan, self.count, self.seed, self.want_bary = plan, int(count), seed, want_bary
        self.area = plan.area

    def draw(self, start: int, stop: int) -> RawChunk:
        used, b = self.draws(self.plan, self.count, start, stop, self.seed)
        return self.plan.place(start, used, b, self.want_bary)


class StratifiedSource(_PlacedSource):
    """Systematic sampling over the area CDF (:func:`scatter_cli.methods.stratified_draws`):
    point i depends on the count too, so a run of N is not a prefix of a run of N + 1."""

    draws = staticmethod(stratified_draws)


class SobolSource(_PlacedSource):
    """Owen-scrambled Sobol points (:func:`scatter_cli.methods.sobol_draws`), at most 2^32."""

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
    ``plan`` is its :func:`~scatter_cli.weighting.weighted_plan` and ``area`` the
    surface's unweighted area)."""
    if weighting is not None:
        from .weighting import weighted_source

        return weighted_source(plan, weighting, count, seed, want_bary, area)
    return METHOD_SOURCES[method](plan, count, seed, want_bary)


class ThinnedSource:
    """The points of ``kept`` (a RawChunk starting at 0), chosen out of ``candidates``."""

    def __init__(self, kept: RawChunk, candidates: Source):
        self.kept, self.candidates = kept, candidates
        self.count = len(kept.points)
        self.area = candidates.area

    def draw(self, start: int, stop: int) -> RawChunk:
        return self.kept.slice(start, stop)


def thinned(candidates: Source, count: int | None = None, radius: float | None = None):
    """A Poisson-disk subset of all the points of ``candidates``: (ThinnedSource, info).

    ``radius`` given: a maximal set with no two points closer than it; else exactly
    ``count`` points, spaced as far apart as the search reaches. ``info`` holds
    ``count``, ``candidates``, ``radius``, (exact count) ``d_min`` and ``rho``, and the
    ``timings`` of drawing and of thinning.
    """
    from . import thinning
    from .spacing import relative_radius

    t = time.perf_counter()
    blocks = in_blocks(candidates.draw, candidates.count)
    points = np.concatenate([b.points for b in blocks]) if len(blocks) > 1 else blocks[0].points
    t1 = time.perf_counter()
    if radius is not None:
        index, d_min = thinning.thin_by_radius(points, radius), None
    else:
        index, d_min = thinning.thin_to_count(points, count, candidates.area)
    source = ThinnedSource(_take(blocks, index), candidates)
    info = {"count": source.count, "candidates": candidates.count, "radius": radius}
    if d_min is not None:
        info.update(d_min=d_min, rho=relative_radius(d_min, candidates.area, source.count))
    info["timings"] = {"candidates": t1 - t, "thinning": time.perf_counter() - t1}
    return source, info


def _take(blocks, index):
    """Rows ``index`` (k,) ascending of the chunks ``blocks`` end to end, as one chunk."""
    ends = np.cumsum([len(b.points) for b in blocks])
    cuts = np.searchsorted(index, ends)
    return RawChunk.join([b.take(part - (end - len(b.points)))
                          for b, part, end in zip(blocks, np.split(index, cuts[:-1]), ends)])
