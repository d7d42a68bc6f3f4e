"""Removing the camera's depth errors from a measured frame (``toftwin correct``).

The raw frame's correlation phasors (seed eqs. 4-5) are rotated so that their phase is the true
one: first the warm-up drift at the frame's reported illumination temperature
(:meth:`sim_core.warmup.TemperatureDrift.phase_offset_rad`, when the calibration has
``camera.temperature``; the camera adds it after its other depth errors), then those errors
(:meth:`sim_core.depth_errors.DepthErrorModel.correct_phase`); the phase images are rebuilt
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
from sim_core.warmup import TemperatureDrift


def corrected_raw(raw: RawFrame, model: DepthErrorModel | None,
                  drift: TemperatureDrift | None = None) -> RawFrame:
    """``raw`` with its phases corrected (module docstring); amplitudes unchanged. ``drift``
    applies at ``raw.illumination_temperature_c`` (a frame without one is an error)."""
    z = raw.phasor()
    if drift is not None:
        t = raw.illumination_temperature_c
        if t is None:
            raise InvalidInputError("illumination_temperature_c", "the frame reports no "
                                    "illumination temperature: its warm-up drift is unknown")
        z = z * np.exp(1j * drift.phase_offset_rad(t)).reshape(-1, 1, 1)
    phi = phase_from_phasor(z)
    if model is not None:
        phi = model.correct_phase(phi)
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
    if cam.depth is None and cam.temperature is None:
        raise InvalidInputError("calibration.camera.depth",
                                "the calibration holds no depth errors (camera.depth) and no "
                                "warm-up drift (camera.temperature) to remove")
    model = (None if cam.depth is None
             else DepthErrorModel.from_spec(cam.depth, raw.frequencies_hz, raw.shape))
    drift, drift_note = None, None
    if cam.temperature is not None:
        if raw.illumination_temperature_c is None:
            drift_note = ("not removed: the frame reports no illumination temperature, so its "
                          "warm-up drift is unknown")
        else:
            t = raw.illumination_temperature_c
            drift = TemperatureDrift.from_spec(cam.temperature, raw.frequencies_hz)
            drift_mm = [round(float(d) * 1e3, 3) for d in drift.range_drift_m(t)]
            drift_note = f"removed at {t:.2f} degC: {drift_mm} mm"
    if model is None and drift is None:
        raise InvalidInputError("illumination_temperature_c", drift_note or "nothing to remove")
    fixed = corrected_raw(raw, model, drift)
    frame_io.write_measured(out, fixed, Camera(intr, np.eye(4)), {
        "corrected": {"source": str(src), "calibration_hash": twin_hash(calibration),
                      "warm_up_drift": drift_note}})
    return out
