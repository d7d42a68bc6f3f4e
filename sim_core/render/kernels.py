"""Compiled per-ray kernels of the integrator (numba).

The integrator traces a frame as many independent *chunks* (a block of pixels, a few sample
passes), each on one worker thread from start to finish: camera rays (:func:`primary_rays`),
then per bounce one Embree query, one call of :func:`bounce`, one occlusion query and one call
of :func:`add_shadowed`, and finally :func:`accumulate_chunk` into the per-pixel sums. With our
Embree binding (:mod:`sim_core.embree_binding`) the whole bounce loop is one compiled call,
:func:`trace_paths`, which queries Embree itself in ray packets; with embreex (the fallback)
the integrator runs the same steps from Python. These
kernels are therefore serial and ``nogil``: two threads run them side by side with Embree,
without numba's thread pool (whose workers, parked or spinning, competed with Embree's callers:
measured ~30 % slower Embree queries), without a barrier after every stage, and on chunks small
enough to stay in cache. The one parallel kernel, :func:`camera_rays`, serves the per-render
ground truth only.

Being serial, :func:`bounce` writes the rays it spawns (shadow rays, continuing paths) packed,
in ray order, so no separate compaction pass is needed. History: the first numpy version spent
~1 us of numpy per path against ~0.1 us inside Embree; the parallel fused kernels that followed
still spent ~60 % of the wall time outside Embree, a third of it in ``math.sin``/``math.cos``
(now :func:`sincos_turns`), allocation and compaction.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit, prange

import sim_core.camera as _camera
import sim_core.embree_binding as _embree
import sim_core.materials.kernels as _material_kernels
import sim_core.numba_runtime  # noqa: F401  (camera_rays is a parallel kernel)
import sim_core.render.rng as _rng
from sim_core.materials.kernels import (
    KIND_COOK_TORRANCE,
    KIND_HAPKE,
    KIND_LAMBERTIAN,
    KIND_SEED_MICROFACET,
    KIND_TABULATED,
    N_PARAMS,
    duff_frame,
    eval_brdf_row,
    sample_brdf_row,
    sincos_turns,
)
from sim_core.render.rng import path_key, seed_key, uniform_pair


def _drop_stale_cache() -> None:
    """Delete this module's numba cache when a module it calls into has changed.

    numba keys a cached kernel on its own file only: after an edit of the material kernels,
    ``bounce`` would keep running the old, inlined BRDF code from ``__pycache__``. A stamp of
    the dependencies' sources next to the cache detects that.
    """
    cache = Path(__file__).with_name("__pycache__")
    digest = hashlib.sha256()
    for mod in (_material_kernels, _rng, _camera, _embree):
        digest.update(Path(mod.__file__).read_bytes())
    stamp = cache / "kernels.deps.sha256"
    want = digest.hexdigest()
    try:
        if stamp.read_text() == want:
            return
    except OSError:
        pass
    try:
        cache.mkdir(exist_ok=True)
        for f in cache.glob("kernels.*.nb[ic]"):
            f.unlink(missing_ok=True)
        stamp.write_text(want)
    except OSError:  # a read-only install: numba then compiles in memory anyway
        pass


_drop_stale_cache()

# Every division in these kernels is guarded where its divisor can be 0 (see the comments), so
# numba's per-division zero check (error_model="python") only costs time: "numpy" drops it.
_SERIAL = {"cache": True, "nogil": True, "error_model": "numpy"}

#: relative offset of secondary-ray origins (shadow rays, continuing paths) along the normal,
#: times the largest coordinate of the hit point in the render frame: Embree is float32 (~6e-8
#: relative), so origins closer than ~100 ulps re-hit the surface they start on
#: (self-intersection)
RAY_OFFSET_REL = 1e-5
#: absolute floor of that offset [m], for points near the render origin (the camera centre)
RAY_OFFSET_MIN_M = 1e-6


@njit(cache=True, inline="always", error_model="numpy")
def _offset_scale(px, py, pz):
    """Offset of a secondary ray's origin from the hit point (px, py, pz) along the normal."""
    m = max(abs(px), abs(py), abs(pz)) * RAY_OFFSET_REL
    return m if m > RAY_OFFSET_MIN_M else RAY_OFFSET_MIN_M


# Argument groups of the kernels. NamedTuples are numba tuples (typed per field, passed by
# value, fields read like attributes), so a group costs nothing inside a kernel; the integrator
# builds the per-render ones (Pinhole, SceneTables, CameraLight, AmbientSources, PixelSums)
# once per render.


class Pinhole(NamedTuple):
    """The camera model of :func:`camera_ray` (OpenCV pinhole with distortion)."""

    fx: float  #: focal length along u [px]
    fy: float  #: focal length along v [px]
    cx: float  #: principal point u [px]
    cy: float  #: principal point v [px]
    dist: np.ndarray  #: (5,) float64 distortion k1, k2, p1, p2, k3
    rotation: np.ndarray  #: (3, 3) float64 camera-to-world rotation (columns: camera axes)

    @classmethod
    def of(cls, intrinsics, rotation) -> Pinhole:
        """The model of :class:`sim_core.camera.Intrinsics` and a camera-to-world rotation."""
        return cls(
            float(intrinsics.fx_px), float(intrinsics.fy_px), float(intrinsics.cx_px),
            float(intrinsics.cy_px), np.asarray(intrinsics.distortion, dtype=np.float64),
            np.ascontiguousarray(rotation, dtype=np.float64),
        )


class Paths(NamedTuple):
    """The live paths of a chunk, one row each: the rays to trace next and what they carry.

    Ray arrays are float32 in the render frame (what Embree takes).
    """

    o: np.ndarray  #: (m, 3) float32 ray origins
    d: np.ndarray  #: (m, 3) float32 unit ray directions
    slot: np.ndarray  #: (m,) int64 the path's row in the chunk's :class:`SampleValues`
    key: np.ndarray  #: (m,) uint64 the path's random-number key (:mod:`sim_core.render.rng`)
    length: np.ndarray  #: (m,) float64 path length from the camera to the ray's origin [m]
    throughput: np.ndarray  #: (m,) float64 BRDF sampling weights so far, over roulette survival


