"""The PMD pixel: irradiance to tap charges, SBI, noise, ADC (seed 2.2.3, eqs. 4-6, 15-16, 32;
peer paper eqs. 3-6, 13-14).

Per pixel, per modulation frequency f and phase step tau_i = i * pi / 2 (seed eq. 3), with
N_dc the electrons of the active light (DC), N_amb those of ambient light, N_dark dark
electrons and N_f the complex phasor of the active light in electrons (its magnitude is the
modulated part; its argument minus the phase delay):

    A_i = (N_dc + N_amb + N_dark) / 2 + D / 2 * Re(exp(1j tau_i) conj(N_f))
    B_i = (N_dc + N_amb + N_dark) / 2 - D / 2 * Re(exp(1j tau_i) conj(N_f))

which is the peer paper's eqs. 13-14 summed over all light paths (for one path,
Re(exp(1j tau) conj(N exp(-1j phi))) = N cos(tau + phi)). Ambient light adds equally to both
taps. Then shot noise (Poisson, seed eq. 16), SBI (below), read noise, full well, ADC.

SBI (suppression of background illumination, seed section 2.2.3 after Schmidt & Jaehne): once
the fuller tap passes ``sbi_start_e`` (n_SBI,start, about 36,500 e-), a compensation charge
n_delta = max(A, B) - n_SBI,start is removed from both taps, but never more than the emptier
tap holds (a strong modulated signal alone then fills the fuller tap, which saturates and is
flagged); the difference A - B, which holds the phase, is kept. Each compensation charge is
itself a Poisson draw, so the shot noise of everything collected stays in the difference and
SBI adds its own. If n_delta exceeds
``sbi_limit_e`` the pixel is in the SBI limit region and invalid (seed Fig. 7).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from sim_core.camera import Camera
from sim_core.constants import PLANCK_J_S, SPEED_OF_LIGHT_M_S
from sim_core.errors import InvalidInputError
from sim_core.noise import clipped_normal_mean, safe_poisson
from sim_core.optics import pixel_irradiance_w_m2
from sim_core.raw import PHASE_OFFSETS_RAD, RawFrame

#: allowed range [low, high] (both included) of each numeric sensor parameter: checked by
#: :class:`SensorParams` and by the scene spec's sensor overrides (:mod:`sim_core.scene_spec`)
SENSOR_BOUNDS: dict[str, tuple[float, float]] = {
    "pixel_pitch_m": (1e-7, 1e-3),
    "fill_factor": (1e-3, 1.0),
    "quantum_efficiency": (1e-4, 1.0),
    "demodulation_contrast": (0.0, 1.0),
    "transmittance": (1e-3, 1.0),
    "full_well_e": (1.0, 1e9),
    "read_noise_e": (0.0, 1e5),
    "dark_current_e_s": (0.0, 1e9),
    "adc_bits": (1, 24),
    "adc_gain_e_per_dn": (1e-3, 1e6),
    "sbi_start_e": (1.0, 1e9),
    "sbi_limit_e": (0.0, 1e12),
}


@dataclass(frozen=True)
class SensorParams:
    """Parameters of the PMD pixel and its readout; sources in docs/camera-presets.md.

    Attributes
    ----------
    pixel_pitch_m : float
        Pixel pitch [m].
    fill_factor : float
        Light-sensitive fraction of the pixel area, [1e-3, 1].
    quantum_efficiency : float
        Electrons per photon at the camera's wavelength, (0, 1].
    demodulation_contrast : float
        D of the peer paper's eq. 6, [0, 1].
    transmittance : float
        Lens and filter transmittance tau of seed eq. 32, (0, 1].
    full_well_e : float
        Tap capacity [e-]; beyond it the pixel is saturated.
    read_noise_e : float
        Read noise per tap and readout, standard deviation [e-].
    dark_current_e_s : float
        Dark current per tap [e-/s].
    adc_bits : int
        ADC resolution; taps are digitised to [0, 2^bits - 1] DN.
    adc_gain_e_per_dn : float
        Electrons per digital number.
    sbi_start_e : float
        n_SBI,start of the seed [e-].
    sbi_limit_e : float
        Largest compensation charge the SBI circuit supplies per exposure [e-].
    sbi_enabled : bool
        Whether the SBI circuit is active.
    """

    pixel_pitch_m: float = 17.5e-6
    fill_factor: float = 0.6
    quantum_efficiency: float = 0.3
    demodulation_contrast: float = 0.8
    transmittance: float = 0.85
    full_well_e: float = 100_000.0
    read_noise_e: float = 25.0
    dark_current_e_s: float = 2_000.0
    adc_bits: int = 12
    adc_gain_e_per_dn: float = 10.0
    sbi_start_e: float = 36_500.0
    sbi_limit_e: float = 500_000.0
    sbi_enabled: bool = True

    def __post_init__(self) -> None:
        for name, (lo, hi) in SENSOR_BOUNDS.items():
            v = getattr(self, name)
            if not (np.isfinite(v) and lo <= v <= hi):
                raise InvalidInputError(f"sensor.{name}", f"{v} is outside [{lo}, {hi}]")

    def to_dict(self) -> dict:
        return asdict(self)


def f_number(camera: Camera, sensor: SensorParams) -> float:
    """F/# = focal length / aperture diameter, focal length = fx [px] * pixel pitch."""
    return camera.intrinsics.fx_px * sensor.pixel_pitch_m / camera.aperture_diameter_m


