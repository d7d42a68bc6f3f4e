"""The effect planner: simulate only what a scene calls for, and say why.

``plan_effects`` renders a small probe of the scene (a coarse image with the same field of
view, a few samples per pixel, all bounces) and decides quantitatively, effect by effect,
whether it changes the frame by more than a tolerance:

- multipath (bounces beyond direct): the probe's indirect light is the difference between a
  path render and a direct render with the same seed (their primary rays and direct light are
  identical), so the planner knows the indirect-to-direct ratio and the range bias the indirect
  light causes, in millimetres; off when the bias stays below the tolerance;
- ambient light: off when there is no ambient source, when it lights no surface the camera sees,
  or when its electrons are negligible against the active signal's;
- SBI: only when the predicted charge of some tap can pass n_SBI,start;
- each MTF component: off when it is the identity within ``mtf_tolerance`` up to Nyquist;
- motion: only when the scene asks for it; noise: off for an ideal sensor;
- stray light: only when the twin has ``camera.stray_light`` with a fraction and radius above 0;
- temperature drift: only when the twin has ``camera.temperature`` with a drift and the frame's
  illumination temperature differs from the start (or is not known yet: the simulated lab
  renders once and applies each frame's temperature as it exposes); off for an ideal sensor.

The default tolerance is a quarter of the median predicted range noise of the object pixels
(at least 0.1 mm); ``effect_tolerance_mm`` sets it.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from sim_core import optics
from sim_core.camera import Camera, Intrinsics
from sim_core.raw import ValidityThresholds
from sim_core.render import RenderSettings, render
from sim_core.scene import Scene
from sim_core.sensor import f_number, mean_electrons, predicted_range_std_m
from sim_core.tof import phase_from_phasor, range_from_phase
from sim_core.tracing import RayTracer

#: probe image width [px]; the height follows the aspect ratio
PROBE_WIDTH_PX = 56
#: samples per pixel of the probe renders
PROBE_SPP = 4
#: ambient light below this fraction of the active electrons is negligible
AMBIENT_FRACTION_TOLERANCE = 0.01
#: an MTF component deviating less than this from 1 up to Nyquist is the identity
MTF_TOLERANCE = 0.01
#: margin on the predicted tap charge before SBI is ruled out (probe noise, unseen highlights)
SBI_MARGIN = 1.5
#: tolerance for an ideal (noise-free) sensor [mm]
IDEAL_TOLERANCE_MM = 0.5
#: ray throughput used to turn ray counts into seconds; measured by `toftwin bench render`
#: (path integrator, example scenes, 2 cores). The probe itself is too small to time.
NOMINAL_RAYS_PER_S = 5e6


@dataclass(frozen=True)
class Effect:
    """One decision of the plan."""

    name: str
    enabled: bool
    reason: str
    cost_s: float = 0.0
    numbers: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class EffectPlan:
    """What to simulate for one frame."""

    mode: str
    effects: tuple[Effect, ...]
    tolerance_mm: float
    probe_seconds: float

    def enabled(self, name: str) -> bool:
        return any(e.name == name and e.enabled for e in self.effects)

    def mtf_components(self, scene: Scene) -> list:
        return [c for c in all_mtf_components(scene) if self.enabled(c.name)]

    def pixel_footprint_px(self, scene: Scene) -> float:
        """Side of the sampled square per pixel: the light-sensitive area, or the whole pixel."""
        if self.enabled("pixel_aperture"):
            return float(np.sqrt(scene.sensor.fill_factor))
        return 1.0

    def to_dict(self) -> dict:
        return {
            "mode": self.mode,
            "tolerance_mm": self.tolerance_mm,
            "probe_seconds": self.probe_seconds,
            "effects": [e.to_dict() for e in self.effects],
        }

    def explain(self) -> str:
        """A table of every effect: on/off, estimated cost and the reason with its numbers."""
        lines = [f"effect plan ({self.mode}; tolerance {self.tolerance_mm:.3g} mm, "
                 f"probe {self.probe_seconds:.2f} s)"]
        for e in self.effects:
            state = "on " if e.enabled else "off"
            lines.append(f"  {e.name:<15} {state}  ~{e.cost_s:7.3f} s  {e.reason}")
        return "\n".join(lines)


def all_mtf_components(scene: Scene) -> list:
    """The MTF components the scene's optics block describes (before any decision)."""
    cam, sensor, spec = scene.camera, scene.sensor, scene.optics
    comps: list = []
    if spec.diffraction:
        comps.append(optics.Diffraction(cam.wavelength_m, f_number(cam, sensor),
                                        sensor.pixel_pitch_m))
    if spec.electronics_cutoff_cycles_per_px is not None:
        comps.append(optics.Electronics(spec.electronics_cutoff_cycles_per_px))
    if spec.motion is not None:
        comps.append(optics.LinearMotion(spec.motion.length_px, spec.motion.direction_deg))
    if spec.vibration_sigma_px is not None:
        comps.append(optics.Vibration(spec.vibration_sigma_px))
    return comps