class SceneTables(NamedTuple):
    """Per-triangle geometry and the material tables."""

    normals: np.ndarray  #: (T, 3) float64 unit normals
    tri_mat: np.ndarray  #: (T,) int64 material row of each triangle
    mat_kind: np.ndarray  #: (M,) int64 kernel ids (``sim_core.materials.kernels.KIND_*``)
    #: (M, L) float64 parameter vectors, L >= N_PARAMS (shorter ones padded with zeros)
    mat_params: np.ndarray
    #: ``mat_params`` again where a material has data beyond its header (a tabulated one), else
    #: None: ``bounce`` is then compiled without any code for such materials
    mat_data: np.ndarray | None


class CameraLight(NamedTuple):
    """The camera's own (modulated) point source."""

    position: np.ndarray  #: (3,) float64 in the render frame [m]
    axis: np.ndarray  #: (3,) float64 unit beam axis
    scale: float  #: radiant intensity on the axis [W/sr]
    profile_angle: np.ndarray  #: (k,) float64 increasing angles [rad]; empty: isotropic
    profile_rel: np.ndarray  #: (k,) float64 relative intensity at those angles
    min_distance_m: float  #: irradiance cap: a surface closer sees the light from this distance


class AmbientSources(NamedTuple):
    """The collimated, unmodulated sources, one row each (possibly none)."""

    direction: np.ndarray  #: (A, 3) float64 unit propagation directions
    irradiance: np.ndarray  #: (A,) float64 irradiance normal to the beam [W/m^2]
    centre: np.ndarray  #: (A, 3) float64 a point on the beam axis, world frame [m]
    u: np.ndarray  #: (A, 3) float64 unit vector of the beam cross-section along its width
    v: np.ndarray  #: (A, 3) float64 unit vector of the cross-section along its height
    size: np.ndarray  #: (A, 2) float64 width and height of the beam cross-section [m]
    has_footprint: np.ndarray  #: (A,) bool False: an unbounded beam (centre, u, v, size unused)


class ShadowRays(NamedTuple):
    """Candidate contributions of light sources, each behind one shadow ray."""

    o: np.ndarray  #: (k, 3) float32 origins
    d: np.ndarray  #: (k, 3) float32 unit directions towards the source
    t_max: np.ndarray  #: (k,) float32 distance to the source (inf for ambient sources)
    slot: np.ndarray  #: (k,) int64 row of the path in the chunk's :class:`SampleValues`
    contribution: np.ndarray  #: (k,) float64 radiance added if the ray is unblocked
    length: np.ndarray  #: (k,) float64 full path length, source to camera [m] (unused: ambient)
    is_ambient: np.ndarray  #: (k,) bool from an ambient source (adds to DC only)


class SampleValues(NamedTuple):
    """A chunk's per-sample results, one entry (column) per camera ray."""

    dc: np.ndarray  #: (m,) float64 radiance of the camera's source
    ambient: np.ndarray  #: (m,) float64 radiance of the ambient sources
    re: np.ndarray  #: (n_f, m) float64 real part of each frequency's phasor
    im: np.ndarray  #: (n_f, m) float64 imaginary part


class PixelSums(NamedTuple):
    """Per-pixel sample counts, sums and sums of squares (and of re x im) of the samples."""

    n: np.ndarray  #: (P,) int64
    s_dc: np.ndarray  #: (P,) float64
    ss_dc: np.ndarray  #: (P,) float64
    s_amb: np.ndarray  #: (P,) float64
    ss_amb: np.ndarray  #: (P,) float64
    s_re: np.ndarray  #: (n_f, P) float64
    s_im: np.ndarray  #: (n_f, P) float64
    ss_re: np.ndarray  #: (n_f, P) float64
    ss_im: np.ndarray  #: (n_f, P) float64
    s_reim: np.ndarray  #: (n_f, P) float64


@njit(cache=True, inline="always", error_model="numpy")
def camera_ray(u, v, cam):
    """World-frame unit direction through pixel coordinates (u, v) of the :class:`Pinhole`
    ``cam`` (OpenCV model).

    ``cam.dist`` holds k1, k2, p1, p2, k3; the distortion is inverted by 20 fixed-point steps
    of :func:`sim_core.camera.undistort_point` (as :func:`sim_core.camera.undistort_normalized`).
    """
    dist, rotation = cam.dist, cam.rotation
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    xd = (u - cam.cx) / cam.fx
    yd = (v - cam.cy) / cam.fy
    x, y = xd, yd
    if k1 != 0.0 or k2 != 0.0 or p1 != 0.0 or p2 != 0.0 or k3 != 0.0:
        x, y = _camera.undistort_point(xd, yd, k1, k2, p1, p2, k3, 20)
    inv = 1.0 / math.sqrt(x * x + y * y + 1.0)
    cx_, cy_, cz_ = x * inv, y * inv, inv
    return (
        rotation[0, 0] * cx_ + rotation[0, 1] * cy_ + rotation[0, 2] * cz_,
        rotation[1, 0] * cx_ + rotation[1, 1] * cy_ + rotation[1, 2] * cz_,
        rotation[2, 0] * cx_ + rotation[2, 1] * cy_ + rotation[2, 2] * cz_,
    )


@njit(cache=True, parallel=True, error_model="numpy")
def camera_rays(u_px, v_px, cam):
    """:func:`camera_ray` over arrays of pixel coordinates: (m, 3) float64 unit directions.

    Parallel (numba's thread pool): callers hold
    :data:`sim_core.numba_runtime.PARALLEL_KERNEL_LOCK`.
    """
    m = u_px.shape[0]
    out = np.empty((m, 3))
    for i in prange(m):
        out[i, 0], out[i, 1], out[i, 2] = camera_ray(u_px[i], v_px[i], cam)
    return out


