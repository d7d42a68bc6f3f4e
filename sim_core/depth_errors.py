"""The camera's systematic depth errors: global phase offset, wiggling, fixed-pattern offsets.

Model (issue 13, section 1; the calibration file's ``camera.depth``), per modulation frequency
``f_k`` and pixel, with phi the true phase delay (seed eq. 4):

    phi_measured = phi + offset_k + sum_j a_j sin(h_j phi + p_j) + 4 pi f_k o(u, v) / c

where ``o(u, v)`` is the pixel's fixed-pattern offset as a range [m] (seed eq. 7 turns a range
into a phase). Wiggling comes from the harmonics of the not quite sinusoidal modulation and
correlation signals; the fixed pattern from per-pixel delays of the modulation signal.

:meth:`DepthErrorModel.apply_to_phasor` puts the errors into a simulated frame's phasors (the twin
reproduces the camera as it is), :meth:`DepthErrorModel.correct_phase` removes them from a
measured frame's phases (``toftwin correct``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.errors import InvalidInputError
from sim_core.tof import phase_from_phasor
from sim_core.twin_file import (
    MAX_WIGGLING_SLOPE,
    DepthErrors,
    PixelOffsetGrid,
    PixelOffsetPattern,
    grid_coverage_problem,
)

__all__ = ["MAX_WIGGLING_SLOPE", "DepthErrorModel"]

TWO_PI = 2.0 * np.pi
#: fixed-point iterations of the inversion; converges as (sum a_j h_j)^n (< 0.5: the file's
#: rule, :class:`sim_core.twin_file.DepthErrors`)
CORRECTION_ITERATIONS = 30


def range_to_phase_rad(range_m: np.ndarray | float, frequency_hz: float) -> np.ndarray:
    """Phase delay of a range at one frequency, 4 pi f d / c (seed eq. 7 inverted)."""
    return 4.0 * np.pi * frequency_hz * np.asarray(range_m, dtype=np.float64) / SPEED_OF_LIGHT_M_S


def random_pixel_offsets_m(pattern: PixelOffsetPattern, shape: tuple[int, int]) -> np.ndarray:
    """A reality's fixed pattern: Gaussian-smoothed white noise of standard deviation ``sigma``.

    Deterministic for (pattern, shape). The smoothed field is rescaled to its exact standard
    deviation; a constant field (one pixel, or ``sigma`` 0) gives zeros.

    >>> p = PixelOffsetPattern(sigma=0.004, correlation_px=12, seed=5)
    >>> o = random_pixel_offsets_m(p, (171, 224))
    >>> o.shape, round(float(o.std()), 6)
    ((171, 224), 0.004)
    """
    rng = np.random.default_rng(pattern.seed)
    noise = rng.standard_normal(shape)
    if pattern.correlation_px > 0.0:
        noise = ndimage.gaussian_filter(noise, pattern.correlation_px, mode="reflect")
    noise = noise - noise.mean()
    std = float(noise.std())
    if pattern.sigma == 0.0 or not std > 0.0:
        return np.zeros(shape)
    return noise * (pattern.sigma / std)


def grid_pixel_offsets_m(grid: PixelOffsetGrid, shape: tuple[int, int]) -> np.ndarray:
    """A calibration's fixed pattern: its grid interpolated to every pixel (cubic spline)."""
    knots = np.asarray(grid.offsets_mm, dtype=np.float64) * 1e-3
    h, w = shape
    problem = grid_coverage_problem(grid, shape)  # the file checked the preset's image
    if problem is not None:
        raise InvalidInputError("camera.depth.pixel_offset_m.offsets_mm",
                                problem.removeprefix("offsets_mm: "))
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64) / grid.grid_step_px
    order = 3 if min(knots.shape) >= 4 else 1
    return ndimage.map_coordinates(knots, [rows, cols], order=order, mode="nearest")


