"""Optics between the scene and the sensor: the MTF chain (seed eq. 33) and radiance to
irradiance on a pixel (seed eq. 32).

The MTFs act on the linear light quantities (the DC images and each complex phasor image)
before the sensor, so that at an edge the phasors of near and far surfaces mix and produce
flying pixels, as on a real camera. Each component is a transfer function on the frequency grid
of the padded image, in cycles per pixel; the image is padded by reflection before the FFT so
nothing wraps around the border.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_core.camera import Camera, z_over_range


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
    c = z_over_range(camera.intrinsics)  # cos(alpha)
    return radiance_w_m2_sr * (transmittance * np.pi / 4.0 / f_number**2) * c**4


@dataclass(frozen=True)
class Diffraction:
    """Diffraction-limited circular aperture: OTF 2/pi (acos x - x sqrt(1 - x^2)), x = nu/nu_c.

    nu_c = 1 / (lambda F#) cycles per metre on the sensor, i.e. pitch / (lambda F#) per pixel.
    """

    wavelength_m: float
    f_number: float
    pixel_pitch_m: float

    name = "diffraction"

    def transfer(self, fx: np.ndarray, fy: np.ndarray) -> np.ndarray:
        cutoff = self.pixel_pitch_m / (self.wavelength_m * self.f_number)
        x = np.minimum(np.hypot(fx, fy) / cutoff, 1.0)  # beyond the cutoff the OTF is 0
        return (2.0 / np.pi) * (np.arccos(x) - x * np.sqrt(1.0 - x * x))


@dataclass(frozen=True)
class PixelAperture:
    """Square light-sensitive area of side pitch * sqrt(fill factor): separable sinc.

    The renderer does not use this filter: it samples each pixel's light-sensitive square
    directly (``RenderSettings.footprint_px``), which is exact and cannot ring. It is kept for
    images from elsewhere (e.g. an ideal rasteriser) that need the aperture applied.
    """

    fill_factor: float

    name = "pixel_aperture"

    def transfer(self, fx: np.ndarray, fy: np.ndarray) -> np.ndarray:
        w = math.sqrt(self.fill_factor)
        return np.sinc(fx * w) * np.sinc(fy * w)


@dataclass(frozen=True)
class Electronics:
    """First-order low-pass along the readout direction (image rows, x): 1 / sqrt(1 + (f/fc)^2).

    ``cutoff_cycles_per_px`` is the -3 dB frequency along x.
    """

    cutoff_cycles_per_px: float

    name = "electronics"

    def transfer(self, fx: np.ndarray, fy: np.ndarray) -> np.ndarray:
        return 1.0 / np.sqrt(1.0 + (fx / self.cutoff_cycles_per_px) ** 2) + 0.0 * fy


@dataclass(frozen=True)
class LinearMotion:
    """Uniform linear motion of ``length_px`` during the exposure at ``direction_deg`` (from +x
    towards +y): a box blur along that direction.

    The blur is rasterised: points every 1/8 px along the segment are splatted bilinearly onto
    the pixel grid, and the transfer function is the exact DFT of that non-negative kernel. A
    continuous sinc(nu * length) sampled on the grid instead rings below zero (-19 % measured
    for 5 px diagonal motion).
    """

    length_px: float
    direction_deg: float = 0.0

    name = "motion"

    def kernel(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Integer offsets (dx, dy) and weights (summing to 1) of the rasterised blur."""
        a = math.radians(self.direction_deg)
        n = max(2, math.ceil(8.0 * abs(self.length_px)) + 1)
        t = (np.linspace(0.0, 1.0, n) - 0.5) * self.length_px
        x, y = t * math.cos(a), t * math.sin(a)
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        dx = np.concatenate([x0, x0 + 1, x0, x0 + 1]).astype(np.int64)
        dy = np.concatenate([y0, y0, y0 + 1, y0 + 1]).astype(np.int64)
        w = np.concatenate([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy]) / n
        span = int(dy.max() - dy.min()) + 1
        keys = (dx - dx.min()) * span + (dy - dy.min())
        uniq, inv = np.unique(keys, return_inverse=True)
        return uniq // span + dx.min(), uniq % span + dy.min(), np.bincount(inv, weights=w)

    def transfer(self, fx: np.ndarray, fy: np.ndarray) -> np.ndarray:
        dx, dy, w = self.kernel()
        out = np.zeros(np.broadcast(fx, fy).shape, dtype=np.complex128)
        for x, y, wk in zip(dx, dy, w, strict=True):
            out += wk * np.exp(-2j * np.pi * (fx * x + fy * y))
        # The kernel is symmetric about the segment's centre up to splatting round-off: the
        # imaginary part is that round-off and the (sub-pixel) shift it implies is negligible.
        return out.real


@dataclass(frozen=True)
class Vibration:
    """Random platform vibration, Gaussian of ``sigma_px``: exp(-2 pi^2 sigma^2 nu^2)."""

    sigma_px: float

    name = "vibration"

    def transfer(self, fx: np.ndarray, fy: np.ndarray) -> np.ndarray:
        return np.exp(-2.0 * np.pi**2 * self.sigma_px**2 * (fx * fx + fy * fy))


MTFComponent = Diffraction | PixelAperture | Electronics | LinearMotion | Vibration


def max_deviation_from_identity(component: MTFComponent) -> float:
    """Largest |1 - H| up to the Nyquist frequency (0.5 cycles/pixel) on both axes."""
    f = np.linspace(-0.5, 0.5, 65)
    fx, fy = np.meshgrid(f, f)
    return float(np.max(np.abs(1.0 - component.transfer(fx, fy))))


def padding_px(components: list[MTFComponent]) -> int:
    """Border wide enough for the point-spread functions of the components [px]."""
    pad = 8
    for c in components:
        if isinstance(c, LinearMotion):
            pad = max(pad, math.ceil(abs(c.length_px)) + 4)
        elif isinstance(c, Vibration):
            pad = max(pad, math.ceil(4.0 * c.sigma_px) + 4)
        elif isinstance(c, Electronics):
            pad = max(pad, math.ceil(3.0 / max(c.cutoff_cycles_per_px, 1e-3)))
    return min(pad, 256)


def apply_mtf(image: np.ndarray, components: list[MTFComponent]) -> np.ndarray:
    """Filter a (..., H, W) real or complex image with the product of the components (eq. 33).

    The image is padded by reflection (so no light wraps around and the border is not darkened
    by zeros), transformed, multiplied by the transfer functions, transformed back and cropped.
    With no components the image is returned unchanged.
    """
    if not components:
        return image
    pad = padding_px(components)
    h, w = image.shape[-2:]
    widths = [(0, 0)] * (image.ndim - 2) + [(pad, pad), (pad, pad)]
    # "reflect" also for pads wider than the image (numpy reflects repeatedly): "edge" would
    # repeat a border pixel across the whole pad and the filter would pull that streak back in.
    padded = np.pad(image, widths, mode="reflect")
    hp, wp = padded.shape[-2:]
    fy = np.fft.fftfreq(hp)[:, None]
    fx = np.fft.fftfreq(wp)[None, :]
    transfer = np.ones((hp, wp))
    for c in components:
        transfer = transfer * c.transfer(fx, fy)
    out = np.fft.ifft2(np.fft.fft2(padded) * transfer)
    out = out[..., pad : pad + h, pad : pad + w]
    return out if np.iscomplexobj(image) else out.real


@dataclass(frozen=True)
class StrayLight:
    """Stray light of lens and cover glass: ``fraction`` of each pixel's light spread over the
    image with a normalised Gaussian kernel of standard deviation ``radius_px`` (issue 27; the
    file's ``camera.stray_light``).

        out = (1 - fraction) I + fraction S(I),   S(I)_i = sum_j K(i - j) I_j / N_j

    ``K(dx, dy) = exp(-(dx^2 + dy^2) / (2 r^2))`` and ``N_j = sum_i K(i - j)`` over the image's
    pixels: every pixel's scattered light is renormalised over the sensor, so the image's total
    light is kept exactly (``sum out = sum I``), at the border too. Like the MTF chain it acts on
    the linear light quantities (DC images and each complex phasor image): a dark pixel beside a
    bright one receives the bright one's phasor and its range is pulled towards it.

    Why a Gaussian: it is positive (no ringing: DC stays non-negative, no phasor is amplified),
    separable (two small matrix products, exact at the border without padding or wrap-around,
    any radius from 0 to far beyond the image) and has one parameter; the scattering measured in
    ToF cameras is modelled as a broad point-spread function of this kind (a sum of Gaussians;
    a single one is its first term). The separable form ``K = g(dy) g(dx)`` with ``g(0) = 1``
    keeps ``N_j >= 1``: the normalisation never divides by less than one.
    """

    fraction: float
    radius_px: float

    name = "stray_light"

    def __post_init__(self) -> None:
        if not 0.0 <= self.fraction <= 1.0:
            raise ValueError(f"stray light fraction = {self.fraction} is outside [0, 1]")
        if not (self.radius_px >= 0.0 and math.isfinite(self.radius_px)):
            raise ValueError(f"stray light radius_px = {self.radius_px} is not finite and >= 0")

    def kernel_1d(self, n: int) -> np.ndarray:
        """``G[i, j] = g(i - j)`` for ``n`` pixels, with ``g(0) = 1`` (symmetric, (n, n))."""
        d = np.arange(n, dtype=np.float64)
        d = d[:, None] - d[None, :]
        if self.radius_px == 0.0:
            return np.eye(n)  # no spread: every pixel keeps its light
        # A radius far below a pixel gives (d / r)^2 = inf off the diagonal: exp(-inf) = 0.
        with np.errstate(over="ignore"):
            return np.exp(-0.5 * (d / self.radius_px) ** 2)

    def apply(self, image: np.ndarray, to_irradiance: np.ndarray | None = None) -> np.ndarray:
        """``image`` (..., H, W), real or complex, with the stray light added (see above).

        ``to_irradiance`` (H, W), > 0: the per-pixel factor from the image's quantity to the
        irradiance on the sensor (``cos^4`` of the field angle, seed eq. 32, for radiance): the
        light is scattered where it falls, on the sensor, so it is spread as irradiance and
        converted back (``sum(out * to_irradiance) == sum(image * to_irradiance)``).
        """
        if self.fraction == 0.0:
            return image
        h, w = image.shape[-2:]
        weight = np.ones((h, w)) if to_irradiance is None else np.asarray(to_irradiance)
        if weight.shape != (h, w) or not np.all(weight > 0.0):
            raise ValueError(f"to_irradiance must be a positive ({h}, {w}) array")
        gy, gx = self.kernel_1d(h), self.kernel_1d(w)
        # N_j = (column sums of gy) x (column sums of gx), each >= g(0) = 1.
        norm = gy.sum(axis=0)[:, None] * gx.sum(axis=0)[None, :]
        spread = gy @ (image * (weight / norm)) @ gx / weight  # weight > 0: checked above
        return (1.0 - self.fraction) * image + self.fraction * spread

    def remove(self, image: np.ndarray, to_irradiance: np.ndarray | None = None) -> np.ndarray:
        """``image`` (..., H, W), real or complex, with the stray light taken out: the exact
        inverse of :meth:`apply` (same ``to_irradiance``), for a fraction below 1.

        As irradiance ``J = image * to_irradiance``, :meth:`apply` is ``J' = (1 - f) J + f A J B``
        with ``A = G_y D_y^-1`` and ``B = D_x^-1 G_x`` (``D`` the diagonal of the column sums
        ``N``). Each is similar to the symmetric ``D^-1/2 G D^-1/2``, whose eigenvalues lie in
        [0, 1] (a Gaussian kernel's Gram matrix is positive semi-definite and ``A`` is column
        stochastic), so in their eigenbases ``J'`` is ``J`` times ``(1 - f) + f a_i b_j >= 1 - f``
        element by element: the division is safe for every fraction below 1, and a fraction of 1
        (every pixel's own light gone) is refused.
        """
        if self.fraction == 0.0 or self.radius_px == 0.0:
            return image  # apply() leaves such an image as it is
        if self.fraction >= 1.0:
            raise ValueError("stray light fraction = 1 cannot be removed: no pixel keeps any of "
                             "its own light (allowed: [0, 1))")
        h, w = image.shape[-2:]
        weight = np.ones((h, w)) if to_irradiance is None else np.asarray(to_irradiance)
        if weight.shape != (h, w) or not np.all(weight > 0.0):
            raise ValueError(f"to_irradiance must be a positive ({h}, {w}) array")
        a_val, p_y, p_y_inv = _column_stochastic_eigen(self.kernel_1d(h))  # A = P_y a P_y^-1
        b_val, p_x, p_x_inv = _column_stochastic_eigen(self.kernel_1d(w))  # B = P_x^-T b P_x^T
        k = p_y_inv @ (image * weight) @ p_x_inv.T
        k = k / ((1.0 - self.fraction) + self.fraction * np.multiply.outer(a_val, b_val))
        return (p_y @ k @ p_x.T) / weight  # weight > 0: checked above


def _column_stochastic_eigen(g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``G D^-1 = P diag(lam) P^-1`` for a symmetric positive semi-definite ``G`` with
    positive column sums ``D`` (:meth:`StrayLight.kernel_1d`, whose diagonal is 1, so each sum
    is at least 1): ``(lam, P, P^-1)``, ``lam`` clipped to [0, 1] against rounding."""
    d = g.sum(axis=0)  # >= g[j, j] = 1
    root = np.sqrt(d)
    lam, q = np.linalg.eigh(g / np.outer(root, root))
    return np.clip(lam, 0.0, 1.0), root[:, None] * q, q.T / root[None, :]
