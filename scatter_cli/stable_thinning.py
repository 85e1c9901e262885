"""``--stable --radius R``: the candidate horizon and the dart throwing that thins the
stable arrivals. The thinning policy (RADIUS_OVERSAMPLING) comes from the API for now:
the one import of :mod:`scatter_cli.api` of the stable modules, kept here alone so that
moving the policy to the thinning modules touches this file only.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ScatterUsageError


def radius_horizon(radius, rate, area, source, max_candidates):
    """The time before which arrivals are the candidates of ``--radius R``: candidates at
    RADIUS_OVERSAMPLING times the hexagonal density of spacing R (a time per unit area,
    the same for every face, so an edit moves only nearby points). ``rate``: arrivals
    per unit time over the surface."""
    from .api import RADIUS_OVERSAMPLING

    tau = RADIUS_OVERSAMPLING / (math.sqrt(3) / 2 * radius * radius)
    expected = tau * rate
    if max_candidates is not None and expected > max_candidates:
        raise ScatterUsageError(f"--radius {radius:g} is too small for {source} (area "
                                f"{area:.6g}): thinning would need {expected:,.0f} candidates, more than "
                                f"{max_candidates:,}")
    return tau


def dart_thrown(source, radius):
    """A :class:`~scatter_cli.sources.ThinnedSource` of ``source``'s points, each kept in
    order when no point kept before it lies within ``radius``: every kept pair at least R
    apart, every point within R of a kept one, and the kept set is as local as the order."""
    from . import greedy, pairs
    from .sources import ThinnedSource

    raw = source.draw(0, source.count)
    i, j, _ = pairs.all_pairs(raw.points, radius)
    kept = np.flatnonzero(greedy.in_priority_order(len(raw.points), i, j, np.arange(len(raw.points))))
    return ThinnedSource(raw.take(kept), source)
