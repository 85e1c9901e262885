"""Density weighting: ``--weight vertex-color:C`` or ``--weight texture:C`` (C in r, g, b, a).

The density over the surface is proportional to a weight ``w(p)`` in [0, 1] read from
the file: a colour channel, interpolated with the barycentric coordinates (vertex
colours) or looked up in the texture at the interpolated UV (bilinear, glTF wrap modes).

Both samplers keep the determinism contract of :mod:`scatter_cli.sampling.plan`: point ``i``
uses fixed stream positions, so the output does not depend on chunk size or threads.

vertex-color (exact, no rejection): inside a face, ``w = sum_k w_k b_k`` is linear, so
the face gets probability ``area * (w_0 + w_1 + w_2) / 3`` (its exact mean weight) and
the density inside it is the mixture ``sum_k (w_k / sum w) * 6 b_k``. Point ``i`` uses
draws ``4 i .. 4 i + 3``: face, mixture component ``k``, then a warp to the density
``6 b_k``: ``t = 1 - b_k`` has density ``6 t (1 - t)`` (CDF ``3 t^2 - 2 t^3``, inverted in
closed form as ``t = 1/2 + sin(asin(2 u - 1) / 3)``) and the point is uniform along the
segment ``b_k = 1 - t``.

texture (exact, rejection): a face is proposed with probability proportional to area
times a bound ``M`` of the weight over its geometry (the texture channel's maximum,
which bilinear filtering never exceeds), a point uniformly inside it, and accepted with
probability ``w / M``. Round 0 uses draws ``4 i .. 4 i + 3`` of the main stream (face,
two warp inputs, acceptance); a point rejected in rounds ``0 .. r - 1`` uses draws
``4 i ..`` of round ``r``'s own stream. Each point's fate depends only on its own draws.
"""

from __future__ import annotations

import numpy as np

from ..core.elementary import asin, sin
from ..errors import ScatterError, ScatterUsageError
from ..loading import textures as textures_named
from .plan import SamplePlan
from ..surface.model import Surface
from ..surface.data import color_source
from .warps import square_to_triangle

SOURCES = ("vertex-color", "texture")
CHANNELS = "rgba"
DRAWS_PER_POINT = 4
MAX_ROUNDS = 10_000


def parse_weight(text):
    """``"texture:a"`` -> ("texture", 3)."""
    source, _, channel = str(text).strip().lower().partition(":")
    if source not in SOURCES or len(channel) != 1 or channel not in CHANNELS:
        raise ScatterUsageError(
            f"--weight must be one of vertex-color:r|g|b|a or texture:r|g|b|a, not {text!r}")
    return source, CHANNELS.index(channel)


def stream(seed: int, round_: int, start: int, stop: int):
    """Draws for points ``start .. stop - 1`` in rejection round ``round_``: (n, 4) float64.

    Round 0 is the run's main stream (the one :func:`scatter_cli.sampling.plan.uniforms`
    uses); later rounds have streams of their own, seeded from (seed, round).
    """
    bits = np.random.PCG64DXSM(seed if round_ == 0 else np.random.SeedSequence([seed, round_]))
    bits.advance(DRAWS_PER_POINT * start)
    return np.random.Generator(bits).random((stop - start, DRAWS_PER_POINT))


def weighted_plan(surface: Surface, weight):
    """The plan whose face CDF is area times ``weight.face_weights``."""
    try:
        return SamplePlan(surface, weights=weight.face_weights)
    except ScatterError:
        raise ScatterError(f"{surface.source}: --weight {weight.spec}: the weight is zero over the whole surface") from None


def read_weight(surface: Surface, spec):
    """The weight ``--weight spec`` reads from ``surface``'s colours or textures."""
    source, channel = parse_weight(spec)
    cls = VertexColorWeight if source == "vertex-color" else TextureWeight
    return cls(surface, channel, spec)


def weighted_source(plan, weight, count: int, seed: int, want_bary: bool, area: float):
    """The source of ``count`` points with density proportional to ``weight``, from
    ``plan = weighted_plan(surface, weight)``; ``area``: the surface's unweighted area."""
    cls = VertexColorSource if isinstance(weight, VertexColorWeight) else TextureSource
    return cls(plan, weight, count, seed, want_bary, area)


class _Weight:
    """A weight in [0, 1] over a surface, read from the file: the per-geometry colour
    sources and the per-face weights the plan's CDF multiplies the areas by."""

    def __init__(self, surface, channel, spec):
        self.surface, self.channel, self.spec = surface, channel, spec
        self._sources = {}
        textures = surface._cache.setdefault("textures", {})
        for gi in dict.fromkeys(i.geometry for i in surface.instances):
            g = surface.geometries[gi]
            src = color_source(g.mesh, g.faces, surface.source, textures)
            if src is None or src.kind not in self.kinds:
                where = f"object '{g.name}' has" if surface.is_scene else "the mesh has"
                raise ScatterError(f"{surface.source}: cannot use --weight {spec}: {where} no {self.what}")
            self._sources[gi] = src


