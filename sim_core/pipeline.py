"""From a posed scene to a frame: plan, render, optics, sensor, reconstruct, save.

    plan_effects -> render (LightField) -> MTF chain (seed eq. 33) -> PMD pixel (RawFrame)
    -> reconstruction (ToFImage, seed eqs. 4-7)

With ``ideal=True`` the sensor is ideal: no noise, SBI, ADC or depth errors (a calibration's
``camera.depth``); depth comes from the phase of the (filtered) rendered phasor and grey from its
magnitude. Otherwise the scene's depth errors (:mod:`sim_core.depth_errors`) enter the phasors
after the optics, before the sensor, and so does the warm-up drift at the scene's illumination
temperature (:mod:`sim_core.warmup`); stray light (:class:`sim_core.optics.StrayLight`) spreads
the light after the MTF chain, ideal sensor or not.

A scene that moves during the frame (the turntable turning) is rendered once per phase step at
its pose at that step's time (:mod:`sim_core.subframes`) and each step exposes its own light
(:func:`simulate_in_motion`); a scene that moves less than the tolerance is rendered once.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sim_core import frame_io
from sim_core.adaptive import MAX_SPP, AdaptiveReport, render_adaptive
from sim_core.camera import Intrinsics
from sim_core.camera import z_over_range as camera_z_over_range
from sim_core.optics import apply_mtf
from sim_core.plan import EffectPlan, plan_effects
from sim_core.raw import PHASE_OFFSETS_RAD, RawFrame, reconstruct_raw
from sim_core.render import LightField, RenderSettings, render
from sim_core.render_request import RenderRequest
from sim_core.scene import Scene
from sim_core.scene_checks import assert_camera_outside_closed_meshes
from sim_core.sensor import expose, mean_electrons
from sim_core.subframes import N_PHASE_STEPS, moves_during_frame
from sim_core.tof import ToFImage, reconstruct
from sim_core.tracing import RayTracer

#: stream of the sensor-noise generator, so noise never shares numbers with the renderer
NOISE_STREAM = 0x5E45


@dataclass
class SimulatedFrame:
    """A simulated frame with everything needed to save, compare and explain it."""

    image: ToFImage
    light_field: LightField
    settings: RenderSettings
    scene_hash: str
    timings_s: dict[str, float]
    rays_traced: int
    embree_share: float  # share of the render threads' time inside Embree
    plan: EffectPlan
    raw: RawFrame | None = None
    ideal: bool = True
    #: amplitude shown as grey 255 (:func:`sim_core.frame_io.grey_full_scale`)
    grey_full_scale: float | None = None
    adaptive: AdaptiveReport | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: render worker threads' time per stage (Embree, kernels) [thread-seconds]
    render_thread_seconds: dict[str, float] = field(default_factory=dict)
    #: :func:`sim_core.twin_file.twin_hash` of the calibration the scene applied, if any
    calibration_hash: str | None = None
    #: the camera the frame was rendered with: its intrinsics and pose (camera frame to the
    #: scene's world, 4 x 4), written into frame.json so other tools can make points of it
    intrinsics: Intrinsics | None = None
    world_from_camera: np.ndarray | None = field(default=None, repr=False)


def z_over_range(scene: Scene) -> np.ndarray:
    """:func:`sim_core.camera.z_over_range` of the scene's camera, (H, W)."""
    return camera_z_over_range(scene.camera.intrinsics)


@dataclass
class RenderedLight:
    """The renderer's part of a frame: the light field and what it took (before optics).

    :func:`expose_light` turns it into a frame; exposing the same one several times gives
    frames that differ by sensor noise only, as repeated frames of a static scene do.
    """

    light_field: LightField
    settings: RenderSettings
    plan: EffectPlan
    timings_s: dict[str, float]
    rays_traced: int
    embree_share: float
    render_thread_seconds: dict[str, float]
    adaptive: AdaptiveReport | None = None
    #: wall time of :func:`render_light`, set-up included [s]
    seconds: float = 0.0