def probe_camera(camera: Camera, width_px: int = PROBE_WIDTH_PX) -> Camera:
    """The camera at a coarse resolution with the same field of view and pose."""
    intr = camera.intrinsics
    scale = min(1.0, width_px / intr.width_px)
    w = max(1, round(intr.width_px * scale))
    h = max(1, round(intr.height_px * scale))
    probe = Intrinsics(
        w, h, intr.fx_px * scale, intr.fy_px * scale,
        (intr.cx_px + 0.5) * scale - 0.5, (intr.cy_px + 0.5) * scale - 0.5, intr.distortion,
    )
    return dataclasses.replace(camera, intrinsics=probe)


def plan_effects(
    scene: Scene,
    settings: RenderSettings,
    mode: str = "auto",
    ideal: bool = False,
    tolerance_mm: float | None = None,
    tracer: RayTracer | None = None,
) -> EffectPlan:
    """Decide which effects to simulate; see the module docstring."""
    if mode not in ("auto", "all"):
        raise ValueError(f"effects mode must be 'auto' or 'all', got {mode!r}")
    t0 = time.perf_counter()
    small = dataclasses.replace(scene, camera=probe_camera(scene.camera))
    own = tracer is None
    tracer = tracer or RayTracer(scene.triangles_m, scene.camera.position_m, settings.threads)
    base = dataclasses.replace(settings, spp=PROBE_SPP, jitter=True)
    direct = render(small, dataclasses.replace(base, integrator="direct", ambient=True), tracer)
    wants_bounces = settings.integrator == "path" and settings.max_bounces > 1
    full = (
        render(small, dataclasses.replace(base, integrator="path"), tracer) if wants_bounces
        else direct
    )
    if own:
        tracer.close()
    probe_s = time.perf_counter() - t0
    # Probe ray counts scaled to the real frame's pixels and samples give the cost estimates.
    scale = (scene.camera.intrinsics.width_px * scene.camera.intrinsics.height_px
             * settings.spp) / (small.camera.intrinsics.width_px
                                * small.camera.intrinsics.height_px * PROBE_SPP)
    multipath_s = (full.rays_traced - direct.rays_traced) * scale / NOMINAL_RAYS_PER_S
    # One shadow ray per ambient source for every primary hit (half the direct rays).
    ambient_s = 0.5 * direct.rays_traced * scale / NOMINAL_RAYS_PER_S

    lf_d, lf_p = direct.light_field, full.light_field
    e = mean_electrons(lf_p.dc_active, lf_p.dc_ambient, lf_p.phasor, small.camera, scene.sensor)
    f0 = float(lf_p.frequencies_hz[0])
    seen = lf_p.hit & (lf_p.dc_active > 0.0)
    if ideal:
        tol = IDEAL_TOLERANCE_MM if tolerance_mm is None else tolerance_mm
        noise_mm = 0.0
    else:
        # Only pixels the camera would report set the tolerance: one far below the validity
        # threshold (a dark backdrop) has a huge predicted noise but never reaches the frame.
        amplitude_dn = (scene.sensor.demodulation_contrast * np.abs(e.phasor[0])
                        / scene.sensor.adc_gain_e_per_dn)
        measurable = seen & (amplitude_dn >= ValidityThresholds().min_amplitude_dn)
        sigma = predicted_range_std_m(e, scene.sensor, f0)[measurable] * 1e3
        sigma = sigma[np.isfinite(sigma)]
        noise_mm = float(np.median(sigma)) if sigma.size else 0.0
        tol = max(0.25 * noise_mm, 0.1) if tolerance_mm is None else tolerance_mm
    effects = [
        _multipath(mode, settings, lf_d, lf_p, seen, f0, tol, multipath_s),
        _ambient(mode, scene, lf_p, e, seen, ambient_s),
        _sbi(mode, scene, e) if not ideal else Effect("sbi", False, "--ideal: ideal sensor"),
        _pixel_aperture(scene),
        *_mtf(mode, scene),
        _stray_light(mode, scene),
        _temperature_drift(mode, scene, ideal),
        _noise(ideal, noise_mm),
    ]
    return EffectPlan(mode=mode, effects=tuple(effects), tolerance_mm=tol, probe_seconds=probe_s)


