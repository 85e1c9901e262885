"""Whether the signs of a run mean much: the share of its points whose inside or outside
rests on a winding number near 1/2.

On a closed surface the winding number w is 0 or 1 away from the surface, and ``w >=
0.5`` is a sure label. On an open one (a terrain, a sheet, a bowl) w drifts towards 1/2
around the holes, and a label there is close to a coin flip: a run says so when more
than ``WARN_SHARE`` of its points have ``|w - 0.5| < NEAR_HALF``.
"""

from __future__ import annotations

import threading

import numpy as np

NEAR_HALF = 0.2  # |w - 0.5| below this: the label is close to a coin flip
WARN_SHARE = 0.01  # a run warns when more than this share of its points is near 1/2


def unclear(winding):
    """(n,) bool: the points whose winding numbers ``winding`` (n,) are within
    ``NEAR_HALF`` of 1/2."""
    return np.abs(winding - 0.5) < NEAR_HALF


def percent(share: float) -> str:
    return f"{100 * share:.3g} %"


def sign_warning(source: str, points: int, near_half: int):
    """The warning of a run of ``source`` whose signs rest on the winding numbers of
    ``points`` points, ``near_half`` of them near 1/2, or None when few are."""
    if not points or near_half <= WARN_SHARE * points:
        return None
    return (f"{source}: {percent(near_half / points)} of the points have a winding number within {NEAR_HALF:g} of "
            f"0.5: their inside/outside signs are close to coin flips (an open surface such as a terrain or a sheet "
            f"has no inside worth the name; see scatter info)")


class SignTally:
    """The points labelled by their winding numbers and those near 1/2, added up chunk
    by chunk from any thread (``add``) and taken once the run is done (``take``)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._counts = [0, 0]

    def add(self, winding):
        k = int(np.count_nonzero(unclear(winding)))
        with self._lock:
            self._counts[0] += len(winding)
            self._counts[1] += k

    def take(self):
        """(points, near half) since the last ``take``."""
        with self._lock:
            counts, self._counts = tuple(self._counts), [0, 0]
        return counts
