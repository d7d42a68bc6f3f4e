"""The twin's prediction of the measured views for a candidate object twin (our own renderer).

For a candidate mount offset and reflectance scales (an :class:`~sim_core.twin_file.
ObjectTwinParameters`), the calibration is combined with it
(:func:`sim_core.twin_file.with_object_twin`, the same path a scene's ``object_twin: FILE``
takes) and every captured view is rendered at the angle the rig reported, with the solar
simulator's shutter closed, and exposed noise-free (the sensor's mean response, as
:mod:`calibration.twin_prediction` does): the camera's depth errors, optics and sensor included,
so the prediction is compared with the averaged capture as measured, in the camera's own
quantity: the raw correlation phasor ``(C0 - C2) - 1j (C3 - C1)`` of every frequency [DN]
(:meth:`sim_core.raw.RawFrame.phasor`). It carries range and amplitude together, and at a
silhouette it mixes the object and the background as the pixel does.

What makes a prediction cheap:

- every view renders every effect (:func:`sim_core.plan.plan_effects` with ``"all"``: the
  planner's ``"auto"`` judges an effect against one frame's noise, while the fit compares with
  averaged frames, and its verdict on a marginal effect, the interreflections between panels and
  body, flips with the reflectances being fitted; a twin without light the frames have biases a
  panel's scale by a few per cent); the plan is made once per view and kept;
- only the *region* is re-rendered: the pixels that see a mounted object at the starting pose,
  grown by :data:`MARGIN_PX` (a mount offset within the fit's reach moves a silhouette by a few
  pixels). The rest of the frame is static (the turntable's surroundings; the camera's own light
  casts the object's shadow behind it) and comes from one full render per view with the same
  seed, spliced in before the optics, so the optics' blur across the region's edge is right;
- a fixed seed: a pixel's k-th sample is the same in every render (common random numbers), so
  predictions of nearby candidates differ by the candidates, not by Monte Carlo noise, and the
  stratified pixel jitter makes a silhouette's coverage converge like 1/N.

The render's own Monte Carlo variance (the light field's per-sample covariance) comes with each
prediction, converted to DN: :func:`calibration.object_twin.refine.phasor_sigma` puts it in the
residual's weights.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

from calibration.captures import AveragedCapture
from calibration.object_twin.views import capture_spec
from sim_core.pipeline import RenderedLight, expose_light
from sim_core.plan import EffectPlan, plan_effects
from sim_core.raw import RawFrame
from sim_core.render import LightField, RenderSettings
from sim_core.render.integrator import ProgressiveRenderer
from sim_core.scene import Scene, build_scene
from sim_core.scene_spec import SceneSpec
from sim_core.sensor import SensorParams
from sim_core.tracing import RayTracer
from sim_core.twin_file import ObjectTwinParameters, TwinParameters, with_object_twin

#: how the fit renders: path tracing with one bounce between surfaces, 64 samples per pixel, a
#: fixed seed
FIT_RENDER = RenderSettings(integrator="path", spp=64, max_bounces=2, seed=14)
#: pixels around the mounted objects (at the starting pose) that are re-rendered and compared
#: [px]: ~5 mm of offset per pixel at 1 m, plus the optics' blur
MARGIN_PX = 6


def measured_phasor(capture: AveragedCapture) -> np.ndarray:
    """The averaged capture's raw phasor ``(C0 - C2) - 1j (C3 - C1)`` per frequency, (n_f, H, W)
    [DN]."""
    c = capture.phase_images
    return (c[:, 0] - c[:, 2]) - 1j * (c[:, 3] - c[:, 1])


@dataclass(frozen=True)
class PredictedView:
    """The twin's noise-free prediction of one captured view.

    Attributes
    ----------
    phasor : (n_f, H, W) complex128
        The raw phasor ``(C0 - C2) - 1j (C3 - C1)`` of the sensor's mean response [DN].
    mc_var : (n_f, 2, H, W) float64
        Monte Carlo variance of the real and imaginary parts of ``phasor`` [DN^2] (per sample:
        divide by the samples per pixel for the render's own).
    taps : (n_f, 4, 2, H, W) float64
        The sensor's mean tap values [DN] (the shot noise's scale).
    object_id : (H, W) int
        Index into the scene's objects of what each pixel centre sees (-1: nothing).
    saturated : (H, W) bool
        Pixels the sensor model saturates (or holds at its SBI limit).
    """

    phasor: np.ndarray = field(repr=False)
    mc_var: np.ndarray = field(repr=False)
    taps: np.ndarray = field(repr=False)
    object_id: np.ndarray = field(repr=False)
    saturated: np.ndarray = field(repr=False)

    @property
    def amplitude(self) -> np.ndarray:
        """Amplitude at the first frequency (seed eq. 5: half the raw phasor's magnitude) [DN]."""
        return 0.5 * np.abs(self.phasor[0])


@dataclass
class _View:
    capture: AveragedCapture
    spec: SceneSpec
    plan: EffectPlan
    run: RenderSettings
    static: LightField = field(repr=False)
    pixels: np.ndarray = field(repr=False)
    region: np.ndarray = field(repr=False)
    sensor: SensorParams = field(default_factory=SensorParams)


def _splice(static: LightField, part: LightField, pixels: np.ndarray) -> LightField:
    """``static`` with the ``pixels`` (flat) of ``part``; the ground truth is ``part``'s."""
    def put(a, b):
        out = a.copy()
        flat_out = out.reshape(*out.shape[:-2], -1)
        flat_b = b.reshape(*b.shape[:-2], -1)
        flat_out[..., pixels] = flat_b[..., pixels]
        return out
    return dataclasses.replace(
        part, dc_active=put(static.dc_active, part.dc_active),
        dc_ambient=put(static.dc_ambient, part.dc_ambient),
        phasor=put(static.phasor, part.phasor),
        samples_per_pixel=put(static.samples_per_pixel, part.samples_per_pixel),
        dc_active_var=put(static.dc_active_var, part.dc_active_var),
        dc_ambient_var=put(static.dc_ambient_var, part.dc_ambient_var),
        phasor_cov=put(static.phasor_cov, part.phasor_cov))


class TwinRenderer:
    """Renders the captured views for candidate object twins (module docstring).

    Parameters
    ----------
    spec, base_dir
        The nominal scene and its folder.
    calibration : TwinParameters or None
        The rig's calibration (camera, rig); never the object keys being fitted.
    captures : list of AveragedCapture
    settings : RenderSettings
    start : ObjectTwinParameters
        The starting candidate: the plans and the regions are made for it.
    mounted : tuple of str
        The on-turntable objects (their pixels make the region).
    margin_px : int
    """

    def __init__(self, spec: SceneSpec, base_dir: str | Path, calibration: TwinParameters | None,
                 captures: list[AveragedCapture], settings: RenderSettings,
                 start: ObjectTwinParameters, mounted: tuple[str, ...],
                 margin_px: int = MARGIN_PX) -> None:
        self.spec = spec
        self.base_dir = Path(base_dir)
        self.calibration = calibration or TwinParameters()
        self.settings = settings
        self.renders = 0
        self.pixels_rendered = 0
        self.margin_px = margin_px
        self._ids = [i for i, o in enumerate(spec.objects) if o.name in mounted]
        self.views: list[_View] = []
        for cap in captures:
            cspec = capture_spec(spec, cap).model_copy(
                update={"calibration": None, "object_twin": None})
            scene = self._scene(cspec, cap, start)
            with RayTracer(scene.triangles_m, scene.camera.position_m,
                           settings.threads) as tracer:
                # Every effect, as the frames have them; the shutter is closed (no ambient).
                plan = plan_effects(scene, settings, "all", tracer=tracer)
                run = dataclasses.replace(
                    settings, ambient=False,
                    footprint_px=plan.pixel_footprint_px(scene))
                static, region = self._static(scene, run, tracer)
            self.views.append(_View(cap, cspec, plan, run, static, np.flatnonzero(region),
                                    region, scene.sensor))

    def _static(self, scene: Scene, run: RenderSettings,
                tracer: RayTracer | None = None) -> tuple[LightField, np.ndarray]:
        """A view's full render at one candidate, and its region (the mounted objects' pixels
        grown by the margin)."""
        r = ProgressiveRenderer(scene, run, tracer)
        try:
            r.add_samples(run.spp)
            static = r.light_field()
        finally:
            r.close()  # closes only a tracer it made
        region = ndimage.binary_dilation(np.isin(static.object_id, self._ids),
                                         iterations=self.margin_px)
        return static, region

    def recentre(self, object_twin: ObjectTwinParameters) -> None:
        """Make every view's static render and region again at ``object_twin`` (the effect plans
        stay): a candidate far from where the regions were made would move a silhouette out of
        its region, where neither the render nor the residual sees it."""
        for v in self.views:
            v.static, v.region = self._static(self._scene(v.spec, v.capture, object_twin), v.run)
            v.pixels = np.flatnonzero(v.region)

    @property
    def regions(self) -> list[np.ndarray]:
        """Each view's re-rendered pixels, (H, W) bool."""
        return [v.region for v in self.views]

    def _scene(self, cspec: SceneSpec, cap: AveragedCapture,
               object_twin: ObjectTwinParameters) -> Scene:
        return build_scene(cspec, self.base_dir, turntable_deg=cap.turntable_angle_deg,
                           solar_suns=0.0, twin=with_object_twin(self.calibration, object_twin),
                           illumination_temperature_c=cap.illumination_temperature_c)

    def predict(self, object_twin: ObjectTwinParameters) -> list[PredictedView]:
        """The prediction of every captured view under ``object_twin``."""
        out = []
        for v in self.views:
            scene = self._scene(v.spec, v.capture, object_twin)
            r = ProgressiveRenderer(scene, v.run)
            try:
                r.add_samples(v.run.spp, v.pixels)
                lf = _splice(v.static, r.light_field(), v.pixels)
            finally:
                r.close()
            frame = expose_light(scene, RenderedLight(lf, v.run, v.plan, {}, 0, 0.0, {}),
                                 noise=False)
            raw: RawFrame = frame.raw
            phasor = raw.phasor()
            out.append(PredictedView(
                phasor=phasor, mc_var=_mc_var_dn(lf, phasor, v.region),
                taps=np.asarray(raw.taps, dtype=np.float64), object_id=lf.object_id,
                saturated=raw.saturated | raw.sbi_limit))
            self.renders += 1
            self.pixels_rendered += int(v.pixels.size)
        return out


def _mc_var_dn(lf: LightField, phasor_dn: np.ndarray, region: np.ndarray) -> np.ndarray:
    """Per-sample variance of the phasor's parts in DN^2, (n_f, 2, H, W): the light field's
    radiance covariance times the square of the view's gain (DN per radiance, the ratio of the
    summed magnitudes over the region: the optics spread but keep the light), the largest of
    each pixel's 3 x 3 neighbourhood. A pixel next to a bright face's silhouette whose samples
    all missed the face reports no variance, yet another render's samples (or the pose a
    fraction of a pixel off) reach into it, and the optics spread an edge pixel's error onto its
    neighbours: the neighbourhood's maximum covers both."""
    out = np.zeros((lf.phasor.shape[0], 2, *lf.shape))
    for f in range(lf.phasor.shape[0]):
        rad = float(np.abs(lf.phasor[f][region]).sum())
        gain = float(np.abs(phasor_dn[f][region]).sum()) / rad if rad > 0.0 else 0.0
        for k in (0, 1):
            out[f, k] = ndimage.maximum_filter(gain**2 * lf.phasor_cov[f, k], size=3)
    return out