def electrons_per_irradiance(camera: Camera, sensor: SensorParams) -> float:
    """Electrons collected in one exposure per W/m^2 of pixel irradiance (peer eqs. 4-5).

    N = E * A_pixel * fill * T / (h c / lambda) * QE. ``power_w`` of the camera's source is its
    mean power over the modulation period, so no extra duty-cycle factor applies.
    """
    area = sensor.pixel_pitch_m**2 * sensor.fill_factor
    photon_j = PLANCK_J_S * SPEED_OF_LIGHT_M_S / camera.wavelength_m
    return area * camera.exposure_s / photon_j * sensor.quantum_efficiency


@dataclass(frozen=True)
class PixelElectrons:
    """Mean electrons per exposure: active DC, ambient, dark, and the active phasor (n_f).

    A static scene has one light for every phase step: ``active``, ``ambient`` (H, W) and
    ``phasor`` (n_f, H, W). A scene that moved during the frame has one per phase step
    (:mod:`sim_core.subframes`): ``active``, ``ambient`` and ``phasor`` (n_f, 4, H, W).
    """

    active: np.ndarray
    ambient: np.ndarray
    dark: float
    phasor: np.ndarray


def mean_electrons(
    dc_active: np.ndarray,
    dc_ambient: np.ndarray,
    phasor: np.ndarray,
    camera: Camera,
    sensor: SensorParams,
) -> PixelElectrons:
    """Radiance images (after optics) to mean electrons per exposure (seed eq. 32)."""
    fn = f_number(camera, sensor)
    k = electrons_per_irradiance(camera, sensor)

    def to_e(radiance):
        return k * pixel_irradiance_w_m2(radiance, camera, sensor.transmittance, fn)

    return PixelElectrons(
        active=to_e(dc_active),
        ambient=to_e(dc_ambient),
        dark=sensor.dark_current_e_s * camera.exposure_s,
        phasor=to_e(phasor),
    )


def tap_means(e: PixelElectrons, sensor: SensorParams) -> tuple[np.ndarray, np.ndarray]:
    """Mean tap charges A, B, each (n_f, 4, H, W) [e-] (peer eqs. 13-14, module docstring).

    Phase step i of frequency k correlates its own light (``e.phasor[k, i]`` when the scene
    moved during the frame, :class:`PixelElectrons`) with the reference shifted by tau_i.
    """
    per_step = e.phasor.ndim == 4
    common = 0.5 * (e.active + e.ambient + e.dark)
    if common.ndim == 2:
        common = common[None, None]
    rot = np.exp(1j * PHASE_OFFSETS_RAD)[None, :, None, None]
    phasor = e.phasor if per_step else e.phasor[:, None]
    modulated = 0.5 * sensor.demodulation_contrast * np.real(rot * np.conj(phasor))
    return common + modulated, common - modulated