def render_light(
    scene: Scene,
    request: RenderRequest,
    tracer: RayTracer | None = None,
    progress=None,
) -> RenderedLight:
    """Plan the effects and render the light field (the first stages of :func:`simulate`).

    ``request.accuracy`` decides the samples: ``settings.spp`` everywhere, or adaptively
    (:class:`sim_core.render_request.AccuracyTarget`, :func:`sim_core.adaptive.render_adaptive`).
    """
    settings, accuracy = request.settings, request.accuracy
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    own_tracer = tracer is None
    if tracer is None:
        tracer = RayTracer(scene.triangles_m, scene.camera.position_m, threads=settings.threads)
    try:
        assert_camera_outside_closed_meshes(scene, tracer)
        t = time.perf_counter()
        plan = plan_effects(scene, settings, request.effects, request.ideal,
                            request.tolerance_mm, tracer)
        timings["plan"] = time.perf_counter() - t
        multipath = plan.enabled("multipath")
        run = dataclasses.replace(
            settings,
            integrator=settings.integrator if multipath else "direct",
            ambient=plan.enabled("ambient"),
            footprint_px=plan.pixel_footprint_px(scene),
        )
        adaptive = None
        if not accuracy.adaptive:
            result = render(scene, run, tracer=tracer, progress=progress)
        else:
            target_m = (None if accuracy.range_error_mm is None
                        else accuracy.range_error_mm * 1e-3)
            initial = accuracy.initial_spp(settings)
            result, adaptive = render_adaptive(
                scene, run, target_m, accuracy.time_budget_s, tracer, initial_spp=initial,
                max_spp=max(MAX_SPP, initial), target_noise_fraction=accuracy.noise_fraction)
    finally:
        if own_tracer:
            tracer.close()
    timings["render"] = result.seconds
    timings.update({f"render.{k}": v for k, v in result.timings_s.items()})
    return RenderedLight(
        light_field=result.light_field, settings=run, plan=plan, timings_s=timings,
        rays_traced=result.rays_traced, embree_share=result.embree_share,
        render_thread_seconds=dict(result.stage_thread_seconds), adaptive=adaptive,
        seconds=time.perf_counter() - t0,
    )


@dataclass(frozen=True)
class SensorLight:
    """The light on the sensor of one rendered light field: what of the optics does not change
    from frame to frame (:func:`sensor_light`). Exposing the same render many times (a world's
    repeated frames of one rig state) computes it once."""

    #: DC of the camera's own light and of the ambient light (H, W) [W m^-2 sr^-1]
    dc_active: np.ndarray
    dc_ambient: np.ndarray
    #: the phasors (n_f, H, W), after the camera's phase errors unless ``ideal``
    phasor: np.ndarray
    ideal: bool


def sensor_light(scene: Scene, plan: EffectPlan, lf: LightField, ideal: bool) -> SensorLight:
    """The light after the MTF chain, the stray light and (unless ``ideal``) the camera's own
    phase errors: DC active, DC ambient and phasors. All of it is noise-free and fixed for a
    given render; the warm-up's drift, which follows each frame's temperature, is not in it
    (:func:`_optics` adds it)."""
    comps = plan.mtf_components(scene)
    # Ringing of the MTF can leave tiny negative radiance next to a bright edge: clamp DC.
    dc_active = np.maximum(apply_mtf(lf.dc_active, comps), 0.0)
    dc_ambient = np.maximum(apply_mtf(lf.dc_ambient, comps), 0.0)
    phasor = apply_mtf(lf.phasor, comps)
    if scene.stray_light is not None and plan.enabled("stray_light"):
        # Scattered light spreads DC and phasors alike (linear in the light, like the MTF), as
        # irradiance on the sensor: radiance times cos^4 of the field angle (seed eq. 32).
        cos4 = z_over_range(scene) ** 4
        dc_active, dc_ambient, phasor = (scene.stray_light.apply(a, cos4)
                                         for a in (dc_active, dc_ambient, phasor))
    if not ideal and scene.depth_errors is not None:
        # The camera's own phase errors act on each pixel's correlation, after the optics.
        phasor = scene.depth_errors.apply_to_phasor(phasor)
    return SensorLight(dc_active, dc_ambient, phasor, ideal)


