"""The six image panels of a pose: measured, simulated and their difference, grey and depth.

One definition serves the campaign report (inline PNGs) and the operator page (PNGs from
``/api/v1/poses/{id}/panels``). Each panel carries its colour scale, so it is shown with a
colour bar and its unit (:func:`sim_core.preview.colour_bar_png`):

- grey measured / simulated: each frame's grey image at its own grey full scale (its grey.png,
  as in the metrics; :func:`sim_core.frame_io.grey_full_scale`), 0-255;
- |grey difference|: the absolute difference of those, where both frames are valid;
- depth measured / simulated: range [m] on one scale for both (1st to 99th percentile of their
  valid pixels), near = yellow, far = blue;
- depth simulated - measured [mm], +-50 mm, red = the simulation is farther.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from PIL import Image

from service.store.frame_files import FrameStore
from sim_core import frame_io
from sim_core.frame_io import Frame
from sim_core.preview import (
    DIFFERENCE_CMAP,
    GREY_CMAP,
    ColourScale,
    colourise,
    depth_scale,
)

DEPTH_DIFF_RANGE_MM = 50.0
GREY_SCALE = ColourScale(GREY_CMAP, 0.0, 255.0, "8-bit level")
DEPTH_DIFF_SCALE = ColourScale(DIFFERENCE_CMAP, -DEPTH_DIFF_RANGE_MM, DEPTH_DIFF_RANGE_MM, "mm")

#: panel names in display order (grey row, then depth row)
PANEL_NAMES = ("grey-measured", "grey-simulated", "grey-difference",
               "depth-measured", "depth-simulated", "depth-difference")


@dataclass(frozen=True)
class Panel:
    """One image of a pose: ``rgb`` (H, W, 3) uint8 and the scale its colours stand for."""

    name: str
    caption: str
    quantity: str
    scale: ColourScale
    rgb: np.ndarray

    @property
    def label(self) -> str:
        """The colour bar's label: quantity and unit."""
        return self.scale.label(self.quantity)


def png_bytes(rgb: np.ndarray) -> bytes:
    """An RGB (H, W, 3) uint8 image as PNG bytes."""
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def _load(store: FrameStore, frame_id: str) -> Frame:
    return frame_io.read_frame(store.path(frame_id))


def _grey_rgb(grey: np.ndarray) -> np.ndarray:
    return np.repeat(grey[..., None], 3, axis=2)


def pose_panels(store: FrameStore, measured_id: str, simulated_id: str) -> tuple[Panel, ...]:
    """The six panels of a measured and a simulated frame (order: :data:`PANEL_NAMES`).

    Frames do not change once stored, so the panels of the last few pairs are kept (a frame
    whose files have gone is a :class:`GoneError` naming it, cached panels or not).
    """
    for frame_id in (measured_id, simulated_id):
        store.file(frame_id, frame_io.FRAME_NPZ)
    return _panels(store.root, measured_id, simulated_id)


@lru_cache(maxsize=16)
def _panels(root: Path, measured_id: str, simulated_id: str) -> tuple[Panel, ...]:
    store = FrameStore(root)
    mf, sf = _load(store, measured_id), _load(store, simulated_id)
    m_range, m_valid = mf.image.range_m, mf.image.valid
    s_range, s_valid = sf.image.range_m, sf.image.valid
    both = m_valid & s_valid
    gm, gs = mf.grey_8bit(), sf.grey_8bit()
    gdiff = np.abs(gm.astype(int) - gs.astype(int)).astype(np.uint8)
    gdiff[~both] = 0
    depth = depth_scale((m_range, m_valid), (s_range, s_valid))
    ddiff_mm = (s_range - m_range) * 1000.0
    return (
        Panel("grey-measured", "grey measured", "grey", GREY_SCALE, _grey_rgb(gm)),
        Panel("grey-simulated", "grey simulated", "grey", GREY_SCALE, _grey_rgb(gs)),
        Panel("grey-difference", "|grey difference|", "|grey sim - meas|", GREY_SCALE,
              _grey_rgb(gdiff)),
        Panel("depth-measured", "depth measured", "range", depth,
              colourise(m_range, m_valid, depth)),
        Panel("depth-simulated", "depth simulated", "range", depth,
              colourise(s_range, s_valid, depth)),
        Panel("depth-difference", f"depth sim - meas (+-{DEPTH_DIFF_RANGE_MM:g} mm)",
              "range sim - meas", DEPTH_DIFF_SCALE, colourise(ddiff_mm, both, DEPTH_DIFF_SCALE)),
    )