def expose(
    e: PixelElectrons,
    camera: Camera,
    sensor: SensorParams,
    rng: np.random.Generator | None,
    meta: dict | None = None,
) -> RawFrame:
    """Tap charges with noise, SBI, saturation and ADC; ``rng=None`` gives the noise-free frame:
    the noisy frames' mean (the readout's clipping of the noise at 0 included), unquantised.

    Returns a :class:`RawFrame` in DN (taps and their differences).
    """
    a_mean, b_mean = tap_means(e, sensor)
    if rng is not None:
        a = safe_poisson(rng, a_mean)
        b = safe_poisson(rng, b_mean)
    else:
        a, b = a_mean.copy(), b_mean.copy()
    sbi_limit = np.zeros(a.shape[-2:], dtype=bool)
    if sensor.sbi_enabled:
        excess = np.maximum(np.maximum(a, b) - sensor.sbi_start_e, 0.0)
        # The circuit removes the same charge from both taps, but never more than the emptier
        # tap holds: beyond that the difference (the phase) alone fills the fuller tap, which
        # then reaches full well and is flagged, instead of the emptier tap going negative.
        removable = np.minimum(excess, np.minimum(a, b))
        if rng is not None:
            comp_a = np.minimum(safe_poisson(rng, removable), a)
            comp_b = np.minimum(safe_poisson(rng, removable), b)
        else:
            comp_a = comp_b = removable
        a = a - comp_a
        b = b - comp_b
        sbi_limit = np.any(excess > sensor.sbi_limit_e, axis=(0, 1))
    if rng is not None and sensor.read_noise_e > 0.0:
        a = a + sensor.read_noise_e * rng.standard_normal(a.shape)
        b = b + sensor.read_noise_e * rng.standard_normal(b.shape)
    elif sensor.read_noise_e > 0.0:
        # The noise-free frame is the noisy frames' mean: read noise lets a dim tap go below 0,
        # where the readout clips it, so a dim tap reads more than its charge on average and a
        # dim pixel's A - B less (3.3 % of a 28 DN pixel's amplitude at 48 e- read noise). Shot
        # and read noise as one normal distribution, censored at 0.
        a = clipped_normal_mean(a, np.sqrt(np.maximum(a, 0.0) + sensor.read_noise_e**2))
        b = clipped_normal_mean(b, np.sqrt(np.maximum(b, 0.0) + sensor.read_noise_e**2))
    saturated = np.any((a >= sensor.full_well_e) | (b >= sensor.full_well_e), axis=(0, 1))
    a = np.clip(a, 0.0, sensor.full_well_e)
    b = np.clip(b, 0.0, sensor.full_well_e)
    top = float(2**sensor.adc_bits - 1)
    a_dn = a / sensor.adc_gain_e_per_dn
    b_dn = b / sensor.adc_gain_e_per_dn
    if rng is not None:  # quantisation is part of the noise; the ideal frame stays continuous
        a_dn, b_dn = np.round(a_dn), np.round(b_dn)
    saturated |= np.any((a_dn >= top) | (b_dn >= top), axis=(0, 1))
    a_dn = np.clip(a_dn, 0.0, top)
    b_dn = np.clip(b_dn, 0.0, top)
    return RawFrame(
        phase_images=(a_dn - b_dn).astype(np.float32),
        intensity=(0.25 * (a_dn + b_dn)[0].sum(axis=0)).astype(np.float32),
        frequencies_hz=np.asarray(camera.modulation_frequencies_hz, dtype=np.float64),
        saturated=saturated,
        sbi_limit=sbi_limit,
        exposure_s=camera.exposure_s,
        taps=np.stack([a_dn, b_dn], axis=2).astype(np.float32),
        meta={"sensor": sensor.to_dict(), **(meta or {})},
    )


def predicted_phase_std_rad(e: PixelElectrons, sensor: SensorParams, k: int = 0) -> np.ndarray:
    """Shot- and read-noise-limited standard deviation of the phase [rad], per pixel; it is
    also the relative standard deviation of the amplitude (the noise is the same along and
    across the phasor).

    Each C_i = A_i - B_i has variance N_tot + 2 sigma_r^2 (+ 2 n_delta with SBI active), with
    N_tot = N_dc + N_amb + N_dark the electrons of one exposure; the phasor
    Z = (C0 - C2) - 1j (C3 - C1) has magnitude 2 D |N_f| and per-component variance twice
    that. So sigma_phi = sqrt(var(C) / 2) / (D |N_f|) (seed eq. 7 before the range factor).
    Infinite where there is no modulated signal.
    """
    n_tot = e.active + e.ambient + e.dark
    var_c = n_tot + 2.0 * sensor.read_noise_e**2
    if sensor.sbi_enabled:
        # Upper bound of the compensation charge: the fuller tap's excess over n_SBI,start.
        half = 0.5 * n_tot + 0.5 * sensor.demodulation_contrast * np.abs(e.phasor[k])
        var_c = var_c + 2.0 * np.maximum(half - sensor.sbi_start_e, 0.0)
    signal = sensor.demodulation_contrast * np.abs(e.phasor[k])
    # A subnormal signal's quotient overflows to inf: no measurable modulation, as for 0.
    with np.errstate(divide="ignore", over="ignore"):
        return np.where(signal > 0.0, np.sqrt(0.5 * var_c) / np.where(signal > 0, signal, 1),
                        np.inf)


def predicted_range_std_m(
    e: PixelElectrons, sensor: SensorParams, frequency_hz: float, k: int = 0
) -> np.ndarray:
    """Shot- and read-noise-limited standard deviation of range [m], per pixel:
    c / (4 pi f) times :func:`predicted_phase_std_rad` (seed eq. 7). Infinite where there is no
    modulated signal.
    """
    sigma_phi = predicted_phase_std_rad(e, sensor, k)
    return SPEED_OF_LIGHT_M_S / (4.0 * np.pi * frequency_hz) * sigma_phi
