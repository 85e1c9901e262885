"""``--weight`` for ``--stable``: the rates and in-face warps of a weighted stable run."""

from __future__ import annotations

import numpy as np


class VertexColorRates:
    """``--weight vertex-color:C`` for the stable source: rate area times the face's mean
    weight, positions by the weighting's exact in-face mixture warp."""

    def __init__(self, weight):
        from .. import weighting

        # {geometry: (F, 3) corner weights}, and the mixture warp (w (n, 3), u (n, 3)) -> (n, 2)
        self._w = weight.corner_w if hasattr(weight, "corner_w") else weight._corner_w
        self.barycentric = getattr(weighting, "barycentric", None) or weight.barycentric
        self.surface = weight.surface

    def face_weights_of(self, k, inst):
        return self._w[inst.geometry]

    def corner_weights(self, part, face):
        """(n, 3) corner weights of faces ``face`` (n,) of instances ``part`` (n,)."""
        out = np.empty((len(face), 3))
        for k in np.unique(part):
            rows = np.flatnonzero(part == k)
            out[rows] = self._w[self.surface.instances[k].geometry][face[rows]]
        return out


class TextureRates:
    """``--weight texture:C`` for the stable source: arrivals at rate area times the
    weight's bound over the geometry, each kept with probability weight / bound (a
    thinned Poisson process: rate area times weight, face by face)."""

    def __init__(self, weight):
        self._weight = weight
        self._bound = weight._bound
        self._inst_bound = np.array([weight._bound[i.geometry] for i in weight.surface.instances])

    def face_weights_of(self, k, inst):
        return np.full(len(self._weight.surface.geometries[inst.geometry].faces), self._bound[inst.geometry])

    def accept(self, raw, u):
        return u * self._inst_bound[raw.instance] < self._weight.weight(raw)


def stable_weight(surface, spec):
    """The stable source's form of ``--weight spec``."""
    from ..weighting import TextureWeight, VertexColorWeight, parse_weight

    source, channel = parse_weight(spec)
    if source == "vertex-color":
        return VertexColorRates(VertexColorWeight(surface, channel, spec))
    return TextureRates(TextureWeight(surface, channel, spec))
