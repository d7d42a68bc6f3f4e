"""Human-friendly pictures of a frame: grey and colour-coded depth side by side."""

from __future__ import annotations

import numpy as np
from PIL import Image

from sim_core.frame_io import Frame


def depth_colours(range_m: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """RGB uint8 image: near = yellow, far = blue, invalid = black (H, W, 3)."""
    rgb = np.zeros((*range_m.shape, 3), dtype=np.uint8)
    if not valid.any():
        return rgb
    r = range_m[valid]
    lo, hi = np.percentile(r, [1, 99])
    t = np.clip((range_m - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
    # A short perceptual ramp (viridis end points and middle), linearly interpolated.
    stops = np.array([[253, 231, 37], [33, 145, 140], [68, 1, 84]], dtype=np.float64)
    x = np.where(valid, t, 0.0) * 2.0
    i = np.minimum(x.astype(int), 1)
    f = (x - i)[..., None]
    col = stops[i] * (1 - f) + stops[i + 1] * f
    rgb[valid] = np.round(col[valid]).astype(np.uint8)
    return rgb


def side_by_side(frame: Frame, scale: int = 2) -> Image.Image:
    """Grey (the frame's grey image, as its grey.png) left, depth right, magnified ``scale``
    times."""
    valid = frame.image.valid
    grey = frame.grey_8bit()
    left = np.repeat(grey[..., None], 3, axis=2)
    right = depth_colours(frame.image.range_m, valid)
    gap = np.full((grey.shape[0], 4, 3), 255, dtype=np.uint8)
    img = Image.fromarray(np.concatenate([left, gap, right], axis=1))
    return img.resize((img.width * scale, img.height * scale), Image.NEAREST)
