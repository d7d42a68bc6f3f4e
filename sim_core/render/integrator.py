"""Path tracing for an AMCW ToF camera (seed section 2.3.1, eqs. 17-31).

Rays are traced in batches (chunks of pixels and sample passes, see "Work split"), every bounce
of a batch in one Embree query. Each path carries its total length L from the light source
through all bounces to the pixel; a path's contribution ``w`` (radiance, W m^-2 sr^-1) adds to
the DC image and ``w * exp(-1j * 2*pi*f*L / c)`` to each modulation frequency's phasor (eqs.
17, 31). Ambient light adds to DC only.

Integrators
-----------
- ``direct``: camera -> surface -> light, one vertex (the peer paper's direct model, eqs. 1-2).
- ``path``: up to ``max_bounces`` surface interactions. At every vertex, next-event estimation
  towards the point source (eqs. 20-21) and each ambient source (shadow rays), then BRDF
  importance sampling of the next direction (eq. 22 with the pdf of the material), Russian
  roulette from ``russian_roulette_from_bounce`` on. The point and collimated sources are
  delta lights: BRDF-sampled rays can never hit them, so next-event estimation alone is
  unbiased and no multiple importance sampling is needed.

Rays are traced in the render frame, world coordinates relative to the camera centre, where
Embree's float32 loses least. Secondary rays (shadow rays and continuing paths) start a little
off the surface they leave, on the side they go to, to keep Embree from finding that surface
again: :data:`sim_core.render.kernels.RAY_OFFSET_REL` times the hit point's largest coordinate,
at least :data:`sim_core.render.kernels.RAY_OFFSET_MIN_M`.

Work split
----------
A request for ``n`` samples of some pixels becomes tasks, one block of pixels each (about
``TASKS_PER_THREAD`` per worker thread). A task traces its block in chunks of a few sample
passes, about ``CHUNK_RAYS`` camera rays, one after the other on one thread: each chunk from
start to finish (camera rays, then per bounce: Embree, the fused kernel, the shadow rays), then
its samples into the per-pixel sums. A block of pixels belongs to one task, so no two threads
write the same pixel. Each chunk is wavefront-style inside (one Embree query per bounce for all
its rays) and small enough to stay in cache; there is no barrier between stages. With our
Embree binding (the tracer's default backend) a chunk's whole bounce loop is one compiled call
(:func:`sim_core.render.kernels.trace_paths`, Embree queried in ray packets); with embreex (the
fallback) the same steps run from Python (:func:`_bounces_from_python`).

Determinism
-----------
Every random number is a hash of (seed, pixel, sample number, bounce, dimension)
(:mod:`sim_core.render.rng`), Embree's answers do not depend on threading, and each pixel's
sums add its samples one by one in sample order. So the same seed gives bit-identical images
whatever the number of threads and however the samples were split into chunks or requests.
"""

from __future__ import annotations

import operator
import threading
import time
from collections.abc import Callable
from concurrent.futures import as_completed, wait
from dataclasses import dataclass, field

import numpy as np

from sim_core import embree_binding
from sim_core.camera import pixel_centre_grid
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.materials.kernels import N_PARAMS
from sim_core.numba_runtime import PARALLEL_KERNEL_LOCK
from sim_core.render import kernels
from sim_core.render.kernels import (
    AmbientSources,
    CameraLight,
    Paths,
    Pinhole,
    PixelSums,
    SampleValues,
    SceneTables,
    camera_rays,
)
from sim_core.render.lightfield import LightField
from sim_core.scene import Scene
from sim_core.scene_spec import RUSSIAN_ROULETTE_FROM_BOUNCE
from sim_core.tracing import RayTracer

