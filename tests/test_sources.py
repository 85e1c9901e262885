"""The point-source protocol holds for every source: ``draw(a, b)`` over any cuts joins
to ``draw(0, N)`` byte for byte, the chunks carry absolute starts and barycentrics only
when asked, and ``Run.chunks(s, t)`` is the slice s:t of the whole run."""

import functools

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from scatter_cli import api
from scatter_cli.sampling.plan import SamplePlan
from scatter_cli.run.pipeline import plan_surface
from scatter_cli.sampling.sources import METHOD_SOURCES, make_source
from scatter_cli.sampling.plan import RawChunk
from scatter_cli.sampling.poisson.thinning import ThinnedSource, dart_thrown, thinned
from scatter_cli.loading.load import load_surface

from .conftest import SAMPLES
from .doubles import RestartingSource

N = 1000
FIELDS = ("points", "face", "instance", "bary")


@functools.lru_cache(maxsize=None)
def surface(name):
    return load_surface(SAMPLES / name)


def _weighted(name, spec, want_bary):
    surface = load_surface(SAMPLES / name)  # its own: a weighting reads the file's colours
    plan, weighting, area = plan_surface(surface, spec)
    return make_source(plan, N, 4, want_bary, weighting=weighting, area=area)


def _method(method, want_bary, mesh="cesiummilktruck.glb"):
    return METHOD_SOURCES[method](SamplePlan(surface(mesh)), N, 4, want_bary)


def _thinned(want_bary, radius=None):
    candidates = METHOD_SOURCES["random"](SamplePlan(surface("cesiummilktruck.glb")), 8 * 300, 4, want_bary)
    return thinned(candidates, None if radius else 300, radius)[0]


def _stable(want_bary, **how):
    from scatter_cli.sampling.stable.source import StableSource

    return StableSource(surface("cesiummilktruck.glb"), 4, want_bary=want_bary, **how)


def _dart_thrown(want_bary):
    return dart_thrown(_stable(want_bary, radius=0.3), 0.3)


def _exterior(want_bary, method="random", **how):
    from scatter_cli.sampling.exterior.filter import ExteriorSource, ExteriorSubset
    from scatter_cli.sampling.exterior.rays import Occluder

    plan = SamplePlan(surface("cesiummilktruck.glb"))
    occluder = Occluder(plan.surface)
    if method == "stratified":
        return ExteriorSubset(lambda m: METHOD_SOURCES[method](plan, m, 4, want_bary), occluder, 4, plan.area, N)
    return ExteriorSource(METHOD_SOURCES[method](plan, N, 4, want_bary), occluder, 4, plan.area, **how)


BUILDERS = {
    "random": lambda b: _method("random", b),
    "random, one mesh": lambda b: _method("random", b, "spot_triangulated.obj"),
    "stratified": lambda b: _method("stratified", b),
    "sobol": lambda b: _method("sobol", b),
    "vertex-color": lambda b: _weighted("boxvertexcolors.glb", "vertex-color:g", b),
    "texture": lambda b: _weighted("boxtextured.glb", "texture:r", b),
    "thinned to a count": lambda b: _thinned(b),
    "thinned to a radius": lambda b: _thinned(b, radius=0.3),
    "stable, N earliest": lambda b: _stable(b, count=N),
    "stable, before a density": lambda b: _stable(b, density=40.0),
    "stable, dart thrown": _dart_thrown,
    "exterior, exactly N": lambda b: _exterior(b, count=N),
    "exterior, among N candidates": lambda b: _exterior(b, candidates=N),
    "exterior subset of stratified": lambda b: _exterior(b, "stratified"),
}
THINNED = {"thinned to a count", "thinned to a radius", "stable, dart thrown"}
FILTERED = {"exterior, exactly N", "exterior, among N candidates", "exterior subset of stratified"}
_built = {}


def source(kind, want_bary):
    """(source, the bytes of its whole draw), built once."""
    if (kind, want_bary) not in _built:
        src = BUILDERS[kind](want_bary)
        _built[kind, want_bary] = src, whole(src)
    return _built[kind, want_bary]


def joined(src, cuts):
    """draw() over the ranges between ``cuts`` (sorted, within 0..count), end to end."""
    edges = [0, *cuts, src.count]
    chunks = [src.draw(a, b) for a, b in zip(edges[:-1], edges[1:])]
    assert [c.start for c in chunks] == edges[:-1]
    return {f: None if chunks[0].bary is None and f == "bary" else
            np.concatenate([getattr(c, f) for c in chunks]).tobytes() for f in FIELDS}