#: the R2 sequence's steps (Roberts 2018): 1/g and 1/g^2 with g the plastic number, the real
#: root of x^3 = x + 1
R2_STEP_U = 0.7548776662466927
R2_STEP_V = 0.5698402909980532
#: the sample pass whose key seeds a pixel's jitter offset; real passes stay below 65536
_JITTER_PASS = 0xFFFFFFFF


@njit(cache=True, inline="always")
def pixel_jitter(seed_hash, pixel, sample):
    """Point ``sample`` of a pixel's jitter pattern in [0, 1)^2: the R2 low-discrepancy sequence
    shifted by a random offset per pixel (a Cranley-Patterson rotation).

    Each point is uniform on the pixel (the offset is), so the estimate stays unbiased; the
    points of one pixel are stratified, which makes the pixel's coverage of an edge converge
    like O(1/N) instead of O(1/sqrt(N)) (uniform random jitter): a silhouette's mixed pixels
    were the renderer's largest noise in grey on the rig's objects. Like the path keys, point k
    of a pixel depends only on (seed, pixel, k), whatever the batching.
    """
    ou, ov = uniform_pair(path_key(seed_hash, _JITTER_PASS, pixel), 0, 0)
    fu = ou + sample * R2_STEP_U
    fv = ov + sample * R2_STEP_V
    return fu - math.floor(fu), fv - math.floor(fv)


@njit(**_SERIAL)
def primary_rays(seed, pixels, first_sample, n_passes, u_px, v_px, footprint_px, cam):
    """Camera rays of the :class:`Pinhole` ``cam`` for ``n_passes`` more samples of each pixel
    in ``pixels`` (flat indices into the pixel-centre grids ``u_px``, ``v_px``).

    Ray ``r`` belongs to pixel ``pixels[r % n]`` and is that pixel's sample number
    ``first_sample[r % n] + r // n``: its path key hashes (seed, that sample number, pixel), so
    a pixel's k-th sample is the same whichever pixels are traced with it. It lands in the
    ``footprint_px`` square around the pixel centre (0: the centre itself) at
    :func:`pixel_jitter`'s point k: stratified over the pixel's samples, each one uniform.
    Returns float32 render-frame directions (m, 3) and the path keys.
    """
    n = pixels.shape[0]
    m = n_passes * n
    d = np.empty((m, 3), dtype=np.float32)
    keys = np.empty(m, dtype=np.uint64)
    sk = seed_key(seed)
    for p in range(n_passes):  # nested loops: r % n and r // n would cost two int divisions
        for j in range(n):
            r = p * n + j
            q = pixels[j]
            k = first_sample[j] + p
            key = path_key(sk, k, q)
            keys[r] = key
            u, v = u_px[q], v_px[q]
            if footprint_px > 0.0:
                ju, jv = pixel_jitter(sk, q, k)
                u += (ju - 0.5) * footprint_px
                v += (jv - 0.5) * footprint_px
            d[r, 0], d[r, 1], d[r, 2] = camera_ray(u, v, cam)
    return d, keys


@njit(cache=True, inline="always", error_model="numpy")
def _profile_intensity(cos_a, scale, prof_angle, prof_rel):
    """Radiant intensity [W/sr] at angle arccos(cos_a) from the source axis.

    ``prof_angle`` (increasing, rad) and ``prof_rel`` are the source's angular table,
    interpolated linearly like ``np.interp``; an empty table means isotropic. Zero at and beyond
    the last angle. Written out instead of calling ``np.interp``, whose inlined code kept the
    ray loop around it from being optimised even where the table is empty (measured ~30 ns
    per vertex).
    """
    n = prof_angle.shape[0]
    if n == 0:
        return scale
    # arccos needs its argument inside [-1, 1]; rounding can leave it 1 + 1e-16.
    a = math.acos(min(1.0, max(-1.0, cos_a)))
    if a >= prof_angle[n - 1]:
        return 0.0
    if a <= prof_angle[0]:
        return scale * prof_rel[0]
    k = 1
    while prof_angle[k] <= a:  # stops at k <= n - 1: a < prof_angle[n - 1]
        k += 1
    a0, a1 = prof_angle[k - 1], prof_angle[k]
    w = (a - a0) / (a1 - a0)  # a0 <= a < a1, so a1 - a0 > 0
    return scale * (prof_rel[k - 1] + w * (prof_rel[k] - prof_rel[k - 1]))


#: rays shaded together in one pass of :func:`bounce`: its per-lane temporaries (39 + 6
#: float64 rows of this many) stay in the L1 cache
LANES = 64

# The per-lane rows of :func:`bounce`, as offsets into its flat buffer ``g`` (row k holds lane j
# at ``k * LANES + j``: one array and offsets known to the compiler, so that LLVM can tell the
# rows apart and run the loops in lanes).
_R = LANES
_PX, _PY, _PZ = 0 * _R, 1 * _R, 2 * _R  # hit point [m]
_NX, _NY, _NZ = 3 * _R, 4 * _R, 5 * _R  # normal facing the ray
_T0, _T1, _T2, _B0, _B1, _B2 = (k * _R for k in range(6, 12))  # tangent, bitangent
_WO0, _WO1, _WO2 = 12 * _R, 13 * _R, 14 * _R  # direction to the ray's origin, local frame
_LX, _LY, _LZ = 15 * _R, 16 * _R, 17 * _R  # unit direction to the camera's source
_LT0, _LT1 = 18 * _R, 19 * _R  # the same in the local frame (its z is _COS_P)
_DIST, _INV_DIST, _COS_P = 20 * _R, 21 * _R, 22 * _R  # distance, 1 / clamped distance, cos
_OFFSET, _LENGTH, _THR = 23 * _R, 24 * _R, 25 * _R  # origin offset, path length [m], weight
_INTEN = 26 * _R  # radiant intensity of the source towards the hit [W/sr]
_FR = 27 * _R  # BRDF towards the source
_P0 = 28 * _R  # the material's parameter header (param_row): rows 28 .. 35
_DX, _DY, _DZ = 36 * _R, 37 * _R, 38 * _R  # the ray's direction
_N_ROWS = 39
# Rows of the sampled continuation (:func:`_scatter_lanes`), offsets into ``smp``.
_WX, _WY, _WZ, _SIDE, _WEIGHT, _U3 = (k * _R for k in range(6))
_N_SAMPLE_ROWS = 6


