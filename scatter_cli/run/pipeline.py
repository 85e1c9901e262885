"""The source pipeline of a surface run: base source -> exterior filter -> thinning.

Each stage is an object with ``count`` (the points of the run at that stage), ``area``
(the unweighted area of the sampled surface, which sizes the thinning) and two ways to
get a source: ``natural()``, the stage's source of its ``count`` points, and
``source_of(n)``, a source of ``n`` points in the stage's order (the candidates a
thinning draws). :func:`surface_source` composes them; every source it returns follows
:class:`scatter_cli.sampling.sources.Source`.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import ScatterError
from .options import DEFAULT_COUNT, MAX_COUNT, SampleOptions, check_sobol_count
from ..sampling.plan import SamplePlan
from ..sampling.sources import make_source


def volume_source(surface, o: SampleOptions, info: dict, warn=None):
    """(source, labels, plan, frame, box) of the volume run of options ``o``
    (:mod:`scatter_cli.volume.source`): near points from the surface source of ``o`` (its faces,
    weight and objects), box points in the padded box, labelled against the unweighted
    sampled surface; sigmas, padding and density in the output's frame."""
    from .bounds import in_frame, normal_frame
    from ..volume.source import VolumeLabels, VolumeSource, sampling_box, world_triangles

    t = time.perf_counter()
    plan, weighting, area = plan_surface(surface, o.weight, warn)
    shape = plan if weighting is None else SamplePlan(surface)  # a weight changes the points, not the shape
    triangles, instance, face = world_triangles(shape)
    frame = normal_frame(shape, o.normalize)
    scale = 1.0 if frame is None else frame[1]
    box = sampling_box(triangles, o.box_padding)
    share = (0.0 if o.near else 1.0) if o.box_share is None else o.box_share
    count = DEFAULT_COUNT if o.count is None else o.count
    if o.density is not None:
        count = density_count(o.density * float(np.prod(box[1] - box[0])) * scale**3)
    near = with_edges(surface, o, count, lambda n: make_source(plan, n, o.seed, False, weighting=weighting, area=area),
                      False, info, warn)
    edge_sigmas = None if o.near_edges is None else [s / scale for s in o.near_edges]
    source = VolumeSource(near, count, o.seed, box, [s / scale for s in o.near or ()], share, edge_sigmas)
    labels = VolumeLabels(triangles, instance, face, o.attributes, o.sign_mode, frame)
    info.update(source=surface.source, count=count, area=area, faces=surface.face_count, faces_used=len(triangles),
                seed=o.seed, volume={"box": in_frame(box, frame).tolist(), "box_share": share, "near": list(o.near or ()),
                                     "sign": o.sign_mode})
    info["timings"]["plan"] = time.perf_counter() - t
    return source, labels, plan, frame, box


def surface_source(surface, o: SampleOptions, want_bary: bool, info: dict, warn=None):
    """(source, plan) of the surface run of options ``o``; ``info`` gets what each stage
    reports (count, area, faces, exterior statistics, thinning, timings)."""
    base = StableBase(surface, o, want_bary, info, warn) if o.stable else MethodBase(surface, o, want_bary, info, warn)
    stage = ExteriorStage(base, surface, o, info) if o.exterior else base
    if o.edge_fraction:  # (not with --stable, --exterior or thinning)
        return with_edges(surface, o, base.count, base.source_of, want_bary, info, warn), base.plan
    if not o.thinned:
        return stage.natural(), base.plan
    from ..sampling.poisson.thinning import candidate_count, dart_thrown, thinned  # (a plain run does not load the thinning)

    if o.stable:
        source = dart_thrown(stage.natural(), o.radius)
        info.update(radius=o.radius, count=source.count)
    else:
        n = candidate_count(base.area, stage.count, o.radius, surface.source, o.oversampling)
        source, thinning = thinned(stage.source_of(n), stage.count, o.radius)
        info["timings"].update(thinning.pop("timings"))
        info.update(thinning)
    return source, base.plan


class MethodBase:
    """The points of ``--method`` (or of a ``--weight``) over the surface's faces."""

    def __init__(self, surface, o: SampleOptions, want_bary, info, warn):
        t = time.perf_counter()
        self.plan, self.weighting, self.area = plan_surface(surface, o.weight, warn)
        self.count = point_count(o.count, o.density, self.area, o.method)
        self.fixed = o.density is None  # else the exterior filter keeps what it finds among count
        self.o, self.want_bary = o, want_bary
        info.update(source=surface.source, count=self.count, area=self.area, faces=surface.face_count,
                    faces_used=self.plan.faces_used, seed=o.seed, method=o.method)
        if self.weighting is not None:
            info["weight"] = o.weight
        info["timings"]["plan"] = time.perf_counter() - t

    def source_of(self, n):
        return make_source(self.plan, n, self.o.seed, self.want_bary, method=self.o.method, weighting=self.weighting,
                           area=self.area)

    def natural(self):
        return self.source_of(self.count)

    stream = natural  # what a filter reads on from: draws past ``count`` go on with the stream