class VertexColorWeight(_Weight):
    kinds = ("vertex",)
    what = "vertex colours"

    def __init__(self, surface, channel, spec):
        super().__init__(surface, channel, spec)
        # (F, 3) weights of each face's corners, per geometry.
        self.corner_w = {gi: src.table[:, channel][src.faces] / 255.0 for gi, src in self._sources.items()}

    def face_weights(self, k, inst):
        """(F,) exact mean weight of each face of instance k."""
        return self.corner_w[inst.geometry].mean(axis=1)


class TextureWeight(_Weight):
    kinds = ("texture", "constant")
    what = "texture or material colour"

    def __init__(self, surface, channel, spec):
        textures_named.require_pillow(surface.source)
        super().__init__(surface, channel, spec)
        self._bound = {}
        for gi, src in self._sources.items():
            src.prepare()
            top = src.texture.channel_max(channel) if src.kind == "texture" else 255.0
            if src.factor is not None:
                top = top * src.factor[channel] / 255.0
            self._bound[gi] = top / 255.0
        # (instances,) the bound of each instance's geometry
        self.instance_bound = np.array([self._bound[i.geometry] for i in surface.instances])

    def face_weights(self, k, inst):
        """(F,) the bound of the weight over the geometry (rejection makes it exact)."""
        return np.full(len(self.surface.geometries[inst.geometry].faces), self._bound[inst.geometry])

    def weight(self, raw):
        """(n,) weight in [0, 1] at the points of ``raw`` (bary required)."""
        out = np.empty(len(raw.face))
        instances = np.unique(raw.instance)
        for k in instances:
            rows = np.flatnonzero(raw.instance == k) if len(instances) > 1 else slice(None)
            src = self._sources[self.surface.instances[k].geometry]
            out[rows] = src.colors(raw.face[rows], raw.bary[rows])[:, self.channel] / 255.0
        return out


class _WeightedSource:
    kept = stats = None  # (the Source protocol: neither thinned nor filtered)

    def __init__(self, plan, weight, count, seed, want_bary, area):
        self.plan, self.weight, self.count, self.seed, self.want_bary = plan, weight, int(count), seed, want_bary
        self.area = area


class VertexColorSource(_WeightedSource):
    """Points with density proportional to a vertex-colour channel (exact, no rejection)."""

    def __init__(self, plan, weight, count, seed, want_bary, area):
        super().__init__(plan, weight, count, seed, want_bary, area)
        # (N, 3) corner weights of the plan's used faces, in CDF order.
        rows = []
        for p in plan.parts:
            w = weight.corner_w[plan.surface.instances[p.instance].geometry]
            rows.append(w if p.faces is None else w[p.faces])
        self._used_w = np.concatenate(rows)

    def draw(self, start, stop):
        u = stream(self.seed, 0, start, stop)
        used = self.plan.select(u[:, 0])
        return self.plan.place(start, used, barycentric(self._used_w[used], u[:, 1:]), self.want_bary)


def barycentric(w, u):
    """Corner weights ``w`` (n, 3) >= 0 and draws ``u`` (n, 3) -> (b1, b2) (n, 2)
    distributed with density proportional to ``w0 b0 + w1 b1 + w2 b2``."""
    n = len(w)
    c = np.cumsum(w, axis=1)
    x = u[:, 0] * c[:, 2]
    k = (x >= c[:, 0]).astype(np.int64) + (x >= c[:, 1])
    # A draw that rounds onto a zero-weight component goes to the heaviest one.
    zero = w[np.arange(n), k] <= 0
    if zero.any():
        k[zero] = np.argmax(w[zero], axis=1)
    t = 0.5 + sin(asin(2.0 * u[:, 1] - 1.0) / 3.0)
    np.clip(t, 0.0, 1.0, out=t)
    b = np.empty((n, 3))
    rows = np.arange(n)
    b[rows, k] = 1.0 - t
    b[rows, (k + 1) % 3] = t * u[:, 2]
    b[rows, (k + 2) % 3] = t - t * u[:, 2]
    return b[:, 1:]


class TextureSource(_WeightedSource):
    """Points with density proportional to a texture channel (exact, by rejection)."""

    def draw(self, start, stop):
        plan, bound = self.plan, self.weight.instance_bound
        n = stop - start
        final_used = np.empty(n, dtype=np.int64)
        final_b = np.empty((n, 2))
        todo = np.arange(n)
        u = stream(self.seed, 0, start, stop)
        for round_ in range(MAX_ROUNDS):
            used = plan.select(u[:, 0])
            b = square_to_triangle(u[:, 1:3])
            raw = plan.place(0, used, b, want_bary=True)
            ok = u[:, 3] * bound[raw.instance] < self.weight.weight(raw)
            final_used[todo[ok]] = used[ok]
            final_b[todo[ok]] = b[ok]
            todo = todo[~ok]
            if not todo.size:
                return plan.place(start, final_used, final_b, self.want_bary)
            lo, hi = int(todo[0]), int(todo[-1]) + 1
            u = stream(self.seed, round_ + 1, start + lo, start + hi)[todo - lo]
        raise ScatterError(f"{plan.surface.source}: --weight {self.weight.spec}: the weight is zero almost everywhere "
                           f"(no point accepted after {MAX_ROUNDS} rounds)")
