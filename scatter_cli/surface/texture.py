"""Texture lookup: bilinear filtering with the glTF sampler wrap modes.

Pillow is imported only by :meth:`Texture.pixels`, the first time a texel is needed, so
a run that asks for no colour and no texture weight never decodes an image.

Wrap modes: trimesh does not keep the glTF sampler of a material's texture, so
every texture is sampled with REPEAT (the glTF default). :func:`bilinear` implements
CLAMP_TO_EDGE and MIRRORED_REPEAT too, for a loader that gives the sampler.

Colour: texture RGBA times the material's base colour factor, both taken as stored
(sRGB-encoded bytes; no linearisation), rounded to uint8.

Conventions: ``uv`` is as trimesh presents it (origin at the bottom-left of the image,
v up). Texel ``(i, j)`` (column, row from the top) has its centre at
``u = (i + 0.5) / W``, ``v = 1 - (j + 0.5) / H``, as in OpenGL/glTF sampling.
"""

from __future__ import annotations

import threading

import numpy as np

REPEAT, CLAMP_TO_EDGE, MIRRORED_REPEAT = 10497, 33071, 33648


class Texture:
    """An image and its wrap modes; the pixels are decoded once, on first use.

    ``image`` is a PIL image (possibly not yet decoded) or an (H, W, 4) uint8 array.
    """

    def __init__(self, image, wrap_s=REPEAT, wrap_t=REPEAT, source="<texture>"):
        self.image = image
        self.wrap_s, self.wrap_t = wrap_s, wrap_t
        self.source = source
        self._pixels = None
        self._lock = threading.Lock()

    def pixels(self):
        """(H, W, 4) uint8 RGBA, decoded on the first call."""
        with self._lock:
            if self._pixels is None:
                self._pixels = decode(self.image, self.source)
            return self._pixels

    def channel_max(self, channel: int) -> float:
        """Largest value of one channel (0..255), the bound bilinear filtering never exceeds."""
        return float(self.pixels()[..., channel].max())

    def lookup(self, uv):
        """Bilinear RGBA at ``uv`` (n, 2) float -> (n, 4) float64 in [0, 255]."""
        return bilinear(self.pixels(), uv, self.wrap_s, self.wrap_t)


def decode(image, source="<texture>"):
    """A PIL image or an array -> (H, W, 4) uint8 RGBA."""
    if isinstance(image, np.ndarray):
        arr = image
        if arr.ndim == 2:
            arr = np.repeat(arr[..., None], 3, axis=2)
        if arr.shape[2] == 3:
            arr = np.concatenate([arr, np.full(arr.shape[:2] + (1,), 255, arr.dtype)], axis=2)
        return np.ascontiguousarray(arr, dtype=np.uint8)
    try:
        from PIL import Image  # noqa: F401  (the optional `texture` extra)
    except ImportError:
        from ..errors import ScatterError

        raise ScatterError(f"{source}: decoding the texture needs Pillow (pip install pillow)") from None
    return np.ascontiguousarray(np.asarray(image.convert("RGBA")), dtype=np.uint8)


def wrap_index(i, size, mode):
    """Texel indices ``i`` (n,) int64 folded into ``[0, size)`` by a glTF wrap mode."""
    if mode == CLAMP_TO_EDGE:
        return np.clip(i, 0, size - 1)
    if mode == MIRRORED_REPEAT:
        m = np.mod(i, 2 * size)
        return np.where(m < size, m, 2 * size - 1 - m)
    return np.mod(i, size)


def bilinear(pixels, uv, wrap_s=REPEAT, wrap_t=REPEAT):
    """Bilinear filtering of ``pixels`` (H, W, C) at ``uv`` (n, 2) -> (n, C) float64.

    The four texels around each point are fetched with the wrap modes applied to their
    indices, so REPEAT blends across the seam and CLAMP_TO_EDGE holds the border texel.
    """
    h, w, c = pixels.shape
    uv = np.asarray(uv, dtype=np.float64)
    x = uv[:, 0] * w - 0.5
    y = (1.0 - uv[:, 1]) * h - 0.5
    with np.errstate(invalid="ignore"):
        x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    # Non-finite UVs give texel 0 (and NaN weights would poison the blend).
    bad = ~(np.isfinite(fx) & np.isfinite(fy))
    if bad.any():
        x0[bad] = y0[bad] = fx[bad] = fy[bad] = 0.0
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xs = (wrap_index(x0, w, wrap_s), wrap_index(x0 + 1, w, wrap_s))
    ys = (wrap_index(y0, h, wrap_t) * w, wrap_index(y0 + 1, h, wrap_t) * w)
    flat = pixels.reshape(h * w, c)
    out = np.zeros((len(uv), c))
    for yi, wy in zip(ys, (1.0 - fy, fy)):
        for xi, wx in zip(xs, (1.0 - fx, fx)):
            out += flat[yi + xi] * (wy * wx)[:, None]
    return out