@njit(cache=True, inline="always", error_model="numpy")
def _gather_lanes(n, prim, throughput, normals, tri_mat, mat_params, g, live, mat):
    """The table lookups of lanes ``j < n``, one by one: ``live[j]`` (the ray met a surface
    and carries weight), its material row ``mat[j]``, the triangle's normal and
    the material's parameter header into rows of ``g``. Apart, because a loop that reads
    through an index it loaded is one LLVM cannot run in lanes ("cannot identify array
    bounds"): the passes after this one index by lane alone. A ray that met nothing reads
    triangle 0 (the caller has one)."""
    for j in range(n):
        f = prim[j]
        live[j] = (f >= 0) & (throughput[j] > 0.0)
        f = max(f, 0)
        g[_NX + j] = normals[f, 0]
        g[_NY + j] = normals[f, 1]
        g[_NZ + j] = normals[f, 2]
        row = tri_mat[f]
        mat[j] = row
        for k in range(N_PARAMS):
            g[_P0 + k * LANES + j] = mat_params[row, k]


@njit(cache=True, inline="always", error_model="numpy")
def _params(g, j):
    """Lane ``j``'s parameter header as the dispatchers' tuple (:func:`param_row`)."""
    return (g[_P0 + j], g[_P0 + 1 * LANES + j], g[_P0 + 2 * LANES + j],
            g[_P0 + 3 * LANES + j], g[_P0 + 4 * LANES + j], g[_P0 + 5 * LANES + j],
            g[_P0 + 6 * LANES + j], g[_P0 + 7 * LANES + j])


@njit(cache=True, inline="always", error_model="numpy")
def _vertex_lanes(n, o, d, tfar, throughput, length, light_pos, min_light_distance_m, g):
    """Per lane ``j < n``: everything about the vertex that does not depend on its material,
    into the rows of ``g`` (the normal, gathered by :func:`_gather_lanes`, is turned to face
    the ray).

    Branch-free loops indexed by lane, each of which LLVM runs in SIMD lanes (joined, they
    were not: "early exit loop"); the ray arrays are the block's views, ``o[a:a + n]``, as
    LLVM cannot bound the addresses of rows at an offset ("cannot identify array bounds").
    """
    for j in range(n):  # the hit point and the normal facing the ray
        t = np.float64(tfar[j])
        dx, dy, dz = np.float64(d[j, 0]), np.float64(d[j, 1]), np.float64(d[j, 2])
        nx, ny, nz = g[_NX + j], g[_NY + j], g[_NZ + j]
        flip = nx * dx + ny * dy + nz * dz > 0.0
        g[_NX + j] = -nx if flip else nx
        g[_NY + j] = -ny if flip else ny
        g[_NZ + j] = -nz if flip else nz
        g[_PX + j] = o[j, 0] + t * dx
        g[_PY + j] = o[j, 1] + t * dy
        g[_PZ + j] = o[j, 2] + t * dz
        g[_DX + j], g[_DY + j], g[_DZ + j] = dx, dy, dz
        g[_LENGTH + j] = length[j] + t
        g[_THR + j] = throughput[j]
    for j in range(n):  # the local frame
        t0, t1, t2, b0, b1, b2 = duff_frame(g[_NX + j], g[_NY + j], g[_NZ + j])
        g[_T0 + j], g[_T1 + j], g[_T2 + j] = t0, t1, t2
        g[_B0 + j], g[_B1 + j], g[_B2 + j] = b0, b1, b2
    for j in range(n):  # the way back, in the local frame
        dx, dy, dz = g[_DX + j], g[_DY + j], g[_DZ + j]
        nx, ny, nz = g[_NX + j], g[_NY + j], g[_NZ + j]
        t0, t1, t2 = g[_T0 + j], g[_T1 + j], g[_T2 + j]
        b0, b1, b2 = g[_B0 + j], g[_B1 + j], g[_B2 + j]
        g[_WO0 + j] = -(dx * t0 + dy * t1 + dz * t2)
        g[_WO1 + j] = -(dx * b0 + dy * b1 + dz * b2)
        g[_WO2 + j] = -(dx * nx + dy * ny + dz * nz)
    for j in range(n):  # the origin offset of the rays leaving the hit point
        g[_OFFSET + j] = _offset_scale(g[_PX + j], g[_PY + j], g[_PZ + j])
    for j in range(n):  # the camera's source: E = I(theta) cos / d^2 (seed eq. 20), L = E f
        nx, ny, nz = g[_NX + j], g[_NY + j], g[_NZ + j]
        lx = light_pos[0] - g[_PX + j]
        ly = light_pos[1] - g[_PY + j]
        lz = light_pos[2] - g[_PZ + j]
        dist = math.sqrt(lx * lx + ly * ly + lz * lz)
        # The direction to the light is normalised by the true distance: the BRDF contract
        # asks for unit vectors (a point exactly at the light has no direction: cos_p = 0).
        inv_true = 1.0 / dist if dist > 0.0 else 0.0
        lx, ly, lz = lx * inv_true, ly * inv_true, lz * inv_true
        # A surface through the light itself would see I / 0^2: the irradiance is capped at
        # I / d_min^2 (the clamp enters 1/d^2 only).
        g[_INV_DIST + j] = 1.0 / (dist if dist > min_light_distance_m else min_light_distance_m)
        g[_LX + j], g[_LY + j], g[_LZ + j] = lx, ly, lz
        g[_LT0 + j] = lx * g[_T0 + j] + ly * g[_T1 + j] + lz * g[_T2 + j]
        g[_LT1 + j] = lx * g[_B0 + j] + ly * g[_B1 + j] + lz * g[_B2 + j]
        g[_COS_P + j] = lx * nx + ly * ny + lz * nz
        g[_DIST + j] = dist


