"""``--stable --radius R``: the candidate horizon of the stable arrivals (the dart throwing
that thins them is :func:`scatter_cli.sampling.poisson.thinning.dart_thrown`; the policy,
RADIUS_OVERSAMPLING, lives in :mod:`scatter_cli.sampling.poisson.thinning`)."""

from __future__ import annotations

import math

from ...errors import ScatterError
from ..poisson.thinning import RADIUS_OVERSAMPLING


def radius_horizon(radius, rate, area, source, max_candidates):
    """The time before which arrivals are the candidates of ``--radius R``: candidates at
    RADIUS_OVERSAMPLING times the hexagonal density of spacing R (a time per unit area,
    the same for every face, so an edit moves only nearby points). ``rate``: arrivals
    per unit time over the surface."""
    tau = RADIUS_OVERSAMPLING / (math.sqrt(3) / 2 * radius * radius)
    expected = tau * rate
    if max_candidates is not None and expected > max_candidates:
        raise ScatterError(f"--radius {radius:g} is too small for {source} (area {area:.6g}): thinning "
                           f"would need {expected:,.0f} candidates, more than {max_candidates:,}")
    return tau
