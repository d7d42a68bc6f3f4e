"""Wavefront path tracing for an AMCW ToF camera (seed section 2.3.1, eqs. 17-31).

Every bounce is one batch of rays for the whole image (and several sample passes at once).
Each path carries its total length L from the light source through all bounces to the pixel;
a path's contribution ``w`` (radiance, W m^-2 sr^-1) adds to the DC image and
``w * exp(-1j * 2*pi*f*L / c)`` to each modulation frequency's phasor (eqs. 17, 31). Ambient
light adds to DC only.

Integrators
-----------
- ``direct``: camera -> surface -> light, one vertex (the peer paper's direct model, eqs. 1-2).
- ``path``: up to ``max_bounces`` surface interactions. At every vertex, next-event estimation
  towards the point source (eqs. 20-21) and each ambient source (shadow rays), then BRDF
  importance sampling of the next direction (eq. 22 with the pdf of the material), Russian
  roulette from ``russian_roulette_from_bounce`` on. The point and collimated sources are
  delta lights: BRDF-sampled rays can never hit them, so next-event estimation alone is
  unbiased and no multiple importance sampling is needed.

Determinism
-----------
Sample pass ``s`` (one sample for every pixel) draws all its random numbers from its own
generator ``numpy.random.default_rng([seed, s])`` in a fixed order, and per-pass pixel sums are
formed with ``np.bincount`` in ray order. Passes are grouped into wavefronts by a rule that only
depends on the image size, and Embree's answers do not depend on threading, so the same seed
gives bit-identical images whatever the number of threads.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from sim_core.camera import pixel_centre_grid
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.materials.kernels import N_PARAMS, PARALLEL_KERNEL_LOCK
from sim_core.render import kernels
from sim_core.render.kernels import camera_rays
from sim_core.render.lightfield import LightField
from sim_core.scene import Scene
from sim_core.tracing import RayTracer

#: rays per wavefront we aim for (Embree throughput is flat from ~10k rays per call and thread)
WAVEFRONT_RAYS = 1 << 18
#: relative offset of secondary-ray origins along the normal; Embree is float32 (~6e-8 relative),
#: so origins closer than ~100 ulps re-hit the surface they start on (self-intersection).
RAY_OFFSET_REL = 1e-5
#: absolute floor of that offset [m], for points near the render origin
RAY_OFFSET_MIN_M = 1e-6
#: a surface closer than this to the point source would see an infinite irradiance I/d^2 [m]
MIN_LIGHT_DISTANCE_M = 1e-4


@dataclass(frozen=True)
class RenderSettings:
    """How to render.

    Attributes
    ----------
    integrator : "direct" or "path"
    spp : int
        Samples (sample passes) per pixel.
    max_bounces : int
        Surface interactions on a path from the light to the camera; 1 = direct only.
    seed : int
    russian_roulette_from_bounce : int
        First bounce index at which paths may be terminated at random.
    threads : int or None
        Threads for Embree queries (default: all cores). Never changes the result.
    ambient : bool
        Whether ambient sources are traced at all.
    jitter : bool
        Spread samples over the pixel footprint (box filter, antialiasing). False traces every
        sample through the pixel centre, which closed-form checks compare against.
    footprint_px : float
        Side of the square, centred on the pixel, that jittered samples cover [px]: 1 for the
        whole pixel, sqrt(fill factor) for the light-sensitive area only (the pixel-aperture
        MTF, sampled exactly instead of filtered).
    """

    integrator: str = "path"
    spp: int = 16
    max_bounces: int = 3
    seed: int = 0
    russian_roulette_from_bounce: int = 3
    threads: int | None = None
    ambient: bool = True
    jitter: bool = True
    footprint_px: float = 1.0

    @property
    def effective_bounces(self) -> int:
        return 1 if self.integrator == "direct" else self.max_bounces


@dataclass
class RenderResult:
    """A light field and what it cost."""

    light_field: LightField
    seconds: float
    embree_seconds: float
    rays_traced: int
    timings_s: dict[str, float] = field(default_factory=dict)

    @property
    def embree_share(self) -> float:
        """Fraction of the wall time spent inside Embree queries."""
        return self.embree_seconds / self.seconds if self.seconds > 0 else 0.0


class _Accumulator:
    """Running per-pixel sums and sums of squares of per-sample values, with per-pixel counts."""

    def __init__(self, npix: int, n_f: int) -> None:
        self.npix = npix
        self.n = np.zeros(npix, dtype=np.int64)
        self.s_active = np.zeros(npix)
        self.ss_active = np.zeros(npix)
        self.s_ambient = np.zeros(npix)
        self.ss_ambient = np.zeros(npix)
        self.s_re = np.zeros((n_f, npix))
        self.s_im = np.zeros((n_f, npix))
        self.ss_re = np.zeros((n_f, npix))
        self.ss_im = np.zeros((n_f, npix))
        self.s_reim = np.zeros((n_f, npix))

    def add(self, active, ambient, re, im, pixels: np.ndarray) -> None:
        """Add g passes over ``pixels`` given as (g, npix) arrays (phasor parts (n_f, g, npix)).

        Pixels that were not traced hold zeros and do not count as sampled.
        """
        self.n[pixels] += active.shape[0]
        self.s_active += active.sum(axis=0)
        self.ss_active += (active * active).sum(axis=0)
        self.s_ambient += ambient.sum(axis=0)
        self.ss_ambient += (ambient * ambient).sum(axis=0)
        self.s_re += re.sum(axis=1)
        self.s_im += im.sum(axis=1)
        self.ss_re += (re * re).sum(axis=1)
        self.ss_im += (im * im).sum(axis=1)
        self.s_reim += (re * im).sum(axis=1)

    def mean(self, s: np.ndarray) -> np.ndarray:
        """Per-pixel mean; unsampled pixels (n = 0) report 0, not 0/0."""
        return s / np.maximum(self.n, 1)

    def cov(self, a: np.ndarray, b: np.ndarray, sab: np.ndarray) -> np.ndarray:
        """Unbiased per-sample covariance of two quantities; 0 with fewer than 2 samples."""
        n = self.n
        nn = np.maximum(n, 1)
        c = (sab / nn - (a / nn) * (b / nn)) * (nn / np.maximum(nn - 1, 1))
        return np.where(n >= 2, c, 0.0)

    def var(self, s: np.ndarray, ss: np.ndarray) -> np.ndarray:
        # Clamp tiny negative values from cancellation; a variance is never negative.
        return np.maximum(self.cov(s, s, ss), 0.0)


class ProgressiveRenderer:
    """A render that can take more samples, for every pixel or for some, at any time.

    ``render`` is this with ``spp`` samples for every pixel; adaptive sampling
    (:mod:`sim_core.adaptive`) adds samples where the estimated error is still too large. A
    pixel's k-th sample is the same whichever pixels are traced with it, so the result depends
    only on how many samples each pixel got.
    """

    def __init__(
        self, scene: Scene, settings: RenderSettings, tracer: RayTracer | None = None
    ) -> None:
        self._t_start = time.perf_counter()
        self.scene = scene
        self.settings = settings
        cam = scene.camera
        self.shape = cam.intrinsics.shape
        self.npix = self.shape[0] * self.shape[1]
        self._own_tracer = tracer is None
        self.tracer = tracer or RayTracer(scene.triangles_m, cam.position_m, settings.threads)
        self._stats0 = self.tracer.stats.snapshot()
        self.timings_s: dict[str, float] = {"path_tracing": 0.0}
        self.ctx = _Context(scene, settings, self.tracer, cam.position_m)
        t0 = time.perf_counter()
        with PARALLEL_KERNEL_LOCK:
            self._truth = _ground_truth(self.ctx)
        self.timings_s["ground_truth"] = time.perf_counter() - t0
        self.acc = _Accumulator(self.npix, self.ctx.n_f)

    @property
    def samples(self) -> np.ndarray:
        """Samples taken so far per pixel, (H, W)."""
        return self.acc.n.reshape(self.shape)

    def add_samples(
        self,
        n: int,
        pixels: np.ndarray | None = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> None:
        """Take ``n`` more samples of each pixel in ``pixels`` (flat indices; default all)."""
        if pixels is None:
            pix = np.arange(self.npix, dtype=np.int64)
        else:
            pix = np.asarray(pixels, dtype=np.int64)
        if pix.size == 0 or n <= 0:
            return
        t0 = time.perf_counter()
        group = max(1, WAVEFRONT_RAYS // pix.size)
        done = 0
        while done < n:
            g = min(group, n - done)
            with PARALLEL_KERNEL_LOCK:
                _render_passes(self.ctx, pix, self.acc.n[pix], g, self.acc)
            done += g
            if progress is not None:
                progress(done, n)
        self.timings_s["path_tracing"] += time.perf_counter() - t0

    def light_field(self) -> LightField:
        """The estimate so far."""
        acc, ctx, shape = self.acc, self.ctx, self.shape
        var_re = acc.var(acc.s_re, acc.ss_re)
        var_im = acc.var(acc.s_im, acc.ss_im)
        cov = acc.cov(acc.s_re, acc.s_im, acc.s_reim)
        return LightField(
            frequencies_hz=ctx.freqs.copy(),
            dc_active=acc.mean(acc.s_active).reshape(shape),
            dc_ambient=acc.mean(acc.s_ambient).reshape(shape),
            phasor=acc.mean(acc.s_re + 1j * acc.s_im).reshape((ctx.n_f, *shape)),
            samples_per_pixel=acc.n.astype(np.int32).reshape(shape),
            dc_active_var=acc.var(acc.s_active, acc.ss_active).reshape(shape),
            dc_ambient_var=acc.var(acc.s_ambient, acc.ss_ambient).reshape(shape),
            phasor_cov=np.stack([var_re, var_im, cov], axis=1).reshape((ctx.n_f, 3, *shape)),
            **self._truth,
        )

    def result(self) -> RenderResult:
        """The light field and what it cost so far."""
        stats = self.tracer.stats
        return RenderResult(
            light_field=self.light_field(),
            seconds=time.perf_counter() - self._t_start,
            embree_seconds=stats.seconds - self._stats0.seconds,
            rays_traced=stats.rays - self._stats0.rays,
            timings_s=dict(self.timings_s),
        )

    def close(self) -> None:
        if self._own_tracer:
            self.tracer.close()


def render(
    scene: Scene,
    settings: RenderSettings,
    tracer: RayTracer | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RenderResult:
    """Render ``scene`` with ``settings.spp`` samples per pixel into a :class:`LightField`.

    Parameters
    ----------
    scene : Scene
    settings : RenderSettings
    tracer : RayTracer, optional
        Reuse an Embree scene built for this geometry (its origin must be the camera centre).
    progress : callable, optional
        Called as ``progress(samples_done, samples_total)`` after each wavefront.
    """
    r = ProgressiveRenderer(scene, settings, tracer)
    try:
        r.add_samples(settings.spp, progress=progress)
        return r.result()
    finally:
        r.close()


def material_tables(materials) -> tuple[np.ndarray, np.ndarray]:
    """Kernel ids (M,) int64 and parameter vectors (M, N_PARAMS) float64 of the materials."""
    kinds = np.array([m.kernel_kind for m in materials], dtype=np.int64)
    params = np.zeros((len(materials), N_PARAMS))
    for i, m in enumerate(materials):
        params[i] = m.kernel_params()
    return kinds, params


class _Context:
    """Per-render constants shared by the stages, as the arrays the kernels take."""

    def __init__(self, scene: Scene, settings: RenderSettings, tracer: RayTracer, origin) -> None:
        self.scene = scene
        self.settings = settings
        self.tracer = tracer
        self.origin = np.asarray(origin, dtype=np.float64)
        self.freqs = np.asarray(scene.camera.modulation_frequencies_hz, dtype=np.float64)
        self.n_f = self.freqs.size
        #: phase per metre of path, Psi of eq. 17 [rad/m]
        self.psi_rad_m = 2.0 * np.pi * self.freqs / SPEED_OF_LIGHT_M_S
        self.u_px, self.v_px = pixel_centre_grid(scene.camera.intrinsics)
        self.npix = self.u_px.size
        self.rotation = np.ascontiguousarray(scene.camera.rotation)
        intr = scene.camera.intrinsics
        self.intr = intr
        self.distortion = np.asarray(intr.distortion, dtype=np.float64)
        self.normals = np.ascontiguousarray(scene.normals, dtype=np.float64)
        self.tri_mat = np.ascontiguousarray(scene.material_index, dtype=np.int64)
        self.mat_kind, self.mat_params = material_tables(scene.materials)
        light = scene.light
        self.light_pos = np.asarray(light.position_m - self.origin, dtype=np.float64)
        self.light_axis = np.asarray(light.axis, dtype=np.float64)
        self.light_scale = float(light.scale_w_sr)
        if light.profile_angle_rad is None:
            self.prof_angle = np.zeros(0)
            self.prof_rel = np.zeros(0)
        else:
            self.prof_angle = np.asarray(light.profile_angle_rad, dtype=np.float64)
            self.prof_rel = np.asarray(light.profile_relative, dtype=np.float64)
        amb = scene.ambient if settings.ambient else ()
        n_a = len(amb)
        self.n_ambient = n_a
        self.amb_dir = np.array([a.direction for a in amb], dtype=np.float64).reshape(n_a, 3)
        self.amb_irr = np.array([a.irradiance_w_m2 for a in amb], dtype=np.float64)
        self.amb_footprint = np.array(
            [a.footprint_centre_m is not None and a.footprint_size_m is not None for a in amb],
            dtype=np.bool_,
        )
        self.amb_centre = np.array(
            [a.footprint_centre_m if f else np.zeros(3)
             for a, f in zip(amb, self.amb_footprint, strict=True)],
            dtype=np.float64,
        ).reshape(n_a, 3)
        self.amb_size = np.array(
            [a.footprint_size_m if f else (0.0, 0.0)
             for a, f in zip(amb, self.amb_footprint, strict=True)],
            dtype=np.float64,
        ).reshape(n_a, 2)
        self.amb_u = np.array([a.footprint_u for a in amb], dtype=np.float64).reshape(n_a, 3)
        self.amb_v = np.array([a.footprint_v for a in amb], dtype=np.float64).reshape(n_a, 3)


def _ground_truth(ctx: _Context) -> dict:
    """Range, depth, normal and object through every pixel centre (no jitter)."""
    h, w = ctx.intr.shape
    d = camera_rays(
        ctx.u_px, ctx.v_px, ctx.intr.fx_px, ctx.intr.fy_px, ctx.intr.cx_px, ctx.intr.cy_px,
        ctx.distortion, ctx.rotation,
    )
    tfar, prim = ctx.tracer.intersect32(np.zeros_like(d, dtype=np.float32), d.astype(np.float32))
    hit = prim >= 0
    rng = np.where(hit, tfar.astype(np.float64), np.nan)
    normal = np.zeros((ctx.npix, 3))
    obj = np.full(ctx.npix, -1, dtype=np.int32)
    if hit.any():  # an empty scene has no normal table to index
        normal[hit] = ctx.normals[prim[hit]]
        facing = np.einsum("ij,ij->i", normal, d) > 0.0
        normal[facing] *= -1.0
        obj[hit] = ctx.scene.object_index[prim[hit]]
    # z component of each unit direction in the camera frame: depth_z = range * z.
    z_cam = d @ ctx.rotation[:, 2]
    return {
        "truth_range_m": rng.reshape(h, w),
        "truth_depth_z_m": (rng * z_cam).reshape(h, w),
        "truth_normal": normal.reshape(h, w, 3),
        "object_id": obj.reshape(h, w),
        "hit": hit.reshape(h, w),
    }


def _shadow(tracer: RayTracer, contrib, origins, dirs, t_max) -> np.ndarray:
    """Occlusion of the shadow rays whose contribution is positive; (k,) bool, False elsewhere."""
    blocked = np.zeros(contrib.shape[0], dtype=np.bool_)
    sel = np.flatnonzero(contrib > 0.0)
    if sel.size:
        o, d, t = kernels.gather_rays(sel, origins, dirs, t_max)
        blocked[sel] = tracer.occluded32(o, d, t)
    return blocked


def _render_passes(
    ctx: _Context, pixels: np.ndarray, first_sample: np.ndarray, g: int, acc: _Accumulator
) -> None:
    """Trace ``g`` more samples of each pixel in ``pixels`` (one wavefront), add them to ``acc``."""
    npix = ctx.npix
    st = ctx.settings
    m = g * npix
    out_active = np.zeros(m)
    out_ambient = np.zeros(m)
    out_re = np.zeros((ctx.n_f, m))
    out_im = np.zeros((ctx.n_f, m))

    d, slot, keys = kernels.primary_rays(
        st.seed, pixels, first_sample, g, npix, ctx.u_px, ctx.v_px,
        st.footprint_px if st.jitter else 0.0, ctx.intr.fx_px,
        ctx.intr.fy_px, ctx.intr.cx_px, ctx.intr.cy_px, ctx.distortion, ctx.rotation,
    )
    o = np.zeros_like(d)
    length = np.zeros(d.shape[0])
    throughput = np.ones(d.shape[0])

    n_bounces = st.effective_bounces
    for b in range(1, n_bounces + 1):
        tfar, prim = ctx.tracer.intersect32(o, d)
        hit = np.flatnonzero(prim >= 0)
        if hit.size == 0:
            break
        (flat, act, act_len, sh_o, sh_d, sh_t, amb, amb_o,
         nxt_o, nxt_d, nxt_len, nxt_thr, alive) = kernels.bounce(
            hit, o, d, tfar, prim, slot, keys, length, throughput,
            ctx.normals, ctx.tri_mat, ctx.mat_kind, ctx.mat_params,
            ctx.light_pos, ctx.light_axis, ctx.light_scale, ctx.prof_angle, ctx.prof_rel,
            MIN_LIGHT_DISTANCE_M, ctx.amb_dir, ctx.amb_irr, ctx.amb_centre, ctx.amb_u,
            ctx.amb_v, ctx.amb_size, ctx.amb_footprint, ctx.origin,
            b, st.russian_roulette_from_bounce, b < n_bounces,
        )
        blocked = _shadow(ctx.tracer, act, sh_o, sh_d, sh_t)
        kernels.accumulate_vertices(
            flat, act, act_len, blocked, ctx.psi_rad_m, out_active, out_re, out_im
        )
        for a in range(ctx.n_ambient):
            dirs = np.empty_like(amb_o[a])
            dirs[:] = -ctx.amb_dir[a]
            tmax = np.full(amb_o[a].shape[0], np.finfo(np.float32).max, dtype=np.float32)
            blocked = _shadow(ctx.tracer, amb[a], amb_o[a], dirs, tmax)
            kernels.accumulate_ambient(flat, amb[a], blocked, out_ambient)
        if b == n_bounces:
            break
        keep = np.flatnonzero(alive)
        src = hit[keep]
        o, d, _ = kernels.gather_rays(keep, nxt_o, nxt_d, np.empty(0, dtype=np.float32))
        slot, keys = slot[src], keys[src]
        length, throughput = nxt_len[keep], nxt_thr[keep]

    gshape = (g, npix)
    acc.add(
        out_active.reshape(gshape), out_ambient.reshape(gshape),
        out_re.reshape(ctx.n_f, *gshape), out_im.reshape(ctx.n_f, *gshape), pixels,
    )