@njit(cache=True, inline="always", error_model="numpy")
def _brdf_to_source(kind, j, g, mat, mat_data):
    """BRDF of lane ``j``'s vertex towards the camera's source."""
    return eval_brdf_row(kind, _params(g, j), mat_data, mat[j], g[_LT0 + j], g[_LT1 + j],
                         g[_COS_P + j], g[_WO0 + j], g[_WO1 + j], g[_WO2 + j])


@njit(cache=True, inline="always", error_model="numpy")
def _brdf_to(kind, j, g, mat, mat_data, ax, ay, az, cos_a):
    """BRDF of lane ``j``'s vertex towards the unit direction (ax, ay, az), ``cos_a`` its
    cosine to the normal."""
    return eval_brdf_row(kind, _params(g, j), mat_data, mat[j],
                         ax * g[_T0 + j] + ay * g[_T1 + j] + az * g[_T2 + j],
                         ax * g[_B0 + j] + ay * g[_B1 + j] + az * g[_B2 + j],
                         cos_a, g[_WO0 + j], g[_WO1 + j], g[_WO2 + j])


@njit(cache=True, inline="always", error_model="numpy")
def _brdf_lanes(kind, n, g, mat, mat_data, amb_dir, f_amb):
    """The BRDF of material kind ``kind`` (every lane's) towards the camera's source (row
    ``_FR`` of ``g``) and towards each ambient source ``a`` (``f_amb[a * LANES + j]``), in
    every lane, needed or not: the analytic models are total functions of unit directions, and
    their branches become selects. Called with ``kind`` a constant, so each model gets loops of
    its own with no branch on the kind, which LLVM runs in SIMD lanes where the model has no
    calls (Lambertian and Hapke, 8 wide with AVX-512: LLVM's loop-vectorize remarks)."""
    for j in range(n):
        g[_FR + j] = _brdf_to_source(kind, j, g, mat, mat_data)
    for a in range(amb_dir.shape[0]):
        ax, ay, az = -amb_dir[a, 0], -amb_dir[a, 1], -amb_dir[a, 2]
        for j in range(n):
            cos_a = ax * g[_NX + j] + ay * g[_NY + j] + az * g[_NZ + j]
            f_amb[a * LANES + j] = _brdf_to(kind, j, g, mat, mat_data, ax, ay, az, cos_a)


@njit(cache=True, inline="always", error_model="numpy")
def _brdf_guarded(n, g, live, mat, mat_kind, mat_data, amb_dir, f_amb):
    """:func:`_brdf_lanes` for a block of mixed kinds or with a tabulated material: lane by
    lane, the kind looked up per lane, a BRDF evaluated only where it is used (a live vertex,
    the source above its horizon), as a table lookup needs."""
    for j in range(n):
        if not live[j]:
            continue
        k = mat_kind[mat[j]]
        if g[_COS_P + j] > 0.0:
            g[_FR + j] = _brdf_to_source(k, j, g, mat, mat_data)
        for a in range(amb_dir.shape[0]):
            ax, ay, az = -amb_dir[a, 0], -amb_dir[a, 1], -amb_dir[a, 2]
            cos_a = ax * g[_NX + j] + ay * g[_NY + j] + az * g[_NZ + j]
            if cos_a > 0.0:
                f_amb[a * LANES + j] = _brdf_to(k, j, g, mat, mat_data, ax, ay, az, cos_a)


@njit(cache=True, inline="always", error_model="numpy")
def _scatter_lane(kind, j, g, mat, mat_data, keys, bounce_index, smp):
    """BRDF importance sampling of lane ``j``'s next direction (uniform dimensions 0-2 of
    bounce ``bounce_index``, dimension 3 kept for the roulette): world direction, side of the
    surface and weight into the rows of ``smp``."""
    key = keys[j]
    u0, u1 = uniform_pair(key, bounce_index, 0)
    u2, u3 = uniform_pair(key, bounce_index, 1)
    x, y, z, _pdf, w = sample_brdf_row(kind, _params(g, j), mat_data, mat[j], g[_WO0 + j],
                                       g[_WO1 + j], g[_WO2 + j], u0, u1, u2)
    wx = x * g[_T0 + j] + y * g[_B0 + j] + z * g[_NX + j]
    wy = x * g[_T1 + j] + y * g[_B1 + j] + z * g[_NY + j]
    wz = x * g[_T2 + j] + y * g[_B2 + j] + z * g[_NZ + j]
    inv = 1.0 / math.sqrt(wx * wx + wy * wy + wz * wz)  # orthonormal frame: ~1
    smp[_WX + j], smp[_WY + j], smp[_WZ + j] = wx * inv, wy * inv, wz * inv
    smp[_SIDE + j] = 1.0 if z >= 0.0 else -1.0
    smp[_WEIGHT + j] = w
    smp[_U3 + j] = u3


@njit(cache=True, inline="always", error_model="numpy")
def _scatter_lanes(kind, n, g, mat, mat_data, keys, bounce_index, smp):
    """:func:`_scatter_lane` in every lane, ``kind`` a constant as in :func:`_brdf_lanes` (the
    sampling has branches LLVM does not turn into selects, but the model's code is the only
    code in the loop)."""
    for j in range(n):
        _scatter_lane(kind, j, g, mat, mat_data, keys, bounce_index, smp)


@njit(cache=True, inline="always", error_model="numpy")
def _scatter_guarded(n, g, live, mat, mat_kind, mat_data, keys, bounce_index, smp):
    """:func:`_scatter_lane` in every live lane, with the lane's own kind."""
    for j in range(n):
        if live[j]:
            _scatter_lane(mat_kind[mat[j]], j, g, mat, mat_data, keys, bounce_index, smp)