def _multipath(mode, settings, lf_d, lf_p, seen, f0, tol, cost) -> Effect:
    if not (settings.integrator == "path" and settings.max_bounces > 1):
        return Effect("multipath", False, "the render settings ask for direct light only")
    indirect = lf_p.dc_active - lf_d.dc_active
    direct_sum = float(lf_d.dc_active[seen].sum())
    ratio = float(indirect[seen].sum()) / direct_sum if direct_sum > 0 else 0.0
    r_direct = range_from_phase(phase_from_phasor(lf_d.phasor[0]), f0)
    r_full = range_from_phase(phase_from_phasor(lf_p.phasor[0]), f0)
    bias = np.abs(r_full - r_direct)[seen] * 1e3
    # A phase difference near 2 pi is a wrap, not a bias.
    bias = np.minimum(bias, range_from_phase(2 * np.pi, f0) * 1e3 - bias)
    bias95 = float(np.percentile(bias, 95)) if bias.size else 0.0
    nums = {"indirect_to_direct": ratio, "range_bias_p95_mm": bias95, "tolerance_mm": tol}
    if mode == "all":
        return Effect("multipath", True, "--effects all", cost, nums)
    if bias95 > tol:
        return Effect("multipath", True, f"indirect/direct {ratio:.3f}, range bias p95 "
                      f"{bias95:.3g} mm > {tol:.3g} mm", cost, nums)
    return Effect("multipath", False, f"indirect/direct {ratio:.3g}, range bias p95 "
                  f"{bias95:.3g} mm <= {tol:.3g} mm", cost, nums)


def _ambient(mode, scene, lf, e, seen, cost_one) -> Effect:
    if not scene.ambient:
        return Effect("ambient", False, "the scene has no ambient source")
    cost = cost_one * len(scene.ambient)
    amb = e.ambient[seen]
    act = e.active[seen]
    if not np.any(lf.dc_ambient > 0.0):
        nums = {"ambient_e_max": 0.0}
        if mode == "all":
            return Effect("ambient", True, "--effects all", cost, nums)
        return Effect("ambient", False, "no surface the camera sees is lit by "
                      f"{', '.join(a.name for a in scene.ambient)} (probe)", cost, nums)
    frac = float(amb.max() / max(act[amb.argmax()], 1e-300)) if amb.size else 0.0
    nums = {"ambient_e_max": float(amb.max()) if amb.size else 0.0,
            "ambient_to_active_at_max": frac}
    if mode == "all" or frac > AMBIENT_FRACTION_TOLERANCE:
        why = "--effects all" if mode == "all" else (
            f"up to {nums['ambient_e_max']:.3g} e- of ambient light, {frac:.3g} x the active "
            "signal there")
        return Effect("ambient", True, why, cost, nums)
    return Effect("ambient", False, f"ambient electrons at most {frac:.3g} x the active signal "
                  f"(< {AMBIENT_FRACTION_TOLERANCE})", cost, nums)


def _sbi(mode, scene, e) -> Effect:
    s = scene.sensor
    if not s.sbi_enabled:
        return Effect("sbi", False, "the sensor has no SBI circuit (sensor.sbi_enabled false)")
    tap_max = 0.5 * (e.active + e.ambient + e.dark) + 0.5 * s.demodulation_contrast * np.abs(
        e.phasor[0])
    peak = float(tap_max.max()) * SBI_MARGIN
    nums = {"tap_peak_e": float(tap_max.max()), "sbi_start_e": s.sbi_start_e}
    if mode == "all" or peak >= s.sbi_start_e:
        why = "--effects all" if mode == "all" else (
            f"predicted tap charge up to {nums['tap_peak_e']:.3g} e- (x{SBI_MARGIN} margin) "
            f"reaches n_SBI,start {s.sbi_start_e:.3g} e-")
        return Effect("sbi", True, why, 0.001, nums)
    return Effect("sbi", False, f"predicted tap charge at most {nums['tap_peak_e']:.3g} e- "
                  f"(x{SBI_MARGIN} margin) < n_SBI,start {s.sbi_start_e:.3g} e-", 0.0, nums)