def whole(src):
    raw = src.draw(0, src.count)
    return {f: None if getattr(raw, f) is None else np.asarray(getattr(raw, f)).tobytes() for f in FIELDS}


cuts = st.lists(st.integers(0, N), max_size=6).map(sorted)


@pytest.mark.slow
@pytest.mark.parametrize("want_bary", [False, True])
@pytest.mark.parametrize("kind", list(BUILDERS))
@settings(max_examples=15)
@given(cuts=cuts)
def test_draw_over_any_cuts_is_the_whole_draw(kind, want_bary, cuts):
    src, expect = source(kind, want_bary)
    cuts = [c * src.count // N for c in cuts]  # the thinned sets hold fewer than N
    assert joined(src, cuts) == expect


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_barycentrics_only_when_asked(kind):
    without, with_bary = source(kind, False)[0].draw(5, 50), source(kind, True)[0].draw(5, 50)
    assert without.bary is None and with_bary.bary.shape == (45, 3)
    np.testing.assert_array_equal(with_bary.points, without.points)


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_every_source_declares_what_callers_read(kind):
    """The protocol's attributes, on every source: a caller reads them, it never sniffs."""
    src = source(kind, False)[0]
    assert isinstance(src.count, int) and src.count > 0 and src.area > 0
    if kind in THINNED:
        assert isinstance(src.kept, RawChunk) and len(src.kept.points) == src.count
    else:
        assert src.kept is None
    if kind in FILTERED:
        assert 0 < src.stats["exterior_fraction"] <= 1 and src.area == pytest.approx(src.stats["exterior_area"])
    else:
        assert src.stats is None


def test_a_source_that_restarts_its_stream_fails_the_same_check():
    src = RestartingSource(SamplePlan(surface("cesiummilktruck.glb")), N, 4)
    assert joined(src, [300, 700]) != whole(src)


@pytest.fixture(scope="module")
def runs():
    box = trimesh.creation.box()
    return {
        "random": api.prepare(surface("cesiummilktruck.glb"), N, attributes=("face", "object", "bary"), seed=2,
                              chunk_size=256),
        "stratified": api.prepare(box, N, method="stratified", attributes=("normal",), seed=2, chunk_size=333),
        "poisson": api.prepare(surface("cesiummilktruck.glb"), 300, poisson=True, attributes=("face",), seed=2,
                               chunk_size=64),
        "texture": api.prepare(SAMPLES / "boxtextured.glb", N, weight="texture:r", attributes=("color",), seed=2,
                               chunk_size=100),
    }


@pytest.fixture(scope="module")
def collected(runs):
    return {kind: run.collect() for kind, run in runs.items()}


@pytest.mark.parametrize("kind", ["random", "stratified", "poisson", "texture"])
@settings(max_examples=15)
@given(data=st.data())
def test_run_chunks_of_a_range_are_the_slice_of_the_run(runs, collected, kind, data):
    run, full = runs[kind], collected[kind]
    s = data.draw(st.integers(0, run.count))
    t = data.draw(st.integers(s, run.count))
    part = list(run.chunks(s, t))
    assert all(0 < len(c) <= run.chunk_size for c in part)
    assert b"".join(c.points.tobytes() for c in part) == full.points[s:t].tobytes()
    for key, values in full.attributes.items():
        assert b"".join(c.attributes[key].tobytes() for c in part) == values[s:t].tobytes()


def test_run_chunks_refuse_a_range_outside_the_run(runs):
    with pytest.raises(ValueError):
        next(runs["random"].chunks(10, N + 1))
    with pytest.raises(ValueError):
        next(runs["random"].chunks(20, 10))


def test_thinning_makes_a_new_source():
    candidates = METHOD_SOURCES["random"](SamplePlan(surface("cesiummilktruck.glb")), 4000, 1)
    thin, info = thinned(candidates, 300)
    assert isinstance(thin, ThinnedSource) and thin.count == info["count"] == 300
    assert candidates.count == info["candidates"] == 4000 and thin.candidates is candidates
    assert thin.area == candidates.area


def test_a_run_reads_the_kept_points_from_its_source(runs):
    assert runs["random"].kept is None and runs["stratified"].kept is None
    kept = runs["poisson"].kept
    assert len(kept.points) == runs["poisson"].count == 300
    np.testing.assert_array_equal(kept.points, runs["poisson"].source.draw(0, 300).points)