@njit(cache=True, inline="always", error_model="numpy")
def _shade_lanes(kind, n, g, mat, mat_data, amb_dir, f_amb, scatter, keys, bounce_index, smp):
    """:func:`_brdf_lanes`, then (if ``scatter``) :func:`_scatter_lanes`, for a block of the
    one material kind ``kind`` (a constant at each call)."""
    _brdf_lanes(kind, n, g, mat, mat_data, amb_dir, f_amb)
    if scatter:
        _scatter_lanes(kind, n, g, mat, mat_data, keys, bounce_index, smp)


@njit(cache=True, inline="always", error_model="numpy")
def _block_kind(n, live, mat, mat_kind):
    """The material kind shared by every live lane, -1 if the block mixes kinds or meets a
    tabulated material (whose table lookups are evaluated only where needed), -2 if no lane
    is live."""
    kind = -2
    for j in range(n):
        if live[j]:
            k = mat_kind[mat[j]]
            if kind == -2:
                kind = k
            elif k != kind:
                return -1
    return -1 if kind == KIND_TABULATED else kind


@njit(**_SERIAL)
def bounce(paths, tfar, prim, tables, light, ambient, render_origin, bounce_index, rr_from_bounce,
           scatter):
    """All the work at one path vertex except ray casting (seed eqs. 19-22).

    ``paths`` (:class:`Paths`) were traced by Embree: ``tfar`` (float32) and ``prim`` (-1: no
    hit) are its answer per ray. For every ray ``i`` that met a surface: the hit point and a
    normal facing the ray; the candidate contribution of the camera's source ``light``
    (:class:`CameraLight`, seed eqs. 20-21, none where the light is behind the surface) with
    its shadow ray and the full path length; the same for every source of ``ambient``
    (:class:`AmbientSources`; DC only, inside its beam footprint, which is given in world
    coordinates: ``render_origin`` is the render frame's origin in them); and, if ``scatter``,
    the next ray by BRDF importance sampling with Russian roulette from bounce
    ``rr_from_bounce`` on (uniform dimensions 0-2 and 3 of bounce ``bounce_index``). Sampling
    does not depend on visibility, so both happen in one pass. ``tables`` is a
    :class:`SceneTables`.

    Shading in lanes (issue 30): the rays are taken :data:`LANES` at a time, and each block
    runs in passes over its lanes. The table lookups first (:func:`_gather_lanes`), then
    loops indexed by lane, which LLVM vectorises where the model allows: the vertex geometry
    (:func:`_vertex_lanes`) and the BRDF of the block's one material kind towards every source
    (:func:`_brdf_lanes`: in SIMD lanes for Lambertian and Hapke materials; the microfacet
    models call ``exp`` and ``pow``, which have no vector form here; a block that mixes kinds
    or meets a tabulated material evaluates lane by lane instead, where needed only);
    then BRDF sampling (:func:`_scatter_lanes`, per kind too) and the source's angular
    profile (table lookups, where needed); and
    one serial pass writes the shadow rays and the continuing paths, packed. Every value is the
    same operation on the same operands as in the ray-by-ray loop this replaced, so frames are
    bit-identical to it (measured: ``bounce`` alone 0.8x its time per ray on the corner, 0.87x
    on the satellite ground test; docs/performance.md).

    Returns the :class:`ShadowRays` and the continuing :class:`Paths`, each packed in ray
    order. Ray arrays are float32 in the render frame; the arithmetic is float64.
    """
    o, d, slot, keys, length, throughput = (
        paths.o, paths.d, paths.slot, paths.key, paths.length, paths.throughput
    )
    normals, tri_mat = tables.normals, tables.tri_mat
    mat_kind, mat_params, mat_data = tables.mat_kind, tables.mat_params, tables.mat_data
    light_pos, light_axis, light_scale = light.position, light.axis, light.scale
    prof_angle, prof_rel = light.profile_angle, light.profile_rel
    amb_dir, amb_irr, amb_centre = ambient.direction, ambient.irradiance, ambient.centre
    amb_u, amb_v, amb_size = ambient.u, ambient.v, ambient.size
    amb_footprint = ambient.has_footprint
    m = prim.shape[0] if normals.shape[0] > 0 else 0  # no triangle: nothing was hit
    n_amb = amb_dir.shape[0]
    cap = m * (1 + n_amb)
    sh_o = np.empty((cap, 3), dtype=np.float32)
    sh_d = np.empty((cap, 3), dtype=np.float32)
    sh_t = np.empty(cap, dtype=np.float32)
    sh_slot = np.empty(cap, dtype=np.int64)
    sh_c = np.empty(cap)
    sh_len = np.empty(cap)
    sh_amb = np.empty(cap, dtype=np.bool_)
    ns = 0
    nx_o = np.empty((m if scatter else 0, 3), dtype=np.float32)
    nx_d = np.empty((m if scatter else 0, 3), dtype=np.float32)
    nx_slot = np.empty(m if scatter else 0, dtype=np.int64)
    nx_key = np.empty(m if scatter else 0, dtype=np.uint64)
    nx_len = np.empty(m if scatter else 0)
    nx_thr = np.empty(m if scatter else 0)
    nn = 0
    g = np.zeros(_N_ROWS * LANES)
    smp = np.zeros(_N_SAMPLE_ROWS * LANES)
    f_amb = np.zeros(n_amb * LANES)
    live = np.zeros(LANES, dtype=np.bool_)
    mat = np.zeros(LANES, dtype=np.int64)
    isotropic = prof_angle.shape[0] == 0
    for a in range(0, m, LANES):
        n = min(LANES, m - a)
        end = a + n  # the block's views: the lane passes index them by lane alone
        _gather_lanes(n, prim[a:end], throughput[a:end], normals, tri_mat, mat_params, g, live,
                      mat)
        _vertex_lanes(n, o[a:end], d[a:end], tfar[a:end], throughput[a:end], length[a:end],
                      light_pos, light.min_distance_m, g)
        kind = _block_kind(n, live, mat, mat_kind)
        if kind == -2:
            continue
        # Loops of their own per kind, each compiled for its model alone.
        kb = keys[a:end]
        if kind == KIND_LAMBERTIAN:
            _shade_lanes(KIND_LAMBERTIAN, n, g, mat, mat_data, amb_dir, f_amb, scatter, kb,
                         bounce_index, smp)
        elif kind == KIND_SEED_MICROFACET:
            _shade_lanes(KIND_SEED_MICROFACET, n, g, mat, mat_data, amb_dir, f_amb, scatter,
                         kb, bounce_index, smp)
        elif kind == KIND_COOK_TORRANCE:
            _shade_lanes(KIND_COOK_TORRANCE, n, g, mat, mat_data, amb_dir, f_amb, scatter, kb,
                         bounce_index, smp)
        elif kind == KIND_HAPKE:
            _shade_lanes(KIND_HAPKE, n, g, mat, mat_data, amb_dir, f_amb, scatter, kb,
                         bounce_index, smp)
        else:
            _brdf_guarded(n, g, live, mat, mat_kind, mat_data, amb_dir, f_amb)
            if scatter:
                _scatter_guarded(n, g, live, mat, mat_kind, mat_data, kb, bounce_index, smp)
        if isotropic:
            for j in range(n):
                g[_INTEN + j] = light_scale
        else:  # a table lookup: where the source is above the horizon only
            for j in range(n):
                if live[j] and g[_COS_P + j] > 0.0:
                    g[_INTEN + j] = _profile_intensity(
                        -(g[_LX + j] * light_axis[0] + g[_LY + j] * light_axis[1]
                          + g[_LZ + j] * light_axis[2]),
                        light_scale, prof_angle, prof_rel,
                    )

        # The serial pass: what each live vertex adds, packed in ray order.
        for j in range(n):
            if not live[j]:
                continue
            i = a + j
            thr = g[_THR + j]
            px, py, pz = g[_PX + j], g[_PY + j], g[_PZ + j]
            nx, ny, nz = g[_NX + j], g[_NY + j], g[_NZ + j]
            s = g[_OFFSET + j]
            ln = g[_LENGTH + j]
            ox, oy, oz = px + s * nx, py + s * ny, pz + s * nz  # shadow-ray origin, lit side
            cos_p = g[_COS_P + j]
            if cos_p > 0.0:
                inv_dist = g[_INV_DIST + j]
                c = thr * g[_FR + j] * g[_INTEN + j] * cos_p * inv_dist * inv_dist
                if c > 0.0:
                    sh_o[ns, 0], sh_o[ns, 1], sh_o[ns, 2] = ox, oy, oz
                    sh_d[ns, 0], sh_d[ns, 1], sh_d[ns, 2] = g[_LX + j], g[_LY + j], g[_LZ + j]
                    ex, ey, ez = light_pos[0] - ox, light_pos[1] - oy, light_pos[2] - oz
                    sh_t[ns] = math.sqrt(ex * ex + ey * ey + ez * ez) * (1.0 - 1e-6)
                    sh_slot[ns] = slot[i]
                    sh_c[ns] = c
                    sh_len[ns] = ln + g[_DIST + j]
                    sh_amb[ns] = False
                    ns += 1

            # Ambient sources: collimated, E cos, DC only.
            for b in range(n_amb):
                ax, ay, az = -amb_dir[b, 0], -amb_dir[b, 1], -amb_dir[b, 2]
                cos_a = ax * nx + ay * ny + az * nz
                if cos_a <= 0.0:
                    continue
                if amb_footprint[b]:
                    rx = px + render_origin[0] - amb_centre[b, 0]
                    ry = py + render_origin[1] - amb_centre[b, 1]
                    rz = pz + render_origin[2] - amb_centre[b, 2]
                    cu = abs(rx * amb_u[b, 0] + ry * amb_u[b, 1] + rz * amb_u[b, 2])
                    cv = abs(rx * amb_v[b, 0] + ry * amb_v[b, 1] + rz * amb_v[b, 2])
                    if cu > 0.5 * amb_size[b, 0] or cv > 0.5 * amb_size[b, 1]:
                        continue
                c = thr * f_amb[b * LANES + j] * amb_irr[b] * cos_a
                if c > 0.0:
                    sh_o[ns, 0], sh_o[ns, 1], sh_o[ns, 2] = ox, oy, oz
                    sh_d[ns, 0], sh_d[ns, 1], sh_d[ns, 2] = ax, ay, az
                    sh_t[ns] = np.float32(np.inf)
                    sh_slot[ns] = slot[i]
                    sh_c[ns] = c
                    sh_len[ns] = 0.0
                    sh_amb[ns] = True
                    ns += 1

            if not scatter:
                continue
            tn = thr * smp[_WEIGHT + j]
            if not tn > 0.0:
                continue
            if bounce_index + 1 >= rr_from_bounce:
                # Survival probability follows the throughput; dividing by it keeps the
                # estimate unbiased. The floor keeps 1/q bounded.
                q = min(1.0, max(0.05, tn))
                if smp[_U3 + j] >= q:
                    continue
                tn = tn / q
            sz = s * smp[_SIDE + j]
            nx_o[nn, 0], nx_o[nn, 1], nx_o[nn, 2] = px + sz * nx, py + sz * ny, pz + sz * nz
            nx_d[nn, 0], nx_d[nn, 1], nx_d[nn, 2] = smp[_WX + j], smp[_WY + j], smp[_WZ + j]
            nx_slot[nn] = slot[i]
            nx_key[nn] = keys[i]
            nx_len[nn] = ln
            nx_thr[nn] = tn
            nn += 1
    return (
        ShadowRays(sh_o[:ns], sh_d[:ns], sh_t[:ns], sh_slot[:ns], sh_c[:ns], sh_len[:ns],
                   sh_amb[:ns]),
        Paths(nx_o[:nn], nx_d[:nn], nx_slot[:nn], nx_key[:nn], nx_len[:nn], nx_thr[:nn]),
    )