def _pixel_aperture(scene) -> Effect:
    """The pixel aperture is sampled, not filtered: samples land on the light-sensitive area."""
    if not scene.optics.pixel_aperture:
        return Effect("pixel_aperture", False, "optics.pixel_aperture is false: samples cover "
                      "the whole pixel")
    side = float(np.sqrt(scene.sensor.fill_factor))
    return Effect("pixel_aperture", True, f"sampled: each pixel's samples cover its "
                  f"light-sensitive square of {side:.2f} px (fill factor "
                  f"{scene.sensor.fill_factor})", 0.0, {"footprint_px": side})


def _mtf(mode, scene) -> list[Effect]:
    out = []
    for c in all_mtf_components(scene):
        dev = optics.max_deviation_from_identity(c)
        nums = {"max_deviation": dev}
        if c.name == "motion":
            out.append(Effect("motion", True, f"the scene asks for {c.length_px} px of motion",
                              0.01, nums))
        elif mode == "all" or dev > MTF_TOLERANCE:
            why = "--effects all" if mode == "all" else (
                f"departs from identity by up to {dev:.3g} at Nyquist")
            out.append(Effect(c.name, True, why, 0.01, nums))
        else:
            out.append(Effect(c.name, False, f"identity within {dev:.2g} <= {MTF_TOLERANCE} up "
                              "to Nyquist", 0.0, nums))
    return out


def _stray_light(mode, scene) -> Effect:
    s = scene.stray_light
    if s is None:
        return Effect("stray_light", False, "the twin has no camera.stray_light")
    nums = {"fraction": s.fraction, "radius_px": s.radius_px}
    if mode == "all":
        return Effect("stray_light", True, "--effects all", 0.005, nums)
    if s.fraction == 0.0 or s.radius_px == 0.0:
        return Effect("stray_light", False, f"fraction {s.fraction:g}, radius {s.radius_px:g} "
                      "px: no light leaves its pixel", 0.0, nums)
    return Effect("stray_light", True, f"{100 * s.fraction:.3g} % of each pixel's light spread "
                  f"with a Gaussian of {s.radius_px:g} px", 0.005, nums)


def _temperature_drift(mode, scene, ideal: bool) -> Effect:
    d = scene.temperature_drift
    if d is None:
        return Effect("temperature_drift", False, "the twin has no camera.temperature")
    if ideal:
        return Effect("temperature_drift", False, "--ideal: no depth errors")
    t = scene.illumination_temperature_c
    nums = {"start_c": d.start_c, "illumination_temperature_c": t,
            "drift_mm_per_c": d.drift_mm_per_c.tolist()}
    if mode == "all":
        return Effect("temperature_drift", True, "--effects all", 0.0, nums)
    if not np.any(d.drift_mm_per_c != 0.0):
        return Effect("temperature_drift", False, "depth_drift_mm_per_c is 0", 0.0, nums)
    if t is None:
        return Effect("temperature_drift", True, "applied at each frame's reported "
                      "illumination temperature (none reported: no drift)", 0.0, nums)
    if t == d.start_c:
        return Effect("temperature_drift", False, f"the illumination is at its start, "
                      f"{t:g} degC", 0.0, nums)
    drift_mm = (d.drift_mm_per_c * (t - d.start_c)).tolist()
    return Effect("temperature_drift", True, f"{t:g} degC, {t - d.start_c:+.3g} degC from the "
                  f"start: range drift {', '.join(f'{v:+.3g}' for v in drift_mm)} mm", 0.0,
                  {**nums, "range_drift_mm": drift_mm})


def _noise(ideal: bool, noise_mm: float) -> Effect:
    if ideal:
        return Effect("noise", False, "--ideal: noise-free sensor")
    return Effect("noise", True, f"shot, read and quantisation noise (median predicted range "
                  f"noise {noise_mm:.3g} mm)", 0.005, {"range_noise_median_mm": noise_mm})
