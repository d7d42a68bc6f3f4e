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

from sim_core.camera import pixel_centre_grid, pixel_to_camera_direction
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.render import kernels
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
    """

    integrator: str = "path"
    spp: int = 16
    max_bounces: int = 3
    seed: int = 0
    russian_roulette_from_bounce: int = 3
    threads: int | None = None
    ambient: bool = True
    jitter: bool = True

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
    """Running per-pixel sums and sums of squares of per-pass sample values."""

    def __init__(self, npix: int, n_f: int) -> None:
        self.npix = npix
        self.n = 0
        self.s_active = np.zeros(npix)
        self.ss_active = np.zeros(npix)
        self.s_ambient = np.zeros(npix)
        self.ss_ambient = np.zeros(npix)
        self.s_re = np.zeros((n_f, npix))
        self.s_im = np.zeros((n_f, npix))
        self.ss_re = np.zeros((n_f, npix))
        self.ss_im = np.zeros((n_f, npix))
        self.s_reim = np.zeros((n_f, npix))

    def add(self, active, ambient, re, im) -> None:
        """Add passes given as (g, npix) arrays (phasor parts: (n_f, g, npix))."""
        self.n += active.shape[0]
        self.s_active += active.sum(axis=0)
        self.ss_active += (active * active).sum(axis=0)
        self.s_ambient += ambient.sum(axis=0)
        self.ss_ambient += (ambient * ambient).sum(axis=0)
        self.s_re += re.sum(axis=1)
        self.s_im += im.sum(axis=1)
        self.ss_re += (re * re).sum(axis=1)
        self.ss_im += (im * im).sum(axis=1)
        self.s_reim += (re * im).sum(axis=1)

    @staticmethod
    def _var(s, ss, n):
        if n < 2:
            return np.zeros_like(s)
        mean = s / n
        # Clamp tiny negative values from cancellation; the variance is never negative.
        return np.maximum(ss / n - mean * mean, 0.0) * (n / (n - 1))


class _Wavefront:
    """Alive paths of one wavefront (structure of arrays)."""

    __slots__ = ("length_m", "mat", "n", "p", "pass_id", "pix", "throughput", "wo")

    def __init__(self, pix, pass_id, p, n, wo, length_m, throughput, mat) -> None:
        self.pix, self.pass_id, self.p, self.n = pix, pass_id, p, n
        self.wo, self.length_m, self.throughput, self.mat = wo, length_m, throughput, mat


def _material_groups(mat: np.ndarray, n_materials: int) -> list[tuple[int, np.ndarray | slice]]:
    """(material, selection) pairs covering ``mat``; one slice when a single material is present."""
    if mat.size == 0:
        return []
    counts = np.bincount(mat, minlength=n_materials)
    present = np.flatnonzero(counts)
    if present.size == 1:
        return [(int(present[0]), slice(None))]
    order = np.argsort(mat, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(counts)])
    return [(int(m), order[bounds[m] : bounds[m + 1]]) for m in present]


def render(
    scene: Scene,
    settings: RenderSettings,
    tracer: RayTracer | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RenderResult:
    """Render ``scene`` into a :class:`LightField`.

    Parameters
    ----------
    scene : Scene
    settings : RenderSettings
    tracer : RayTracer, optional
        Reuse an Embree scene built for this geometry (its origin must be the camera centre).
    progress : callable, optional
        Called as ``progress(passes_done, passes_total)`` after each wavefront.
    """
    t_start = time.perf_counter()
    cam = scene.camera
    intr = cam.intrinsics
    h, w = intr.shape
    npix = h * w
    origin = cam.position_m
    own_tracer = tracer is None
    if tracer is None:
        tracer = RayTracer(scene.triangles_m, origin, threads=settings.threads)
    stats0 = tracer.stats.snapshot()
    timings: dict[str, float] = {}

    ctx = _Context(scene, settings, tracer, origin)
    t0 = time.perf_counter()
    truth = _ground_truth(ctx)
    timings["ground_truth"] = time.perf_counter() - t0

    acc = _Accumulator(npix, ctx.n_f)
    group = max(1, WAVEFRONT_RAYS // npix)
    t0 = time.perf_counter()
    for first in range(0, settings.spp, group):
        passes = range(first, min(first + group, settings.spp))
        _render_passes(ctx, passes, acc)
        if progress is not None:
            progress(passes.stop, settings.spp)
    timings["path_tracing"] = time.perf_counter() - t0

    n = acc.n
    shape = (h, w)
    lf = LightField(
        frequencies_hz=ctx.freqs.copy(),
        dc_active=(acc.s_active / n).reshape(shape),
        dc_ambient=(acc.s_ambient / n).reshape(shape),
        phasor=((acc.s_re + 1j * acc.s_im) / n).reshape((ctx.n_f, *shape)),
        samples_per_pixel=np.full(shape, n, dtype=np.int32),
        dc_active_var=_Accumulator._var(acc.s_active, acc.ss_active, n).reshape(shape),
        dc_ambient_var=_Accumulator._var(acc.s_ambient, acc.ss_ambient, n).reshape(shape),
        phasor_cov=_phasor_cov(acc, n).reshape((ctx.n_f, 3, *shape)),
        **truth,
    )
    stats = tracer.stats
    result = RenderResult(
        light_field=lf,
        seconds=time.perf_counter() - t_start,
        embree_seconds=stats.seconds - stats0.seconds,
        rays_traced=stats.rays - stats0.rays,
        timings_s=timings,
    )
    if own_tracer:
        tracer.close()
    return result


def _phasor_cov(acc: _Accumulator, n: int) -> np.ndarray:
    if n < 2:
        return np.zeros((acc.s_re.shape[0], 3, acc.npix))
    mre, mim = acc.s_re / n, acc.s_im / n
    corr = n / (n - 1)
    var_re = np.maximum(acc.ss_re / n - mre * mre, 0.0) * corr
    var_im = np.maximum(acc.ss_im / n - mim * mim, 0.0) * corr
    cov = (acc.s_reim / n - mre * mim) * corr
    return np.stack([var_re, var_im, cov], axis=1)


class _Context:
    """Per-render constants shared by the stages."""

    def __init__(self, scene: Scene, settings: RenderSettings, tracer: RayTracer, origin) -> None:
        self.scene = scene
        self.settings = settings
        self.tracer = tracer
        self.origin = origin
        self.freqs = np.asarray(scene.camera.modulation_frequencies_hz, dtype=np.float64)
        self.n_f = self.freqs.size
        #: phase per metre of path, Psi of eq. 17 [rad/m]
        self.psi_rad_m = 2.0 * np.pi * self.freqs / SPEED_OF_LIGHT_M_S
        self.light_rel = np.asarray(scene.light.position_m - origin, dtype=np.float64)
        self.ambient = scene.ambient if settings.ambient else ()
        self.n_materials = len(scene.materials)
        self.u_px, self.v_px = pixel_centre_grid(scene.camera.intrinsics)
        self.npix = self.u_px.size
        self.rotation = scene.camera.rotation
        self.normals = np.ascontiguousarray(scene.normals, dtype=np.float64)

    def trace(self, origins, directions, pix, pass_id, length_m, throughput) -> _Wavefront:
        """Closest hits of a batch of rays, as the wavefront of paths that go on."""
        t, prim = self.tracer.intersect(origins, directions)
        hit = np.flatnonzero(prim >= 0)
        p, n, wo = kernels.surface_points(
            origins[hit], directions[hit], t[hit], prim[hit], self.normals
        )
        return _Wavefront(
            pix[hit], pass_id[hit], p, n, wo, length_m[hit] + t[hit], throughput[hit],
            self.scene.material_index[prim[hit]],
        )


def _ground_truth(ctx: _Context) -> dict:
    h, w = ctx.scene.camera.intrinsics.shape
    d_cam = pixel_to_camera_direction(ctx.scene.camera.intrinsics, ctx.u_px, ctx.v_px)
    d = d_cam @ ctx.rotation.T
    t, prim = ctx.tracer.intersect(np.zeros_like(d), d)
    hit = prim >= 0
    rng = np.where(hit, t, np.nan)
    normal = np.zeros((ctx.npix, 3))
    if hit.any():
        _, n, _ = kernels.surface_points(
            np.zeros((int(hit.sum()), 3)), d[hit], t[hit], prim[hit], ctx.normals
        )
        normal[hit] = n
    obj = np.full(ctx.npix, -1, dtype=np.int32)
    obj[hit] = ctx.scene.object_index[prim[hit]]
    return {
        "truth_range_m": rng.reshape(h, w),
        "truth_depth_z_m": (rng * d_cam[:, 2]).reshape(h, w),
        "truth_normal": normal.reshape(h, w, 3),
        "object_id": obj.reshape(h, w),
        "hit": hit.reshape(h, w),
    }


def _render_passes(ctx: _Context, passes: range, acc: _Accumulator) -> None:
    """Trace one wavefront holding the sample passes ``passes`` and add it to ``acc``."""
    g = len(passes)
    npix = ctx.npix
    rngs = [np.random.default_rng([ctx.settings.seed, s]) for s in passes]
    jitter = np.concatenate([r.random((npix, 2)) for r in rngs]) - 0.5
    if not ctx.settings.jitter:
        jitter[:] = 0.0
    u = np.tile(ctx.u_px, g) + jitter[:, 0]
    v = np.tile(ctx.v_px, g) + jitter[:, 1]
    intr = ctx.scene.camera.intrinsics
    d = kernels.camera_rays(
        u, v, intr.fx_px, intr.fy_px, intr.cx_px, intr.cy_px,
        np.asarray(intr.distortion, dtype=np.float64), ctx.rotation,
    )
    m = g * npix
    out_active = np.zeros(m)
    out_ambient = np.zeros(m)
    out_re = np.zeros((ctx.n_f, m))
    out_im = np.zeros((ctx.n_f, m))

    wf = ctx.trace(
        np.zeros_like(d), d, np.tile(np.arange(npix), g), np.repeat(np.arange(g), npix),
        np.zeros(m), np.ones(m),
    )
    bounces = ctx.settings.effective_bounces
    for bounce in range(1, bounces + 1):
        if wf.pix.size == 0:
            break
        tb, bb, wo_l = kernels.shading_frames(wf.n, wf.wo)
        groups = _material_groups(wf.mat, ctx.n_materials)
        flat = wf.pass_id * npix + wf.pix
        _next_event_active(ctx, wf, groups, tb, bb, wo_l, flat, out_active, out_re, out_im)
        for light in ctx.ambient:
            _next_event_ambient(ctx, light, wf, groups, tb, bb, wo_l, flat, out_ambient)
        if bounce == bounces:
            break
        # One row of 4 uniforms per pixel and pass for this bounce: 3 for the BRDF, 1 for RR.
        u_all = np.stack([r.random((npix, 4)) for r in rngs])
        uu = u_all[wf.pass_id, wf.pix]
        wf = _continue_paths(ctx, wf, groups, tb, bb, wo_l, uu, bounce)

    gshape = (g, npix)
    acc.add(
        out_active.reshape(gshape), out_ambient.reshape(gshape),
        out_re.reshape(ctx.n_f, *gshape), out_im.reshape(ctx.n_f, *gshape),
    )


def _eval_selected(ctx: _Context, wf: _Wavefront, sel: np.ndarray, wi_l, wo_l) -> np.ndarray:
    """BRDF values at the wavefront vertices ``sel`` for directions ``wi_l`` (one per entry)."""
    f = np.zeros(sel.size)
    mats = wf.mat[sel]
    for m, part in _material_groups(mats, ctx.n_materials):
        f[part] = ctx.scene.materials[m].eval_local(wi_l[part], wo_l[sel[part]])
    return f


def _next_event_active(ctx, wf, groups, tb, bb, wo_l, flat, out_active, out_re, out_im) -> None:
    """Direct light from the camera's source at every vertex (seed eqs. 19-21)."""
    wi, dist, cos_p, origin, t_max = kernels.point_light_setup(
        wf.p, wf.n, ctx.light_rel, MIN_LIGHT_DISTANCE_M
    )
    sel = np.flatnonzero((cos_p > 0.0) & (wf.throughput > 0.0))
    if sel.size == 0:
        return
    blocked = ctx.tracer.occluded(origin[sel], wi[sel], t_max[sel])
    sel = sel[~blocked]
    if sel.size == 0:
        return
    intensity = ctx.scene.light.intensity_w_sr(-wi[sel])
    irradiance = intensity * cos_p[sel] / (dist[sel] * dist[sel])  # eq. 20 / peer eq. 1
    wi_l = kernels.gather_local(wi[sel], sel, tb, bb, wf.n)
    f = _eval_selected(ctx, wf, sel, wi_l, wo_l)
    contrib = wf.throughput[sel] * f * irradiance  # eq. 21, times the path throughput
    kernels.accumulate_modulated(
        flat[sel], contrib, wf.length_m[sel] + dist[sel], ctx.psi_rad_m, out_active, out_re, out_im
    )