@njit(**_SERIAL)
def add_shadowed(occluded, shadow, turns_per_m, out):
    """Add the contributions whose shadow ray is unblocked to their path's sums (eqs. 17, 31).

    ``occluded`` is Embree's answer per ray of ``shadow`` (:class:`ShadowRays`; 0 = blocked,
    -1 = free); ``out`` is the chunk's :class:`SampleValues`. The camera source adds ``c`` to
    DC and ``c exp(-i 2π f L / c0)`` to each frequency's phasor (``turns_per_m`` = f / c0);
    ambient sources add to their DC sum only.
    """
    sh_slot, sh_c = shadow.slot, shadow.contribution
    sh_len, sh_amb = shadow.length, shadow.is_ambient
    out_dc, out_amb, out_re, out_im = out.dc, out.ambient, out.re, out.im
    nf = turns_per_m.shape[0]
    k_rays = sh_slot.shape[0]
    # The phases first, in a loop of their own over every ray (blocked or not): one input and
    # two outputs, which LLVM runs in SIMD lanes; then the additions, ray by ray.
    sin_p = np.empty((nf, k_rays))
    cos_p = np.empty((nf, k_rays))
    for k in range(nf):
        tpm = turns_per_m[k]
        s_k, c_k = sin_p[k], cos_p[k]
        for j in range(k_rays):
            s_k[j], c_k[j] = sincos_turns(tpm * sh_len[j])
    for j in range(k_rays):
        if occluded[j] == 0:
            continue
        q = sh_slot[j]
        c = sh_c[j]
        if sh_amb[j]:
            out_amb[q] += c
            continue
        out_dc[q] += c
        for k in range(nf):
            out_re[k, q] += c * cos_p[k, j]
            out_im[k, q] -= c * sin_p[k, j]