def _optics(scene: Scene, plan: EffectPlan, lf: LightField, ideal: bool,
            light: SensorLight | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The light after the MTF chain and the camera's phase errors: DC active, DC ambient (H, W)
    and phasors (n_f, H, W). ``light``: :func:`sensor_light` of this render, if kept."""
    if light is None or light.ideal != ideal:
        light = sensor_light(scene, plan, lf, ideal)
    phasor = light.phasor
    if (not ideal and scene.temperature_drift is not None
            and scene.illumination_temperature_c is not None
            and plan.enabled("temperature_drift")):
        # The warm-up drift: a phase offset per frequency at the frame's temperature.
        phasor = scene.temperature_drift.apply_to_phasor(phasor,
                                                         scene.illumination_temperature_c)
    return light.dc_active, light.dc_ambient, phasor


def _stacked_steps(scene: Scene, plan: EffectPlan, steps: Sequence[RenderedLight],
                   ideal: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each phase step's light after the optics, ``(n_f, 4, H, W)`` each: step ``i`` of
    frequency ``k`` is ``steps[4 k + i]`` and keeps its own phasor at frequency ``k``."""
    n_f = len(scene.camera.modulation_frequencies_hz)
    if len(steps) != N_PHASE_STEPS * n_f:
        raise ValueError(f"steps: {len(steps)} lights for {n_f} frequencies; expected "
                         f"{N_PHASE_STEPS * n_f} (4 phase steps each)")
    h, w = scene.camera.intrinsics.shape
    active = np.empty((n_f, N_PHASE_STEPS, h, w))
    ambient = np.empty((n_f, N_PHASE_STEPS, h, w))
    phasor = np.empty((n_f, N_PHASE_STEPS, h, w), dtype=np.complex128)
    for s, step in enumerate(steps):
        k, i = divmod(s, N_PHASE_STEPS)
        a, b, z = _optics(scene, plan, step.light_field, ideal)
        active[k, i], ambient[k, i], phasor[k, i] = a, b, z[k]
    return active, ambient, phasor


def demodulated_phasor(step_phasors: np.ndarray) -> np.ndarray:
    """The phasor the four-step demodulation sees when each step has its own, ``(n_f, H, W)``.

    Step i correlates to ``C_i = Re(exp(1j tau_i) conj(p_i))`` (seed eq. 3); the raw frame's
    phasor ``(C0 - C2) - 1j (C3 - C1)`` (:meth:`sim_core.raw.RawFrame.phasor`, seed eq. 4) is
    twice the phasor when all four are equal, so half of it is returned: equal steps give their
    common phasor back.

    >>> p = np.full((1, 4, 1, 1), 2.0 * np.exp(-0.7j))
    >>> bool(np.allclose(demodulated_phasor(p), p[:, 0]))
    True
    """
    rot = np.exp(1j * PHASE_OFFSETS_RAD)[None, :, None, None]
    c = np.real(rot * np.conj(step_phasors))
    return 0.5 * ((c[:, 0] - c[:, 2]) - 1j * (c[:, 3] - c[:, 1]))


def expose_light(
    scene: Scene,
    rendered: RenderedLight,
    ideal: bool = False,
    noise_rng: np.random.Generator | None = None,
    noise: bool = True,
    steps: Sequence[RenderedLight] | None = None,
    light: SensorLight | None = None,
) -> SimulatedFrame:
    """Optics, depth errors, sensor and reconstruction of a rendered light field.

    ``noise=False`` gives the sensor's mean response (no shot or read noise, no quantisation):
    what a calibration compares averaged frames with. ``steps``: when the scene moved during
    the frame, the light of each phase step (``4 n_f``, frequency by frequency, each rendered
    at its time: :func:`simulate_in_motion`); ``rendered`` is then the first of them.
    ``light``: :func:`sensor_light` of ``rendered`` for ``scene`` when the caller keeps it (it
    exposes the same render again); computed here when None.
    """
    t0 = time.perf_counter()
    timings = dict(rendered.timings_s)
    lf, plan, run = rendered.light_field, rendered.plan, rendered.settings
    t = time.perf_counter()
    if steps is None:
        dc_active, dc_ambient, phasor = _optics(scene, plan, lf, ideal, light)
    else:
        dc_active, dc_ambient, phasor = _stacked_steps(scene, plan, steps, ideal)
    timings["optics"] = time.perf_counter() - t

    t = time.perf_counter()
    raw = None
    if ideal:
        if steps is not None:  # what the demodulation makes of the steps' lights, noise-free
            phasor = demodulated_phasor(phasor)
            dc_active, dc_ambient = dc_active[0].mean(axis=0), dc_ambient[0].mean(axis=0)
        image = reconstruct(
            phasor=phasor, intensity=dc_active + dc_ambient, frequencies_hz=lf.frequencies_hz,
            z_over_range=z_over_range(scene), valid=np.abs(phasor[0]) > 0.0,
        )
    else:
        sensor = dataclasses.replace(scene.sensor, sbi_enabled=plan.enabled("sbi"))
        e = mean_electrons(dc_active, dc_ambient, phasor, scene.camera, sensor)
        rng = None
        if noise and plan.enabled("noise"):
            rng = noise_rng or np.random.default_rng([run.seed, NOISE_STREAM])
        meta = {"seed": run.seed} if steps is None else {"seed": run.seed, "subframes": True}
        raw = expose(e, scene.camera, sensor, rng, meta=meta)
        timings["sensor"] = time.perf_counter() - t
        t = time.perf_counter()
        image = reconstruct_raw(raw, z_over_range(scene))
    grey_full_scale = frame_io.grey_full_scale(
        image.amplitude, image.valid, None if ideal else sensor.adc_bits
    )
    timings["reconstruct"] = time.perf_counter() - t
    timings["total"] = rendered.seconds + sum(s.seconds for s in (steps or [])[1:]) + (
        time.perf_counter() - t0)
    return SimulatedFrame(
        image=image,
        light_field=lf,
        settings=run,
        scene_hash=scene.scene_hash,
        timings_s=timings,
        rays_traced=rendered.rays_traced,
        embree_share=rendered.embree_share,
        render_thread_seconds=dict(rendered.render_thread_seconds),
        plan=plan,
        raw=raw,
        ideal=ideal,
        grey_full_scale=grey_full_scale,
        adaptive=rendered.adaptive,
        calibration_hash=scene.twin_hash,
        intrinsics=scene.camera.intrinsics,
        world_from_camera=np.array(scene.camera.world_from_camera, dtype=np.float64),
        extra={} if steps is None else {"subframes_rendered": len({id(s) for s in steps})},
    )


def mean_intensities(scene: Scene, rendered: RenderedLight, ambient_scales: Sequence[float],
                     active_scale: float = 1.0) -> list[np.ndarray]:
    """The sensor's mean intensity [DN] (the raw frame's tap sum, seed eq. 6) of ``rendered``
    with its ambient light scaled by each of ``ambient_scales`` (each >= 0): what
    :func:`expose_light` with ``noise=False`` gives as ``raw.intensity``, frame by frame, with
    the optics applied once (they are linear in the light, and their clamp at zero commutes
    with a non-negative scale) and the sensor per scale (SBI and saturation are not linear).
    ``active_scale`` (>= 0) scales the camera's own light alike (its DC and phasors: a source
    power other than the render's). A fit that varies the levels and the optics' stray light
    calls it many times."""
    if any(not k >= 0.0 for k in ambient_scales):
        raise ValueError(f"ambient_scales: {list(ambient_scales)}; each must be >= 0")
    if not active_scale >= 0.0:
        raise ValueError(f"active_scale: {active_scale!r}; must be >= 0")
    dc_active, dc_ambient, phasor = _optics(scene, rendered.plan, rendered.light_field, False)
    dc_active, phasor = dc_active * active_scale, phasor * active_scale
    sensor = dataclasses.replace(scene.sensor, sbi_enabled=rendered.plan.enabled("sbi"))
    return [expose(mean_electrons(dc_active, dc_ambient * k, phasor, scene.camera, sensor),
                   scene.camera, sensor, None).intensity.astype(np.float64)
            for k in ambient_scales]


def render_in_motion(
    scene_at: Callable[[float], Scene],
    angles_deg: np.ndarray,
    request: RenderRequest,
) -> tuple[Scene, list[RenderedLight] | RenderedLight]:
    """Render a frame whose turntable is at ``angles_deg[k, i]`` at phase step i of frequency k.

    ``scene_at(angle_deg)`` poses the scene. When the angles span no more than
    :data:`sim_core.subframes.MOTION_TOLERANCE_DEG` one render at the first step's angle comes
    back (the scene did not move); otherwise one render per distinct angle, as a list of the
    ``4 n_f`` steps' lights in order (:func:`expose_light`'s ``steps``). Returns the scene of
    the first step with it.
    """
    a = np.asarray(angles_deg, dtype=np.float64)
    first = scene_at(float(a.flat[0]))
    if not moves_during_frame(a):
        return first, render_light(first, request)
    lights: dict[float, RenderedLight] = {}
    steps: list[RenderedLight] = []
    for angle in a.ravel():
        key = round(float(angle), 9)
        if key not in lights:
            scene = first if not lights else scene_at(float(angle))
            lights[key] = render_light(scene, request)
        steps.append(lights[key])
    return first, steps


def simulate_in_motion(
    scene_at: Callable[[float], Scene],
    angles_deg: np.ndarray,
    request: RenderRequest,
    noise_rng: np.random.Generator | None = None,
) -> SimulatedFrame:
    """:func:`simulate` of a frame taken while the turntable moves: each phase step rendered
    at its angle (:func:`render_in_motion`) and exposed with its own light."""
    scene, light = render_in_motion(scene_at, angles_deg, request)
    if isinstance(light, RenderedLight):
        return expose_light(scene, light, request.ideal, noise_rng)
    return expose_light(scene, light[0], request.ideal, noise_rng, steps=light)


def simulate(
    scene: Scene,
    request: RenderRequest,
    tracer: RayTracer | None = None,
    progress=None,
    noise_rng: np.random.Generator | None = None,
) -> SimulatedFrame:
    """Simulate one frame of ``scene`` as ``request`` asks; see the module docstring for the
    stages: :func:`render_light` then :func:`expose_light`.

    ``noise_rng`` replaces the sensor-noise generator derived from the request's seed (the
    camera simulator draws each frame's noise from its own seed and frame number).
    """
    rendered = render_light(scene, request, tracer, progress)
    return expose_light(scene, rendered, request.ideal, noise_rng)


def save_frame(out_dir: str | Path, frame: SimulatedFrame, scene_name: str = "") -> Path:
    """Write the frame folder (:func:`sim_core.frame_io.write_simulated`)."""
    return frame_io.write_simulated(out_dir, frame, scene_name)
