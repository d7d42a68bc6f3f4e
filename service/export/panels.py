"""The six image panels of a pose: measured, simulated and their difference, grey and depth.

One definition serves the campaign report (inline PNGs) and the operator page (PNGs from
``/api/v1/poses/{id}/panels``). Each panel carries its colour scale, so it is shown with a
colour bar and its unit (:func:`sim_core.preview.colour_bar_png`):

- grey measured / simulated: the amplitude in DN, both on one scale stretched from the 1st to the
  99th percentile of their valid pixels (:func:`sim_core.preview.grey_scale`), black to white;
  the stored grey.png keeps the frame's fixed full scale, on which a dim scene is black;
- grey simulated - measured [DN], where both frames are valid, on a symmetric scale of +- the
  99th percentile of its magnitude (at least 1 DN), red = the simulation is brighter;
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
    ColourScale,
    amplitude_unit,
    colourise,
    depth_scale,
    grey_colours,
    grey_scale,
)

DEPTH_DIFF_RANGE_MM = 50.0
#: the grey difference's scale is +- this percentile of its magnitude
GREY_DIFF_PERCENTILE = 99.0
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
    return store.read(frame_id)  # a damaged file: DamagedFileError naming frame and file


def grey_panel_scales(mf: Frame, sf: Frame) -> tuple[ColourScale, ColourScale]:
    """The grey scales of a measured and a simulated frame: one range for both when their
    amplitudes share a unit (DN), each its own otherwise (an ideal-sensor simulation)."""
    m_unit, s_unit = amplitude_unit(mf), amplitude_unit(sf)
    m_img, s_img = (mf.image.amplitude, mf.image.valid), (sf.image.amplitude, sf.image.valid)
    if m_unit == s_unit:
        shared = grey_scale(m_img, s_img, unit=m_unit)
        return shared, shared
    return grey_scale(m_img, unit=m_unit), grey_scale(s_img, unit=s_unit)


def _grey_difference(mf: Frame, sf: Frame, both: np.ndarray) -> tuple[ColourScale, np.ndarray]:
    """Simulated - measured amplitude [DN] (the frames' 8-bit grey levels when their units
    differ) and its symmetric scale."""
    if amplitude_unit(mf) == amplitude_unit(sf):
        diff, unit = sf.image.amplitude - mf.image.amplitude, amplitude_unit(mf)
    else:
        diff = sf.grey_8bit().astype(float) - mf.grey_8bit().astype(float)
        unit = "8-bit level"
    sel = np.abs(diff[both & np.isfinite(diff)])
    span = float(np.percentile(sel, GREY_DIFF_PERCENTILE)) if sel.size else 0.0
    span = max(span, 1.0)
    note = f"+-{GREY_DIFF_PERCENTILE:g}th pct of |diff|"
    return ColourScale(DIFFERENCE_CMAP, -span, span, unit, note, label_ends=True), diff


def pose_panels(store: FrameStore, measured_id: str, simulated_id: str) -> tuple[Panel, ...]:
    """The six panels of a measured and a simulated frame (order: :data:`PANEL_NAMES`).

    Frames do not change once stored, so the panels of the last few pairs are kept (a frame
    whose files have gone is a :class:`GoneError` naming it, cached panels or not; one with a
    file that cannot be read a :class:`DamagedFileError` naming the frame and the file).
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
    grey_m, grey_s = grey_panel_scales(mf, sf)
    gdiff_scale, gdiff = _grey_difference(mf, sf, both)
    depth = depth_scale((m_range, m_valid), (s_range, s_valid))
    ddiff_mm = (s_range - m_range) * 1000.0
    return (
        Panel("grey-measured", "grey measured", "grey", grey_m,
              grey_colours(mf.image.amplitude, grey_m)),
        Panel("grey-simulated", "grey simulated", "grey", grey_s,
              grey_colours(sf.image.amplitude, grey_s)),
        Panel("grey-difference", "grey sim - meas", "grey sim - meas", gdiff_scale,
              colourise(gdiff, both, gdiff_scale)),
        Panel("depth-measured", "depth measured", "range", depth,
              colourise(m_range, m_valid, depth)),
        Panel("depth-simulated", "depth simulated", "range", depth,
              colourise(s_range, s_valid, depth)),
        Panel("depth-difference", f"depth sim - meas (+-{DEPTH_DIFF_RANGE_MM:g} mm)",
              "range sim - meas", DEPTH_DIFF_SCALE, colourise(ddiff_mm, both, DEPTH_DIFF_SCALE)),
    )