@njit(**_SERIAL)
def accumulate_chunk(pixels, samples, sums):
    """Add a chunk's :class:`SampleValues` to the :class:`PixelSums` ``sums``.

    Sample ``r`` belongs to pixel ``pixels[r % len(pixels)]`` (the chunk holds whole passes).
    Samples are added one at a time in ``r`` order, which is the order of the pixel's sample
    numbers, so every sum is the same however the samples were grouped into chunks and threads.
    """
    out_dc, out_amb, out_re, out_im = samples.dc, samples.ambient, samples.re, samples.im
    n, s_dc, ss_dc, s_amb, ss_amb = sums.n, sums.s_dc, sums.ss_dc, sums.s_amb, sums.ss_amb
    s_re, s_im, ss_re, ss_im, s_reim = sums.s_re, sums.s_im, sums.ss_re, sums.ss_im, sums.s_reim
    npx = pixels.shape[0]
    nf = out_re.shape[0]
    for p in range(out_dc.shape[0] // npx):  # nested loops: no integer division per sample
        for j in range(npx):
            r = p * npx + j
            q = pixels[j]
            n[q] += 1
            a = out_dc[r]
            s_dc[q] += a
            ss_dc[q] += a * a
            b = out_amb[r]
            s_amb[q] += b
            ss_amb[q] += b * b
            for k in range(nf):
                re, im = out_re[k, r], out_im[k, r]
                s_re[k, q] += re
                s_im[k, q] += im
                ss_re[k, q] += re * re
                ss_im[k, q] += im * im
                s_reim[k, q] += re * im


@njit(**_SERIAL)
def trace_paths(scene, widths, coherent, buf, paths, n_bounces, tables, light, ambient,
                render_origin, rr_from_bounce, turns_per_m, out, counters):
    """A chunk's whole bounce loop in one call: the steps the integrator runs from Python on the
    embreex backend, here with Embree queried through :mod:`sim_core.embree_binding`.

    Per bounce ``b`` = 1 .. ``n_bounces``: closest hits of ``paths`` (packets of ``widths[0]``
    rays for the camera rays of bounce 1, ``widths[1]`` for bounce rays), :func:`bounce`,
    occlusion of its shadow rays (packets of ``widths[2]``), :func:`add_shadowed` into ``out``.
    ``coherent`` (bool (3,)) holds Embree's coherence hint for the same three kinds.
    ``scene`` is the binding's scene handle, ``buf`` a
    :func:`sim_core.embree_binding.packet_buffer`. The answers are the embreex backend's, bit
    for bit, so the result is too.

    ``counters`` (float64 (4,)) accumulates: rays traced, seconds in Embree, seconds in
    :func:`bounce`, seconds in :func:`add_shadowed` (the integrator's stage clocks).
    """
    for b in range(1, n_bounces + 1):
        m = paths.o.shape[0]
        tfar = np.empty(m, dtype=np.float32)
        prim = np.empty(m, dtype=np.int32)
        # camera rays leave one centre (coherent); bounce rays scatter (incoherent)
        _embree.intersect(scene, paths.o, paths.d, widths[0] if b == 1 else widths[1], buf,
                          tfar, prim, counters, coherent[0] if b == 1 else coherent[1])
        t0 = _embree.now_s()
        shadow, paths = bounce(paths, tfar, prim, tables, light, ambient, render_origin, b,
                               rr_from_bounce, b < n_bounces)
        counters[2] += _embree.now_s() - t0
        occluded = np.empty(shadow.o.shape[0], dtype=np.int32)
        _embree.occluded(scene, shadow.o, shadow.d, shadow.t_max, widths[2], buf, occluded,
                         counters, coherent[2])
        t0 = _embree.now_s()
        add_shadowed(occluded, shadow, turns_per_m, out)
        counters[3] += _embree.now_s() - t0
        if paths.o.shape[0] == 0:
            break
