"""Human-friendly pictures of a frame: colour-mapped images and their colour bars.

One home for how a frame is shown to a person (``toftwin preview``, the campaign report, the
operator page): matplotlib's colour maps turn values into colours, and :func:`colour_bar_png`
draws the scale that goes with an image, with its unit. Depth is ``viridis`` reversed (near =
yellow, far = blue); differences use the diverging ``RdBu_r`` (red = positive).

Grey images shown to people are the amplitude stretched from its 1st to its 99th percentile over
the valid pixels (:data:`GREY_DISPLAY_PERCENTILES`, :func:`grey_scale`), black to white, with a
colour bar whose ends state that range in DN (the sensor's digital numbers). The stored grey
image (``grey.png``, ``grey_8bit``, the metrics' grey) keeps the frame's fixed full scale
(:func:`sim_core.frame_io.grey_full_scale`: 2048 DN for the 12-bit sensor), on which the
satellite ground test (15-55 DN) reads 2 to 7 of 255: black to the eye. Measured and simulated
images of one pose share one range (:func:`grey_scale` of both), so they compare by eye.
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
#: colour map of grey images (black = the low end of the range, white = the high end)
GREY_CMAP = "gray"
#: percentiles of the valid amplitude a grey image shown to a person is stretched between
GREY_DISPLAY_PERCENTILES = (1.0, 99.0)
#: the amplitude's unit in a frame read out by a sensor (measured, or simulated with a sensor)
DN = "DN"
#: the amplitude's unit in an ideal-sensor frame (radiance)
RADIANCE_UNIT = "W m^-2 sr^-1"

#: held around every matplotlib drawing: its text and font caches are not thread-safe, and the
#: service draws colour bars and plots from several request threads
MATPLOTLIB_LOCK = threading.Lock()


@dataclass(frozen=True)
class ColourScale:
    """How values map to colours: ``cmap`` from ``lo`` to ``hi`` (clipped), in ``unit``.

    ``note`` is added to the colour bar's label (e.g. how the range was chosen); with
    ``label_ends`` the bar's ticks are its two ends and its middle, so it states the range
    (:func:`colour_bar_ticks`).

    >>> ColourScale("viridis_r", 0.8, 1.2, "m").label("depth")
    'depth [m]'
    >>> ColourScale("gray", 3.0, 41.0, "DN", note="1st-99th pct").label("grey")
    'grey [DN], 1st-99th pct'
    """

    cmap: str
    lo: float
    hi: float
    unit: str
    note: str = ""
    label_ends: bool = False

    def label(self, quantity: str) -> str:
        """``quantity [unit]`` and the note, if any."""
        text = f"{quantity} [{self.unit}]"
        return f"{text}, {self.note}" if self.note else text


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


def amplitude_unit(frame: Frame) -> str:
    """The unit of a frame's amplitude: :data:`DN` for a frame read out by a sensor (it has a
    raw frame), :data:`RADIANCE_UNIT` for an ideal-sensor frame."""
    return DN if frame.raw is not None else RADIANCE_UNIT


def grey_scale(*images: tuple[np.ndarray, np.ndarray], unit: str = DN) -> ColourScale:
    """The grey scale of one or more ``(amplitude, valid)`` images: from the 1st to the 99th
    percentile (:data:`GREY_DISPLAY_PERCENTILES`) of the valid, finite amplitude of all of them
    together (one range for a measured and a simulated image, so that their greys compare).

    Without a valid pixel, the percentiles of every finite pixel; without one, 0 to 1. A flat
    image (both percentiles equal) is widened by 0.5 either side so that the bar has a span.

    >>> amp = np.arange(101.0).reshape(1, 101)
    >>> s = grey_scale((amp, np.ones(amp.shape, bool)))
    >>> (s.lo, s.hi, s.unit, s.note)
    (1.0, 99.0, 'DN', '1st-99th pct of valid pixels')
    """
    vals = [np.asarray(a, dtype=np.float64)[np.asarray(v, dtype=bool) & np.isfinite(a)]
            for a, v in images]
    chosen = np.concatenate(vals) if vals else np.zeros(0)
    note = "1st-99th pct of valid pixels"
    if chosen.size == 0:
        finite = [np.asarray(a, dtype=np.float64) for a, _ in images]
        chosen = np.concatenate([f[np.isfinite(f)] for f in finite]) if finite else chosen
        note = "1st-99th pct (no valid pixel)"
    if chosen.size == 0:
        return ColourScale(GREY_CMAP, 0.0, 1.0, unit, "no finite pixel", label_ends=True)
    lo, hi = (float(x) for x in np.percentile(chosen, GREY_DISPLAY_PERCENTILES))
    if not hi > lo:
        lo, hi = lo - 0.5, hi + 0.5
    return ColourScale(GREY_CMAP, lo, hi, unit, note, label_ends=True)


def grey_colours(amplitude: np.ndarray, scale: ColourScale) -> np.ndarray:
    """RGB uint8 image (H, W, 3) of an amplitude image under a grey ``scale``: every finite
    pixel is shown (the camera's grey image has no invalid pixels), NaN/inf black."""
    amp = np.asarray(amplitude, dtype=np.float64)
    return colourise(amp, np.isfinite(amp), scale)


def colour_bar_ticks(scale: ColourScale) -> tuple[tuple[float, str], ...]:
    """The ticks a colour bar of ``scale`` labels itself with when ``label_ends`` is set: low
    end, middle, high end, each as (value, text with 4 significant digits). Empty otherwise
    (matplotlib's own ticks).

    >>> colour_bar_ticks(ColourScale("gray", 15.04, 55.06, "DN", label_ends=True))
    ((15.04, '15.04'), (35.05, '35.05'), (55.06, '55.06'))
    """
    if not scale.label_ends:
        return ()
    mid = 0.5 * (scale.lo + scale.hi)
    return tuple((v, f"{v:.4g}") for v in (scale.lo, mid, scale.hi))


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
        # with its ends labelled, room either side for half a label ("-1435", "107.9")
        margin = 0.1 if scale.label_ends else 0.04
        ax = fig.add_axes((margin, 0.52, 1.0 - 2.0 * margin, 0.26))
        # hi == lo would make matplotlib's Normalize divide by zero
        hi = scale.hi if scale.hi > scale.lo else scale.lo + 1.0
        bar = ColorbarBase(ax, cmap=colormaps[scale.cmap], norm=Normalize(scale.lo, hi),
                           orientation="horizontal")
        ticks = colour_bar_ticks(scale)
        if ticks:
            bar.set_ticks([v for v, _ in ticks], labels=[t for _, t in ticks])
        bar.ax.tick_params(labelsize=7, length=2, pad=1)
        # 8 pt, smaller where the label would not fit (about 0.83 px a character per point)
        size = max(5.0, min(8.0, width_px / (0.83 * max(len(label), 1))))
        bar.set_label(label, fontsize=size, labelpad=1)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


#: height of a colour bar under a picture [px]
BAR_HEIGHT_PX = 56
#: white gap between the two halves of :func:`side_by_side` [px, before magnification]
GAP_PX = 4


def preview_scales(frame: Frame) -> tuple[ColourScale, ColourScale]:
    """The grey and depth scales :func:`side_by_side` shows a frame with."""
    im = frame.image
    return (grey_scale((im.amplitude, im.valid), unit=amplitude_unit(frame)),
            depth_scale((im.range_m, im.valid)))


def side_by_side(frame: Frame, scale: int = 2) -> Image.Image:
    """Grey left (the amplitude stretched to its 1st-99th percentile, :func:`grey_scale`),
    depth right (near = yellow, far = blue), magnified ``scale`` times, each with its colour
    bar underneath stating its range and unit. The frame's stored files are not touched."""
    im = frame.image
    grey, depth = preview_scales(frame)
    left = grey_colours(im.amplitude, grey)
    right = colourise(im.range_m, im.valid, depth)
    h, w = left.shape[:2]
    gap = np.full((h, GAP_PX, 3), 255, dtype=np.uint8)
    top = Image.fromarray(np.concatenate([left, gap, right], axis=1))
    top = top.resize((top.width * scale, top.height * scale), Image.NEAREST)
    out = Image.new("RGB", (top.width, top.height + BAR_HEIGHT_PX), "white")
    out.paste(top, (0, 0))
    half = w * scale
    for x, s, quantity in ((0, grey, "grey"), (half + GAP_PX * scale, depth, "range")):
        bar = Image.open(io.BytesIO(colour_bar_png(s, s.label(quantity), half, BAR_HEIGHT_PX)))
        out.paste(bar.convert("RGB"), (x, top.height))
    return out
