"""Optics between the scene and the sensor: radiance to irradiance on a pixel (seed eq. 32).

The MTF chain of seed eq. 33 joins this module with the imaging-chain work.
"""

from __future__ import annotations

import numpy as np

from sim_core.camera import Camera, pixel_centre_grid, pixel_to_camera_direction


def cos_off_axis(camera: Camera) -> np.ndarray:
    """cos(alpha) of every pixel: the angle between the optical axis and its chief ray, (H, W)."""
    intr = camera.intrinsics
    u, v = pixel_centre_grid(intr)
    return pixel_to_camera_direction(intr, u, v)[:, 2].reshape(intr.shape)


def pixel_irradiance_w_m2(
    radiance_w_m2_sr: np.ndarray, camera: Camera, transmittance: float, f_number: float
) -> np.ndarray:
    """Irradiance on the sensor from scene radiance, seed eq. 32.

    E_pixel = L * tau * (pi / 4) * (1 / F#)^2 * cos^4(alpha)

    Parameters
    ----------
    radiance_w_m2_sr : (H, W) or (..., H, W) float or complex
        Radiance in front of the lens (DC or a phasor image; the law is linear).
    transmittance : float
        Optical transmittance tau of lens and filter, in (0, 1].
    f_number : float
        F/#, > 0.
    """
    if not 0.0 < transmittance <= 1.0:
        raise ValueError(f"transmittance = {transmittance} is outside (0, 1]")
    if not f_number > 0.0:
        raise ValueError(f"f_number = {f_number} must be > 0")
    c = cos_off_axis(camera)
    return radiance_w_m2_sr * (transmittance * np.pi / 4.0 / f_number**2) * c**4