#: camera rays per chunk: large enough that Embree's per-call overhead (~2 us) and the Python
#: glue vanish, small enough that a chunk's ray state stays in a core's cache
CHUNK_RAYS = 8192
#: tasks per worker thread a request is split into, so threads finish within ~1/16 of each other
TASKS_PER_THREAD = 16
#: fewest camera rays a chunk should get when the request allows (a small request of few samples
#: would otherwise be cut into chunks of a few hundred rays, each paying the per-call costs)
MIN_CHUNK_RAYS = 2048
#: what the worker threads' time is charged to (:attr:`RenderResult.stage_thread_seconds`)
STAGES = ("camera_rays", "embree", "shading", "accumulation")
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
        First bounce index at which paths may be terminated at random (default
        :data:`sim_core.scene_spec.RUSSIAN_ROULETTE_FROM_BOUNCE`: none within 3 bounces).
    threads : int or None
        Worker threads of the render (default: all cores); each traces whole chunks, Embree
        queries and kernels alike. Never changes the result.
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
    russian_roulette_from_bounce: int = RUSSIAN_ROULETTE_FROM_BOUNCE
    threads: int | None = None
    ambient: bool = True
    jitter: bool = True
    footprint_px: float = 1.0

    @property
    def effective_bounces(self) -> int:
        return 1 if self.integrator == "direct" else self.max_bounces


@dataclass
class RenderResult:
    """A light field and what it cost.

    ``embree_thread_seconds`` is the time inside Embree queries summed over the ``threads``
    worker threads, so :attr:`embree_share` is the share of the machine's capacity (wall time
    x threads) that went to ray casting. ``stage_thread_seconds`` splits the worker threads'
    path-tracing time by :data:`STAGES` (compiled kernels and Embree); what the capacity holds
    beyond them is Python glue and waiting.
    """

    light_field: LightField
    seconds: float
    embree_thread_seconds: float
    rays_traced: int
    timings_s: dict[str, float] = field(default_factory=dict)
    threads: int = 1
    stage_thread_seconds: dict[str, float] = field(default_factory=dict)

    @property
    def embree_share(self) -> float:
        """Fraction of the threads' wall time spent inside Embree queries."""
        capacity = self.seconds * max(self.threads, 1)
        return self.embree_thread_seconds / capacity if capacity > 0 else 0.0