def pixel_offsets_to_grid(offsets_m: np.ndarray, grid_step_px: int) -> PixelOffsetGrid:
    """Sample a per-pixel offset map on a grid (for the calibration file), mm rounded to 0.01.

    The knots are block means around each knot position (a low-pass before sampling); NaN
    pixels (never measured) are ignored, a knot with no measured pixel around it takes the
    value of its nearest measured knot.
    """
    o = np.asarray(offsets_m, dtype=np.float64)
    h, w = o.shape
    s = int(grid_step_px)
    n_r, n_c = int(np.ceil((h - 1) / s)) + 1, int(np.ceil((w - 1) / s)) + 1
    knots = np.full((n_r, n_c), np.nan)
    for i in range(n_r):
        for j in range(n_c):
            r0, r1 = max(0, i * s - s // 2), min(h, i * s + s // 2 + 1)
            c0, c1 = max(0, j * s - s // 2), min(w, j * s + s // 2 + 1)
            block = o[r0:r1, c0:c1]
            block = block[np.isfinite(block)]
            if block.size:
                knots[i, j] = block.mean()
    missing = ~np.isfinite(knots)
    if missing.all():
        raise InvalidInputError("pixel_offset_m", "no pixel has a measured offset")
    if missing.any():
        idx = ndimage.distance_transform_edt(missing, return_distances=False, return_indices=True)
        knots = knots[tuple(idx)]
    return PixelOffsetGrid(grid_step_px=s, offsets_mm=np.round(knots * 1e3, 2).tolist())


@dataclass(frozen=True)
class DepthErrorModel:
    """The depth errors of one camera, for one image shape and set of frequencies.

    Attributes
    ----------
    frequencies_hz : (n_f,) float
    offsets_rad : (n_f,) float
        Global phase offset per frequency.
    wiggling : tuple of (frequency_index or None, harmonic, amplitude_rad, phase_rad)
    pixel_offsets_m : (H, W) float or None
        Fixed-pattern offsets as a range [m].
    """

    frequencies_hz: np.ndarray
    offsets_rad: np.ndarray
    wiggling: tuple[tuple[int | None, int, float, float], ...] = ()
    pixel_offsets_m: np.ndarray | None = field(default=None, repr=False)

    @classmethod
    def from_spec(cls, spec: DepthErrors, frequencies_hz, shape: tuple[int, int]
                  ) -> DepthErrorModel:
        """The model of a file's ``camera.depth`` for a use case's frequencies and image shape.

        ``phase_offset_rad`` has one entry per frequency (a single entry applies to all); a
        wiggling term's ``frequency_index`` must name one of the frequencies.
        """
        freqs = np.asarray(frequencies_hz, dtype=np.float64).reshape(-1)
        n_f = freqs.size
        offs = list(spec.phase_offset_rad)
        if len(offs) == 0:
            offsets = np.zeros(n_f)
        elif len(offs) == 1:
            offsets = np.full(n_f, offs[0])
        elif len(offs) == n_f:
            offsets = np.asarray(offs, dtype=np.float64)
        else:
            raise InvalidInputError(
                "camera.depth.phase_offset_rad",
                f"has {len(offs)} entries for {n_f} modulation frequencies; give one per "
                "frequency or a single one for all",
            )
        terms = []
        for i, t in enumerate(spec.wiggling):
            if t.frequency_index is not None and t.frequency_index >= n_f:
                raise InvalidInputError(
                    f"camera.depth.wiggling[{i}].frequency_index",
                    f"{t.frequency_index} is outside [0, {n_f - 1}] for {n_f} frequencies",
                )
            terms.append((t.frequency_index, t.harmonic, t.amplitude_rad, t.phase_rad))
        pix = spec.pixel_offset_m
        if isinstance(pix, PixelOffsetPattern):
            pixel = random_pixel_offsets_m(pix, shape)
        elif isinstance(pix, PixelOffsetGrid):
            pixel = grid_pixel_offsets_m(pix, shape)
        else:
            pixel = None
        return cls(freqs, offsets, tuple(terms), pixel)

    def _terms(self, k: int):
        return [(h, a, p) for fi, h, a, p in self.wiggling if fi is None or fi == k]

    def phase_error_rad(self, true_phase_rad: np.ndarray, k: int) -> np.ndarray:
        """Systematic error added to the true phase at frequency ``k`` (module docstring)."""
        phi = np.asarray(true_phase_rad, dtype=np.float64)
        err = np.full(phi.shape, float(self.offsets_rad[k]))
        for h, a, p in self._terms(k):
            err = err + a * np.sin(h * phi + p)
        if self.pixel_offsets_m is not None:
            err = err + range_to_phase_rad(self.pixel_offsets_m, self.frequencies_hz[k])
        return err

    def _check_shape(self, shape: tuple[int, ...]) -> None:
        if self.pixel_offsets_m is not None and tuple(shape[-2:]) != self.pixel_offsets_m.shape:
            raise InvalidInputError(
                "camera.depth.pixel_offset_m",
                f"the offsets are for {self.pixel_offsets_m.shape} images, the frame is "
                f"{tuple(shape[-2:])}",
            )
        if shape[0] != self.frequencies_hz.size:
            raise InvalidInputError(
                "frequencies_hz", f"the model has {self.frequencies_hz.size} frequencies, the "
                f"frame {shape[0]}")

    def apply_to_phasor(self, phasor: np.ndarray) -> np.ndarray:
        """Phasors ``A exp(-1j phi)`` (n_f, H, W) of a true scene -> those the camera measures.

        The magnitude is kept; a zero phasor stays zero (its phase is undefined).
        """
        z = np.asarray(phasor)
        self._check_shape(z.shape)
        out = np.empty_like(z, dtype=np.complex128)
        for k in range(z.shape[0]):
            phi = phase_from_phasor(z[k])
            out[k] = z[k] * np.exp(-1j * self.phase_error_rad(phi, k))
        return out

    def correct_phase(self, measured_phase_rad: np.ndarray) -> np.ndarray:
        """Measured phases (n_f, H, W) -> true phases in [0, 2 pi), inverting the model.

        Solves ``phi + e(phi) = phi_m`` by the fixed-point iteration ``phi <- phi_m - e(phi)``,
        a contraction because ``|e'(phi)| <= sum a_j h_j < 1/2`` (checked by
        :meth:`from_spec`); the global and per-pixel offsets do not depend on phi and are exact.
        NaN phases (invalid pixels) stay NaN.
        """
        m = np.asarray(measured_phase_rad, dtype=np.float64)
        self._check_shape(m.shape)
        out = np.empty_like(m)
        for k in range(m.shape[0]):
            phi = m[k].copy()
            for _ in range(CORRECTION_ITERATIONS if self._terms(k) else 1):
                phi = m[k] - self.phase_error_rad(phi, k)
            out[k] = np.mod(phi, TWO_PI)
        return np.where(out >= TWO_PI, 0.0, out)
