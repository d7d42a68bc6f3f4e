"""The renderer's output: light at every pixel, before optics and sensor."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class LightField:
    """Per-pixel radiance reaching the camera, split into what the sensor tells apart.

    All radiances are pixel averages (box filter over the pixel footprint) in
    W m^-2 sr^-1 at the camera's wavelength, in front of the lens; :mod:`sim_core.optics`
    turns them into irradiance on the sensor (seed eq. 32). Arrays are (H, W) unless stated.

    Attributes
    ----------
    frequencies_hz : (n_f,) float64
        Modulation frequencies of the phasor images.
    dc_active : float64
        Radiance of the camera's own (modulated) source, the DC part.
    dc_ambient : float64
        Radiance of unmodulated ambient sources (sun, solar simulator, Earth, Moon).
    phasor : (n_f, H, W) complex128
        Sum over paths of ``w * exp(-1j * 2*pi*f*L / c)``, L the whole path length from the
        source to the pixel (seed eq. 31). ``|phasor| <= dc_active``, with equality when all
        light arrives with the same path length.
    truth_range_m : float64
        Radial distance from the camera centre to the first surface through the pixel centre;
        NaN where the ray escapes.
    truth_depth_z_m : float64
        The same along the optical axis (z-depth); NaN where the ray escapes.
    truth_normal : (H, W, 3) float64
        World-frame unit normal at that surface, facing the camera; 0 where nothing is hit.
    object_id : int32
        Index of the object hit through the pixel centre, -1 for none.
    hit : bool
        True where the pixel-centre ray hits geometry.
    samples_per_pixel : int32
        Number of Monte Carlo samples per pixel.
    dc_active_var, dc_ambient_var : float64
        Variance of one sample (divide by ``samples_per_pixel`` for the variance of the mean).
    phasor_cov : (n_f, 3, H, W) float64
        Per-sample covariance of the phasor: var(re), var(im), cov(re, im).
    """

    frequencies_hz: np.ndarray
    dc_active: np.ndarray
    dc_ambient: np.ndarray
    phasor: np.ndarray
    truth_range_m: np.ndarray
    truth_depth_z_m: np.ndarray
    truth_normal: np.ndarray
    object_id: np.ndarray
    hit: np.ndarray
    samples_per_pixel: np.ndarray
    dc_active_var: np.ndarray = field(repr=False)
    dc_ambient_var: np.ndarray = field(repr=False)
    phasor_cov: np.ndarray = field(repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        return self.dc_active.shape

    def phasor_standard_error(self, along: str = "perpendicular") -> np.ndarray:
        """Standard error of the phasor estimate perpendicular to its mean (``along=
        "perpendicular"``) or along it (``"parallel"``), (n_f, H, W).

        The perpendicular component moves the phase: for a mean phasor m = |m| e^{i phi}, the
        phase error is about this value divided by |m|. The parallel one moves the amplitude
        (the grey image): its relative error is that value divided by |m|.
        """
        if along not in ("perpendicular", "parallel"):
            raise ValueError(f"along must be 'perpendicular' or 'parallel', got {along!r}")
        mean = self.phasor
        mag = np.abs(mean)
        # Unit vector along the mean; where the mean is 0 any direction is as good (use re).
        safe = np.where(mag > 0.0, mag, 1.0)
        cr = np.where(mag > 0.0, mean.real / safe, 1.0)
        ci = np.where(mag > 0.0, mean.imag / safe, 0.0)
        if along == "perpendicular":  # the direction (-ci, cr)
            ur, ui = -ci, cr
        else:
            ur, ui = cr, ci
        var_re, var_im, cov = self.phasor_cov[:, 0], self.phasor_cov[:, 1], self.phasor_cov[:, 2]
        var_u = ur * ur * var_re + ui * ui * var_im + 2.0 * ur * ui * cov
        # Unsampled pixels (0 samples) have no estimate: report an infinite error.
        n = self.samples_per_pixel
        return np.where(n > 0, np.sqrt(np.maximum(var_u, 0.0) / np.maximum(n, 1)), np.inf)
