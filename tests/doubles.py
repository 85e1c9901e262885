"""Test doubles: broken samplers that the statistical tests must reject.

Each is built the way the real ones are, through the point-source protocol
(:mod:`scatter_cli.sampling.sources`) or as a plan a real source draws from.
"""

import numpy as np

from scatter_cli.sampling.plan import SamplePlan, _guide_table, uniforms
from scatter_cli.sampling.warps import square_to_triangle


class UnweightedSource:
    """The classic bug: every face equally likely, whatever its area (otherwise the
    random method: the same draws, the same warp)."""

    def __init__(self, plan: SamplePlan, count: int, seed: int = 0, want_bary: bool = False):
        self.plan, self.count, self.seed, self.want_bary = plan, count, seed, want_bary
        self.area = plan.area

    def draw(self, start, stop):
        u = uniforms(self.seed, start, stop)
        faces = self.plan.faces_used
        used = np.minimum((u[:, 0] * faces).astype(np.int64), faces - 1)
        return self.plan.place(start, used, square_to_triangle(u[:, 1:3]), self.want_bary)


class Float32CdfPlan(SamplePlan):
    """Broken subtly: the CDF accumulated in float32, so small faces round away."""

    def __init__(self, surface):
        super().__init__(surface)
        steps = np.diff(self.cdf, prepend=0.0).astype(np.float32)
        self.cdf = np.cumsum(steps, dtype=np.float32).astype(np.float64)
        self.guide = _guide_table(self.cdf)


class RestartingSource(UnweightedSource):
    """Broken protocol: draws from the stream's beginning whatever ``start`` is, so a
    chunked run repeats its first points (a source must start its stream at ``start``)."""

    def draw(self, start, stop):
        raw = super().draw(0, stop - start)
        raw.start = start
        return raw
