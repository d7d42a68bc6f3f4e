"""Removing the camera's depth errors from a measured frame (``toftwin correct``).

The raw frame's correlation phasors (seed eqs. 4-5) are rotated so that their phase is the true
one (:meth:`sim_core.depth_errors.DepthErrorModel.correct_phase`); the phase images are rebuilt
as ``C_i = |Z| / 2 cos(tau_i + phi)`` (seed eq. 15 with the corrected phase), so the corrected
folder is an ordinary measured frame that every tool reads as such.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from sim_core import frame_io
from sim_core.camera import Camera, Intrinsics
from sim_core.depth_errors import DepthErrorModel
from sim_core.errors import InvalidInputError
from sim_core.raw import PHASE_OFFSETS_RAD, RawFrame
from sim_core.tof import phase_from_phasor
from sim_core.twin_file import CalibrationFile, twin_hash


def corrected_raw(raw: RawFrame, model: DepthErrorModel) -> RawFrame:
    """``raw`` with its phases corrected (module docstring); amplitudes unchanged."""
    z = raw.phasor()
    phi = model.correct_phase(phase_from_phasor(z))
    half = 0.5 * np.abs(z)
    c = half[:, None] * np.cos(PHASE_OFFSETS_RAD[None, :, None, None] + phi[:, None])
    return dataclasses.replace(raw, phase_images=c.astype(np.float32), taps=None)


def correct_frame(frame_dir: str | Path, calibration: CalibrationFile, out_dir: str | Path
                  ) -> Path:
    """Write the corrected copy of measured frame folder ``frame_dir`` into ``out_dir``."""
    src = Path(frame_dir)
    out = Path(out_dir)
    if out.resolve() == src.resolve():
        raise InvalidInputError("--out", "the corrected frame never overwrites its input")
    frame = frame_io.read_measured(src)
    raw = frame.raw
    intr = frame_io.intrinsics_from_meta(frame.meta, raw.shape)
    cam = calibration.camera
    d = cam.distortion
    intr = Intrinsics(
        intr.width_px, intr.height_px, cam.fx_px or intr.fx_px, cam.fy_px or intr.fy_px,
        intr.cx_px if cam.cx_px is None else cam.cx_px,
        intr.cy_px if cam.cy_px is None else cam.cy_px,
        (d.k1, d.k2, d.p1, d.p2, d.k3) if d is not None else intr.distortion)
    if cam.depth is None:
        raise InvalidInputError("calibration.camera.depth",
                                "the calibration holds no depth errors to remove")
    model = DepthErrorModel.from_spec(cam.depth, raw.frequencies_hz, raw.shape)
    fixed = corrected_raw(raw, model)
    frame_io.write_measured(out, fixed, Camera(intr, np.eye(4)), {
        "corrected": {"source": str(src), "calibration_hash": twin_hash(calibration)}})
    return out