class StableBase:
    """``--stable``: arrivals of a Poisson process per face (:class:`scatter_cli.sampling.stable.source.StableSource`):
    the N earliest, those before ``--density``, or the candidates of ``--radius``; an endless
    stream when the exterior filter keeps the N earliest exterior ones."""

    def __init__(self, surface, o: SampleOptions, want_bary, info, warn):
        from ..sampling.stable.source import StableSource
        from ..sampling.stable.weights import stable_weight
        from ..sampling.poisson.thinning import MAX_CANDIDATES

        t = time.perf_counter()
        self.fixed = o.density is None and o.radius is None
        n = DEFAULT_COUNT if o.count is None else o.count
        weight = stable_weight(surface, o.weight) if o.weight else None
        self.source = StableSource(surface, o.seed, count=n if self.fixed and not o.exterior else None,
                                   density=o.density, radius=o.radius, stream=self.fixed and o.exterior,
                                   want_bary=want_bary, weight=weight, max_candidates=MAX_CANDIDATES)
        self.plan = self.source.table  # the used faces, for the bounds that choose the precision
        if self.plan.non_finite and warn:
            warn(f"{surface.source}: skipped {self.plan.non_finite:,} faces with non-finite vertices")
        self.count = n if self.fixed else self.source.count
        self.area = self.source.area
        info.update(source=surface.source, count=self.source.count, area=self.area, faces=surface.face_count,
                    faces_used=len(self.plan), seed=o.seed, method="random", stable=True)
        if o.weight:
            info["weight"] = o.weight
        info["timings"]["plan"] = time.perf_counter() - t

    def natural(self):
        return self.source

    stream = natural

    def source_of(self, n):
        raise ScatterError("--stable draws no candidates: its thinning is dart throwing in arrival order")


class ExteriorStage:
    """``--exterior``: the base's points that can be seen from outside, in its order
    (:mod:`scatter_cli.sampling.exterior.filter`): exactly ``count`` of them, or (``--density``, stable
    ``--radius``) every exterior one among the base's ``count``."""

    def __init__(self, base, surface, o: SampleOptions, info):
        from ..sampling.exterior.rays import Occluder

        t = time.perf_counter()
        self.occluder = Occluder(surface)
        info["timings"]["ray_scene"] = time.perf_counter() - t
        info["timings"]["bvh_build"] = self.occluder.build_seconds  # (Embree's tree: part of ray_scene)
        self.base, self.o, self.info, self.area = base, o, info, base.area
        self.count = base.count
        self.among = None
        if not base.fixed:
            self.among = self._filtered(base.stream(), candidates=base.count)
            self.count = self.among.count

    def natural(self):
        return self.among if self.among is not None else self.source_of(self.count)

    def source_of(self, n):
        from ..sampling.exterior.filter import ExteriorSubset

        if self.o.method == "stratified":  # its strata are fixed by the count: no stream to filter
            return self._timed(lambda: ExteriorSubset(self.base.source_of, self.occluder, self.o.seed, self.area, n))
        return self._filtered(self.base.stream(), count=n)

    def _filtered(self, stream, count=None, candidates=None):
        from ..sampling.exterior.filter import ExteriorSource

        return self._timed(lambda: ExteriorSource(stream, self.occluder, self.o.seed, self.area, count=count,
                                                  candidates=candidates))

    def _timed(self, build):
        t = time.perf_counter()
        source = build()
        self.info.update(count=source.count, exterior=source.stats)
        self.info["timings"]["exterior"] = time.perf_counter() - t
        self.info["timings"]["enclosure"] = source.enclosure_seconds
        return source


def with_edges(surface, o: SampleOptions, count, faces, want_bary, info, warn=None):
    """The surface source of ``count`` points with ``--edges``: its edge points on the
    sharp edges of ``surface`` (:mod:`scatter_cli.sampling.edges`), its face points from
    ``faces(n)``, a face source of ``n`` points; without ``--edges``, or when the surface
    has no sharp edge (a warning), ``faces(count)``."""
    share = o.edge_fraction
    if not share:
        return faces(count)
    from ..sampling.edges import EdgeMixSource, EdgeTable, Interleaving

    t = time.perf_counter()
    table = EdgeTable(surface, o.angle)
    info["timings"]["edges"] = time.perf_counter() - t
    info["edges"] = {"share": float(share), "angle": o.angle, "count": len(table), "length": table.total_length}
    if not table.total_length > 0:
        if warn:
            warn(f"{surface.source}: no sharp edge at {o.angle:g} degrees: every point is a face point")
        return faces(count)
    split = Interleaving(share)
    info["edges"]["points"] = split.before(count)
    return EdgeMixSource(faces(count - split.before(count)), table, count, split, o.seed, want_bary)


def plan_surface(surface, weight=None, warn=None):
    """(plan, weighting or None, area): the face table of ``surface`` (over area times the
    weight ``--weight weight`` reads from the file, if given) and its unweighted area."""
    weighting = None
    if weight:
        from ..sampling.weighting import read_weight, weighted_plan

        weighting = read_weight(surface, weight)
        plan = weighted_plan(surface, weighting)
    else:
        plan = SamplePlan(surface)
    if plan.non_finite and warn:
        warn(f"{surface.source}: skipped {plan.non_finite:,} faces with non-finite vertices")
    area = plan.area if weighting is None else SamplePlan(surface).area  # a weighted CDF's total is no area
    return plan, weighting, area


def density_count(expected) -> int:
    """The count of a ``--density`` run whose mean count is ``expected``: past what a run can
    number, a failure of the mesh (its area or box made it so)."""
    if not expected < MAX_COUNT:  # (inf and NaN too)
        raise ScatterError(f"--density gives {expected:.3g} points: more than a run can number (2^63 - 1)")
    return int(round(expected))


def point_count(count, density, area, method="random") -> int:
    """The run's point count: ``count``, else ``density`` times ``area``, else 10,000."""
    if density is not None:
        count = density_count(density * area)
        check_sobol_count(method, count, ScatterError)  # the mesh's area made it: a failure of the mesh
    return DEFAULT_COUNT if count is None else count