def _next_event_ambient(ctx, light, wf, groups, tb, bb, wo_l, flat, out_ambient) -> None:
    """Unmodulated light from a collimated ambient source; DC only."""
    to_light = -light.direction
    cos_p = wf.n[:, 0] * to_light[0] + wf.n[:, 1] * to_light[1] + wf.n[:, 2] * to_light[2]
    lit = (cos_p > 0.0) & (wf.throughput > 0.0)
    if lit.any():
        lit &= light.in_beam(wf.p + ctx.origin)
    sel = np.flatnonzero(lit)
    if sel.size == 0:
        return
    wi = np.broadcast_to(to_light, (sel.size, 3)).copy()
    origins = kernels.offset_origins(wf.p[sel], wf.n[sel], wi)
    blocked = ctx.tracer.occluded(origins, wi, np.inf)
    sel, wi = sel[~blocked], wi[~blocked]
    if sel.size == 0:
        return
    wi_l = kernels.gather_local(wi, sel, tb, bb, wf.n)
    f = _eval_selected(ctx, wf, sel, wi_l, wo_l)
    contrib = wf.throughput[sel] * f * (light.irradiance_w_m2 * cos_p[sel])
    kernels.accumulate(flat[sel], contrib, out_ambient)


def _continue_paths(ctx, wf, groups, tb, bb, wo_l, uu, bounce) -> _Wavefront:
    """Sample the next direction by the BRDF, apply Russian roulette, trace the new rays."""
    m = wf.pix.size
    wi_l = np.zeros((m, 3))
    weight = np.zeros(m)
    for k, sel in groups:
        s = ctx.scene.materials[k].sample_local(wo_l[sel], uu[sel, :3])
        wi_l[sel] = s.wi
        weight[sel] = s.weight
    throughput = wf.throughput * weight
    alive = throughput > 0.0
    if bounce + 1 >= ctx.settings.russian_roulette_from_bounce:
        # Survival probability follows the throughput; dividing by it keeps the estimate
        # unbiased. The floor keeps 1/q bounded.
        q = np.clip(throughput, 0.05, 1.0)
        alive &= uu[:, 3] < q
        throughput = throughput / q
    idx = np.flatnonzero(alive)
    wi = kernels.local_to_world(wi_l[idx], tb[idx], bb[idx], wf.n[idx])
    origins = kernels.offset_origins(wf.p[idx], wf.n[idx], wi)
    return ctx.trace(
        origins, wi, wf.pix[idx], wf.pass_id[idx], wf.length_m[idx], throughput[idx]
    )
