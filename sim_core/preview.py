"""Human-friendly pictures of a frame: colour-mapped images and their colour bars.

One home for how a frame is shown to a person (``toftwin preview``, the campaign report, the
operator page): matplotlib's colour maps turn values into colours, and :func:`colour_bar_png`
draws the scale that goes with an image, with its unit. Depth is ``viridis`` reversed (near =
yellow, far = blue); differences use the diverging ``RdBu_r`` (red = positive); grey levels are
shown as they are.
"""

from __future__ import annotations

import io
import threading
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from matplotlib import colormaps
from PIL import Image

from sim_core.frame_io import Frame

#: colour map of depth images: near = yellow, far = blue
DEPTH_CMAP = "viridis_r"
#: colour map of signed differences: blue negative, white zero, red positive
DIFFERENCE_CMAP = "RdBu_r"
#: colour map of grey images (grey levels shown as they are)
GREY_CMAP = "gray"

#: held around every matplotlib drawing: its text and font caches are not thread-safe, and the
#: service draws colour bars and plots from several request threads
MATPLOTLIB_LOCK = threading.Lock()


@dataclass(frozen=True)
class ColourScale:
    """How values map to colours: ``cmap`` from ``lo`` to ``hi`` (clipped), in ``unit``.

    >>> ColourScale("viridis_r", 0.8, 1.2, "m").label("depth")
    'depth [m]'
    """

    cmap: str
    lo: float
    hi: float
    unit: str

    def label(self, quantity: str) -> str:
        """``quantity [unit]``."""
        return f"{quantity} [{self.unit}]"


def colourise(values: np.ndarray, valid: np.ndarray, scale: ColourScale) -> np.ndarray:
    """RGB uint8 image (H, W, 3) of ``values`` (H, W) under ``scale``; invalid pixels black.

    >>> scale = ColourScale("gray", 0.0, 1.0, "")
    >>> colourise(np.array([[0.0, 1.0, 2.0]]), np.array([[True, True, False]]), scale)[0, :, 0]
    array([  0, 255,   0], dtype=uint8)
    """
    values = np.asarray(values, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool) & np.isfinite(values)
    # A flat image (hi == lo) would divide by zero: it maps to the scale's low end instead.
    span = max(scale.hi - scale.lo, 1e-12)
    t = np.clip((np.where(valid, values, scale.lo) - scale.lo) / span, 0.0, 1.0)
    rgba = colormaps[scale.cmap](t, bytes=True)
    rgb = np.ascontiguousarray(rgba[..., :3])
    rgb[~valid] = 0
    return rgb


def depth_scale(*ranges: tuple[np.ndarray, np.ndarray]) -> ColourScale:
    """A depth scale in metres spanning the 1st to 99th percentile of the valid pixels of every
    ``(range_m, valid)`` given (one scale for a measured and a simulated image, so that their
    colours compare). Without a valid pixel: 0 to 1 m.
    """
    vals = [np.asarray(r)[np.asarray(v, dtype=bool) & np.isfinite(r)] for r, v in ranges]
    allv = np.concatenate(vals) if vals else np.zeros(0)
    if allv.size == 0:
        return ColourScale(DEPTH_CMAP, 0.0, 1.0, "m")
    lo, hi = (float(x) for x in np.percentile(allv, [1, 99]))
    if hi - lo < 1e-3:  # a flat wall: widen to 1 mm so the bar has a readable span
        lo, hi = lo - 5e-4, hi + 5e-4
    return ColourScale(DEPTH_CMAP, lo, hi, "m")


def depth_colours(range_m: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """RGB uint8 image of a range image on its own scale (:func:`depth_scale`): near =
    yellow, far = blue, invalid = black (H, W, 3)."""
    return colourise(range_m, valid, depth_scale((range_m, valid)))


def colour_bar_png(scale: ColourScale, label: str, width_px: int = 300,
                   height_px: int = 56) -> bytes:
    """A horizontal colour bar of ``scale`` with ticks and ``label``, as PNG bytes (matplotlib).

    Cached: a page shows the same few bars over and over.
    """
    return _colour_bar_png(scale, label, width_px, height_px)


@lru_cache(maxsize=256)
def _colour_bar_png(scale: ColourScale, label: str, width_px: int, height_px: int) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colorbar import ColorbarBase
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    dpi = 100
    with MATPLOTLIB_LOCK:
        fig = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi)
        FigureCanvasAgg(fig)
        ax = fig.add_axes((0.04, 0.52, 0.92, 0.26))
        # hi == lo would make matplotlib's Normalize divide by zero
        hi = scale.hi if scale.hi > scale.lo else scale.lo + 1.0
        bar = ColorbarBase(ax, cmap=colormaps[scale.cmap], norm=Normalize(scale.lo, hi),
                           orientation="horizontal")
        bar.ax.tick_params(labelsize=7, length=2, pad=1)
        bar.set_label(label, fontsize=8, labelpad=1)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


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