class _Accumulator:
    """Running per-pixel sums and sums of squares of per-sample values, with per-pixel counts."""

    def __init__(self, npix: int, n_f: int) -> None:
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
        #: the same arrays, as the accumulation kernel takes them
        self.sums = PixelSums(self.n, self.s_active, self.ss_active, self.s_ambient,
                              self.ss_ambient, self.s_re, self.s_im, self.ss_re, self.ss_im,
                              self.s_reim)

    def add(self, pixels: np.ndarray, samples: SampleValues) -> None:
        """Add per-sample values; sample ``r`` belongs to pixel ``pixels[r % len(pixels)]``."""
        kernels.accumulate_chunk(pixels, samples, self.sums)

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
        self.stage_thread_s: dict[str, float] = dict.fromkeys(STAGES, 0.0)
        self._stage_lock = threading.Lock()
        self._request_lock = threading.Lock()
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
        """Take ``n`` more samples of each pixel in ``pixels``, on the tracer's worker threads
        (with one thread: on the calling thread, block by block).

        ``pixels`` are distinct flat integer indices in [0, H*W) (default: all pixels).
        Requests to one renderer run one at a time.
        """
        try:
            n = operator.index(n)
        except TypeError:
            raise ValueError(f"n: samples per pixel must be an integer, got {n!r}") from None
        pix = self._checked_pixels(pixels)
        if pix.size == 0 or n <= 0:
            return
        with self._request_lock:
            t0 = time.perf_counter()
            tasks = TASKS_PER_THREAD * self.tracer.threads
            block = max(-(-pix.size // tasks), -(-MIN_CHUNK_RAYS // n))
            block = int(min(block, CHUNK_RAYS, pix.size))
            passes = max(1, CHUNK_RAYS // block)
            starts = range(0, pix.size, block)
            args = (n, passes, self.acc, self.stage_thread_s, self._stage_lock)
            if self.tracer.threads == 1:  # in this thread, block by block
                for done, a in enumerate(starts, start=1):
                    _trace_block(self.ctx, pix[a:a + block], *args)
                    if progress is not None:
                        progress(n * done // len(starts), n)
            else:
                futures = [
                    self.tracer.submit(_trace_block, self.ctx, pix[a:a + block], *args)
                    for a in starts
                ]
                try:
                    for done, f in enumerate(as_completed(futures), start=1):
                        f.result()
                        if progress is not None:
                            progress(n * done // len(futures), n)
                finally:
                    for f in futures:  # after a failure: stop what has not started, wait
                        f.cancel()
                    wait(futures)
            self.timings_s["path_tracing"] += time.perf_counter() - t0

    def _checked_pixels(self, pixels: np.ndarray | None) -> np.ndarray:
        """``pixels`` as distinct int64 flat indices, or a ValueError naming what is wrong."""
        if pixels is None:
            return np.arange(self.npix, dtype=np.int64)
        arr = np.asarray(pixels)
        if arr.size and (arr.dtype == np.bool_ or not np.issubdtype(arr.dtype, np.integer)):
            raise ValueError(
                f"pixels: flat integer indices expected, got an array of {arr.dtype} "
                "(for a mask use np.flatnonzero)"
            )
        pix = arr.astype(np.int64).ravel()
        if pix.size and (pix.min() < 0 or pix.max() >= self.npix):
            raise ValueError(
                f"pixels: flat indices must lie in [0, {self.npix - 1}], "
                f"got [{pix.min()}, {pix.max()}]"
            )
        if np.unique(pix).size != pix.size:
            raise ValueError("pixels: every pixel may appear only once per request")
        return pix

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
            embree_thread_seconds=stats.seconds - self._stats0.seconds,
            rays_traced=stats.rays - self._stats0.rays,
            timings_s=dict(self.timings_s),
            threads=self.tracer.threads,
            stage_thread_seconds=dict(self.stage_thread_s),
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
        Called as ``progress(samples_done, samples_total)`` as blocks of pixels finish.
    """
    r = ProgressiveRenderer(scene, settings, tracer)
    try:
        r.add_samples(settings.spp, progress=progress)
        return r.result()
    finally:
        r.close()


def material_tables(materials) -> tuple[np.ndarray, np.ndarray]:
    """Kernel ids (M,) int64 and parameter vectors (M, L) float64 of the materials.

    ``L`` is the longest vector (at least ``N_PARAMS``: a tabulated material carries its whole
    table); shorter vectors are padded with zeros, which no kernel reads.
    """
    kinds = np.array([m.kernel_kind for m in materials], dtype=np.int64)
    vectors = [np.asarray(m.kernel_params(), dtype=np.float64).ravel() for m in materials]
    params = np.zeros((len(materials), max([N_PARAMS, *(v.size for v in vectors)])))
    for i, v in enumerate(vectors):
        params[i, : v.size] = v
    return kinds, params


class _Context:
    """Per-render constants shared by the stages, as the arrays and groups the kernels take."""

    def __init__(self, scene: Scene, settings: RenderSettings, tracer: RayTracer, origin) -> None:
        self.scene = scene
        self.settings = settings
        self.tracer = tracer
        #: (camera, bounce, shadow) packet widths of the tracer's binding backend
        self.widths = np.array(tracer.widths, dtype=np.int64)
        #: (camera, bounce, shadow) Embree coherence hints of the binding backend
        self.coherent = np.array(tracer.coherent, dtype=np.bool_)
        self.origin = np.asarray(origin, dtype=np.float64)
        self.freqs = np.asarray(scene.camera.modulation_frequencies_hz, dtype=np.float64)
        self.n_f = self.freqs.size
        #: phase per metre of path in turns, Psi / 2 pi of eq. 17 [1/m]
        self.turns_per_m = self.freqs / SPEED_OF_LIGHT_M_S
        self.u_px, self.v_px = pixel_centre_grid(scene.camera.intrinsics)
        self.npix = self.u_px.size
        self.shape = scene.camera.intrinsics.shape
        self.camera = Pinhole.of(scene.camera.intrinsics, scene.camera.rotation)
        self.footprint_px = settings.footprint_px if settings.jitter else 0.0
        mat_kind, mat_params = material_tables(scene.materials)
        self.tables = SceneTables(
            np.ascontiguousarray(scene.normals, dtype=np.float64),
            np.ascontiguousarray(scene.material_index, dtype=np.int64),
            mat_kind,
            mat_params,
            mat_params if mat_params.shape[1] > N_PARAMS else None,
        )
        light = scene.light
        if light.profile_angle_rad is None:
            prof_angle = np.zeros(0)
            prof_rel = np.zeros(0)
        else:
            # contiguous: a strided view would make numba compile ``bounce`` for 'A' layout
            prof_angle = np.ascontiguousarray(light.profile_angle_rad, dtype=np.float64)
            prof_rel = np.ascontiguousarray(light.profile_relative, dtype=np.float64)
        self.light = CameraLight(
            np.asarray(light.position_m - self.origin, dtype=np.float64),
            np.asarray(light.axis, dtype=np.float64),
            float(light.scale_w_sr),
            prof_angle,
            prof_rel,
            MIN_LIGHT_DISTANCE_M,
        )
        amb = scene.ambient if settings.ambient else ()
        n_a = len(amb)
        has_footprint = np.array(
            [a.footprint_centre_m is not None and a.footprint_size_m is not None for a in amb],
            dtype=np.bool_,
        )
        self.ambient = AmbientSources(
            direction=np.array([a.direction for a in amb], dtype=np.float64).reshape(n_a, 3),
            irradiance=np.array([a.irradiance_w_m2 for a in amb], dtype=np.float64),
            centre=np.array(
                [a.footprint_centre_m if f else np.zeros(3)
                 for a, f in zip(amb, has_footprint, strict=True)],
                dtype=np.float64,
            ).reshape(n_a, 3),
            u=np.array([a.footprint_u for a in amb], dtype=np.float64).reshape(n_a, 3),
            v=np.array([a.footprint_v for a in amb], dtype=np.float64).reshape(n_a, 3),
            size=np.array(
                [a.footprint_size_m if f else (0.0, 0.0)
                 for a, f in zip(amb, has_footprint, strict=True)],
                dtype=np.float64,
            ).reshape(n_a, 2),
            has_footprint=has_footprint,
        )


def _ground_truth(ctx: _Context) -> dict:
    """Range, depth, normal and object through every pixel centre (no jitter)."""
    h, w = ctx.shape
    d = camera_rays(ctx.u_px, ctx.v_px, ctx.camera)
    tfar, prim = ctx.tracer.intersect32(np.zeros_like(d, dtype=np.float32), d.astype(np.float32))
    hit = prim >= 0
    rng = np.where(hit, tfar.astype(np.float64), np.nan)
    normal = np.zeros((ctx.npix, 3))
    obj = np.full(ctx.npix, -1, dtype=np.int32)
    if hit.any():  # an empty scene has no normal table to index
        normal[hit] = ctx.tables.normals[prim[hit]]
        facing = np.einsum("ij,ij->i", normal, d) > 0.0
        normal[facing] *= -1.0
        obj[hit] = ctx.scene.object_index[prim[hit]]
    # z component of each unit direction in the camera frame: depth_z = range * z.
    z_cam = d @ ctx.camera.rotation[:, 2]
    return {
        "truth_range_m": rng.reshape(h, w),
        "truth_depth_z_m": (rng * z_cam).reshape(h, w),
        "truth_normal": normal.reshape(h, w, 3),
        "object_id": obj.reshape(h, w),
        "hit": hit.reshape(h, w),
    }


class _StageClock:
    """Thread-seconds per stage of one task, merged into the renderer's totals at its end."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = dict.fromkeys(STAGES, 0.0)
        self._t = time.perf_counter()

    def lap(self, stage: str) -> None:
        """Charge the time since the previous lap to ``stage``."""
        now = time.perf_counter()
        self.seconds[stage] += now - self._t
        self._t = now

    def split(self, seconds: dict[str, float]) -> None:
        """Charge the time since the previous lap as measured inside a compiled call: the
        given seconds to their stages, the remainder (the call's own overhead) to none."""
        for stage, s in seconds.items():
            self.seconds[stage] += float(s)
        self._t = time.perf_counter()

    def skip(self) -> None:
        """Charge the time since the previous lap to no stage (it counts as "other")."""
        self._t = time.perf_counter()


def _trace_block(
    ctx: _Context, pixels: np.ndarray, n: int, passes: int, acc: _Accumulator,
    totals: dict[str, float], lock: threading.Lock,
) -> None:
    """Trace ``n`` more samples of each pixel in ``pixels``, ``passes`` samples per chunk.

    Runs on a worker thread (with one thread: the caller's); no two tasks running at once share
    a pixel.
    """
    clock = _StageClock()
    first = acc.n[pixels]  # fancy indexing: a copy, unaffected by this task's own additions
    for p0 in range(0, n, passes):
        _trace_chunk(ctx, pixels, first + p0, min(passes, n - p0), acc, clock)
    with lock:
        for k, v in clock.seconds.items():
            totals[k] += v


def _trace_chunk(
    ctx: _Context, pixels: np.ndarray, first_sample: np.ndarray, g: int, acc: _Accumulator,
    clock: _StageClock,
) -> None:
    """Trace ``g`` samples of each pixel in ``pixels`` (sample numbers from ``first_sample``),
    wavefront-style, and add them to ``acc``."""
    st = ctx.settings
    tracer = ctx.tracer
    d, keys = kernels.primary_rays(
        st.seed, pixels, first_sample, g, ctx.u_px, ctx.v_px, ctx.footprint_px, ctx.camera
    )
    clock.lap("camera_rays")
    m = d.shape[0]
    out = SampleValues(np.zeros(m), np.zeros(m), np.zeros((ctx.n_f, m)), np.zeros((ctx.n_f, m)))
    paths = Paths(np.zeros_like(d), d, np.arange(m, dtype=np.int64), keys, np.zeros(m), np.ones(m))
    clock.skip()  # numpy buffers: "other"
    if tracer.kernel_scene is not None:
        _bounces_compiled(ctx, paths, out, clock)
    else:
        _bounces_from_python(ctx, paths, out, clock)
    acc.add(pixels, out)
    clock.lap("accumulation")


def _bounces_compiled(ctx: _Context, paths: Paths, out: SampleValues, clock: _StageClock) -> None:
    """The bounce loop of a chunk in one compiled call (:func:`kernels.trace_paths`), Embree
    queried in packets through our binding: no Python between bounces."""
    st, tracer = ctx.settings, ctx.tracer
    counters = np.zeros(4)
    kernels.trace_paths(
        tracer.kernel_scene, ctx.widths, ctx.coherent, embree_binding.packet_buffer(), paths,
        st.effective_bounces, ctx.tables, ctx.light, ctx.ambient, ctx.origin,
        st.russian_roulette_from_bounce, ctx.turns_per_m, out, counters,
    )
    tracer.count(int(counters[0]), float(counters[1]))
    clock.split({"embree": counters[1], "shading": counters[2], "accumulation": counters[3]})


def _bounces_from_python(
    ctx: _Context, paths: Paths, out: SampleValues, clock: _StageClock
) -> None:
    """The bounce loop of a chunk on the embreex backend: the steps of
    :func:`kernels.trace_paths`, with embreex's queries between the kernels."""
    st, tracer = ctx.settings, ctx.tracer
    n_bounces = st.effective_bounces
    for b in range(1, n_bounces + 1):
        tfar, prim = tracer.intersect_here(paths.o, paths.d)
        clock.lap("embree")
        shadow, paths = kernels.bounce(
            paths, tfar, prim, ctx.tables, ctx.light, ctx.ambient, ctx.origin,
            b, st.russian_roulette_from_bounce, b < n_bounces,
        )
        clock.lap("shading")
        occluded = tracer.occluded_here(shadow.o, shadow.d, shadow.t_max)
        clock.lap("embree")
        kernels.add_shadowed(occluded, shadow, ctx.turns_per_m, out)
        clock.lap("accumulation")
        if paths.o.shape[0] == 0:
            break
