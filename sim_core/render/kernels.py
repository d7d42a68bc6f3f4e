"""Compiled per-ray kernels of the wavefront integrator (numba).

Profiling the numpy version (line_profiler, corner scene, direct, 32 spp) showed about 1 us of
numpy work per path against ~0.1 us inside Embree: every step allocated and re-read (m, 3)
temporaries. These kernels fuse the work of a bounce into two passes over the rays (``shade``:
hit geometry, BRDF and next-event estimation; ``scatter``: BRDF sampling and Russian roulette)
and run them on all cores (``prange``); each ray's result depends only on that ray, so the
output is identical for any number of threads. Pixel accumulation is serial, in ray order, so
sums are bit-reproducible.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
from numba import njit, prange

import sim_core.materials.kernels as _material_kernels
import sim_core.render.rng as _rng
from sim_core.materials.kernels import duff_frame, eval_brdf, sample_brdf
from sim_core.render.rng import path_key, seed_key, uniform_pair


def _drop_stale_cache() -> None:
    """Delete this module's numba cache when a module it calls into has changed.

    numba keys a cached kernel on its own file only: after an edit of the material kernels,
    ``bounce`` would keep running the old, inlined BRDF code from ``__pycache__``. A stamp of
    the dependencies' sources next to the cache detects that.
    """
    cache = Path(__file__).with_name("__pycache__")
    digest = hashlib.sha256()
    for mod in (_material_kernels, _rng):
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
# The threading layer is set in sim_core.materials.kernels, imported above.

# Relative and absolute offset of secondary-ray origins; see integrator.RAY_OFFSET_REL.
_OFFSET_REL = 1e-5
_OFFSET_MIN_M = 1e-6


@njit(cache=True, inline="always", error_model="numpy")
def _offset_scale(px, py, pz):
    m = max(abs(px), abs(py), abs(pz)) * _OFFSET_REL
    return m if m > _OFFSET_MIN_M else _OFFSET_MIN_M


@njit(cache=True, parallel=True, error_model="numpy")
def accumulate_vertices(flat, act, act_len, blocked, psi_rad_m, out_dc, out_re, out_im):
    """Add the unblocked active-light contributions of one bounce (seed eqs. 17, 31).

    Within one bounce every path owns its own (pass, pixel) slot ``flat``, so the writes never
    collide and the loop runs in parallel with the same result as a serial one.
    """
    nf = psi_rad_m.shape[0]
    for j in prange(flat.shape[0]):
        c = act[j]
        if c > 0.0 and not blocked[j]:
            q = flat[j]
            out_dc[q] += c
            for k in range(nf):
                phase = psi_rad_m[k] * act_len[j]
                out_re[k, q] += c * math.cos(phase)
                out_im[k, q] -= c * math.sin(phase)


@njit(cache=True, parallel=True, error_model="numpy")
def accumulate_ambient(flat, amb, blocked, out):
    """Add the unblocked ambient contributions of one bounce; slots are unique per bounce."""
    for j in prange(flat.shape[0]):
        if amb[j] > 0.0 and not blocked[j]:
            out[flat[j]] += amb[j]


@njit(cache=True, parallel=True, error_model="numpy")
def camera_rays(u_px, v_px, fx, fy, cx, cy, dist, rotation):
    """World-frame unit directions through pixel coordinates (OpenCV model, pinhole).

    ``dist`` holds k1, k2, p1, p2, k3; the distortion is inverted by 20 fixed-point steps, as
    :func:`sim_core.camera.undistort_normalized` does.
    """
    m = u_px.shape[0]
    out = np.empty((m, 3))
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    distorted = k1 != 0.0 or k2 != 0.0 or p1 != 0.0 or p2 != 0.0 or k3 != 0.0
    for i in prange(m):
        xd = (u_px[i] - cx) / fx
        yd = (v_px[i] - cy) / fy
        x, y = xd, yd
        if distorted:
            for _ in range(20):
                r2 = x * x + y * y
                radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
                # keeps a wild k from dividing by 0
                if abs(radial) < 1e-6:
                    radial = 1e-6
                dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
                dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
                x = (xd - dx) / radial
                y = (yd - dy) / radial
        inv = 1.0 / np.sqrt(x * x + y * y + 1.0)
        cx_, cy_, cz_ = x * inv, y * inv, inv
        for k in range(3):
            out[i, k] = rotation[k, 0] * cx_ + rotation[k, 1] * cy_ + rotation[k, 2] * cz_
    return out


@njit(cache=True, parallel=True, error_model="numpy")
def primary_rays(
    seed, pixels, first_sample, n_passes, npix, u_px, v_px, footprint_px, fx, fy, cx, cy, dist,
    rotation,
):
    """Camera rays for ``n_passes`` more samples of each pixel in ``pixels``.

    Ray ``i`` belongs to pixel ``q = pixels[i % n]`` and is that pixel's sample number
    ``first_sample[i % n] + i // n``: its path key hashes (seed, that sample number, q), so a
    pixel's k-th sample is the same whichever pixels are traced with it. It lands uniformly in
    the ``footprint_px`` square around the pixel centre (0: the centre itself), drawn from the
    uniforms of bounce 0. Returns float32 directions (m, 3), the accumulation slot of each
    ray (``(i // n) * npix + q``) and the path keys.
    """
    n = pixels.shape[0]
    m = n_passes * n
    u = np.empty(m)
    v = np.empty(m)
    slot = np.empty(m, dtype=np.int64)
    keys = np.empty(m, dtype=np.uint64)
    sk = seed_key(seed)
    for i in prange(m):
        j = i % n
        q = pixels[j]
        local = i // n
        key = path_key(sk, first_sample[j] + local, q)
        keys[i] = key
        slot[i] = local * npix + q
        if footprint_px > 0.0:
            ju, jv = uniform_pair(key, 0, 0)
            u[i] = u_px[q] + (ju - 0.5) * footprint_px
            v[i] = v_px[q] + (jv - 0.5) * footprint_px
        else:
            u[i] = u_px[q]
            v[i] = v_px[q]
    return camera_rays(u, v, fx, fy, cx, cy, dist, rotation).astype(np.float32), slot, keys


@njit(cache=True, inline="always", error_model="numpy")
def _profile_intensity(cos_a, scale, prof_angle, prof_rel):
    """Radiant intensity [W/sr] at angle arccos(cos_a) from the source axis (linear table)."""
    if prof_angle.shape[0] == 0:
        return scale
    # arccos needs its argument inside [-1, 1]; rounding can leave it 1 + 1e-16.
    c = min(1.0, max(-1.0, cos_a))
    a = math.acos(c)
    if a >= prof_angle[-1]:
        return 0.0
    return scale * np.interp(a, prof_angle, prof_rel)


@njit(cache=True, parallel=True, error_model="numpy")
def bounce(
    hit, o, d, tfar, prim, slot, keys, length, throughput,
    normals, tri_mat, mat_kind, mat_params,
    light_pos, light_axis, light_scale, prof_angle, prof_rel, min_light_distance_m,
    amb_dir, amb_irr, amb_centre, amb_u, amb_v, amb_size, amb_footprint, render_origin,
    bounce_index, rr_from_bounce, scatter,
):
    """All the work at one path vertex except ray casting (seed eqs. 19-22).

    For every traced ray ``hit[j]`` that met a surface: the hit point and a normal facing the
    ray; the candidate contribution of the camera's source (seed eqs. 20-21, 0 where the light
    is behind the surface) with its shadow ray and the full path length; the same for every
    ambient source (DC only, inside its beam footprint); and, if ``scatter``, the next ray by
    BRDF importance sampling with Russian roulette (uniform dimensions 0-2 and 3 of this
    bounce). Sampling does not depend on visibility, so both happen in one pass.

    Ray arrays are float32 in the render frame (what Embree takes); the arithmetic is float64.
    """
    k = hit.shape[0]
    n_amb = amb_dir.shape[0]
    flat = np.empty(k, dtype=np.int64)
    act = np.zeros(k)
    act_len = np.empty(k)
    sh_o = np.empty((k, 3), dtype=np.float32)
    sh_d = np.empty((k, 3), dtype=np.float32)
    sh_t = np.empty(k, dtype=np.float32)
    amb = np.zeros((n_amb, k))
    amb_o = np.empty((n_amb, k, 3), dtype=np.float32)
    nxt_o = np.empty((k, 3), dtype=np.float32)
    nxt_d = np.empty((k, 3), dtype=np.float32)
    nxt_len = np.empty(k)
    nxt_thr = np.zeros(k)
    alive = np.zeros(k, dtype=np.bool_)
    for j in prange(k):
        i = hit[j]
        f = prim[i]
        t = np.float64(tfar[i])
        dx, dy, dz = np.float64(d[i, 0]), np.float64(d[i, 1]), np.float64(d[i, 2])
        nx, ny, nz = normals[f, 0], normals[f, 1], normals[f, 2]
        if nx * dx + ny * dy + nz * dz > 0.0:
            nx, ny, nz = -nx, -ny, -nz
        px = o[i, 0] + t * dx
        py = o[i, 1] + t * dy
        pz = o[i, 2] + t * dz
        t0, t1, t2, b0, b1, b2 = duff_frame(nx, ny, nz)
        wol0 = -(dx * t0 + dy * t1 + dz * t2)
        wol1 = -(dx * b0 + dy * b1 + dz * b2)
        wol2 = -(dx * nx + dy * ny + dz * nz)
        m = tri_mat[f]
        kind = mat_kind[m]
        par = mat_params[m]
        ln = length[i] + t
        flat[j] = slot[i]
        thr = throughput[i]
        s = _offset_scale(px, py, pz)

        # Camera source: E = I(theta) cos / d^2 (seed eq. 20), L = E f (eq. 21).
        lx, ly, lz = light_pos[0] - px, light_pos[1] - py, light_pos[2] - pz
        dist = math.sqrt(lx * lx + ly * ly + lz * lz)
        # The direction to the light is normalised by the true distance: the BRDF contract
        # asks for unit vectors (a point exactly at the light has no direction: cos_p = 0).
        inv_true = 1.0 / dist if dist > 0.0 else 0.0
        lx, ly, lz = lx * inv_true, ly * inv_true, lz * inv_true
        # A surface through the light itself would see I / 0^2: the irradiance is capped at
        # I / d_min^2 (the clamp enters 1/d^2 only).
        inv_dist = 1.0 / (dist if dist > min_light_distance_m else min_light_distance_m)
        cos_p = lx * nx + ly * ny + lz * nz
        act_len[j] = ln + dist
        if cos_p > 0.0 and thr > 0.0:
            fr = eval_brdf(kind, par, lx * t0 + ly * t1 + lz * t2, lx * b0 + ly * b1 + lz * b2,
                           cos_p, wol0, wol1, wol2)
            inten = _profile_intensity(
                -(lx * light_axis[0] + ly * light_axis[1] + lz * light_axis[2]),
                light_scale, prof_angle, prof_rel,
            )
            c = thr * fr * inten * cos_p * inv_dist * inv_dist
            if c > 0.0:
                act[j] = c
                ox, oy, oz = px + s * nx, py + s * ny, pz + s * nz
                sh_o[j, 0], sh_o[j, 1], sh_o[j, 2] = ox, oy, oz
                sh_d[j, 0], sh_d[j, 1], sh_d[j, 2] = lx, ly, lz
                ex, ey, ez = light_pos[0] - ox, light_pos[1] - oy, light_pos[2] - oz
                sh_t[j] = math.sqrt(ex * ex + ey * ey + ez * ez) * (1.0 - 1e-6)

        # Ambient sources: collimated, E cos, DC only.
        for a in range(n_amb):
            ax, ay, az = -amb_dir[a, 0], -amb_dir[a, 1], -amb_dir[a, 2]
            cos_a = ax * nx + ay * ny + az * nz
            if cos_a <= 0.0 or thr <= 0.0:
                continue
            if amb_footprint[a]:
                rx = px + render_origin[0] - amb_centre[a, 0]
                ry = py + render_origin[1] - amb_centre[a, 1]
                rz = pz + render_origin[2] - amb_centre[a, 2]
                cu = abs(rx * amb_u[a, 0] + ry * amb_u[a, 1] + rz * amb_u[a, 2])
                cv = abs(rx * amb_v[a, 0] + ry * amb_v[a, 1] + rz * amb_v[a, 2])
                if cu > 0.5 * amb_size[a, 0] or cv > 0.5 * amb_size[a, 1]:
                    continue
            fr = eval_brdf(kind, par, ax * t0 + ay * t1 + az * t2, ax * b0 + ay * b1 + az * b2,
                           cos_a, wol0, wol1, wol2)
            c = thr * fr * amb_irr[a] * cos_a
            if c > 0.0:
                amb[a, j] = c
                amb_o[a, j, 0] = px + s * nx
                amb_o[a, j, 1] = py + s * ny
                amb_o[a, j, 2] = pz + s * nz

        if not scatter or not thr > 0.0:
            continue
        key = keys[i]
        u0, u1 = uniform_pair(key, bounce_index, 0)
        u2, u3 = uniform_pair(key, bounce_index, 1)
        x, y, z, _pdf, w = sample_brdf(kind, par, wol0, wol1, wol2, u0, u1, u2)
        tn = thr * w
        if not tn > 0.0:
            continue
        if bounce_index + 1 >= rr_from_bounce:
            # Survival probability follows the throughput; dividing by it keeps the estimate
            # unbiased. The floor keeps 1/q bounded.
            q = min(1.0, max(0.05, tn))
            if u3 >= q:
                continue
            tn = tn / q
        wx = x * t0 + y * b0 + z * nx
        wy = x * t1 + y * b1 + z * ny
        wz = x * t2 + y * b2 + z * nz
        inv = 1.0 / math.sqrt(wx * wx + wy * wy + wz * wz)  # orthonormal frame: ~1
        sz = s if z >= 0.0 else -s
        nxt_o[j, 0], nxt_o[j, 1], nxt_o[j, 2] = px + sz * nx, py + sz * ny, pz + sz * nz
        nxt_d[j, 0], nxt_d[j, 1], nxt_d[j, 2] = wx * inv, wy * inv, wz * inv
        nxt_len[j] = ln
        nxt_thr[j] = tn
        alive[j] = True
    return (flat, act, act_len, sh_o, sh_d, sh_t, amb, amb_o,
            nxt_o, nxt_d, nxt_len, nxt_thr, alive)


@njit(cache=True, parallel=True, error_model="numpy")
def gather_rays(idx, o, d, t):
    """Rows ``idx`` of ray origins, directions (float32, (k, 3)) and lengths, contiguous.

    numpy's fancy indexing of (k, 3) float32 rows measured ~20 ns per row here; this is a
    plain parallel copy. ``t`` may be empty (then an empty array comes back).
    """
    n = idx.shape[0]
    go = np.empty((n, 3), dtype=np.float32)
    gd = np.empty((n, 3), dtype=np.float32)
    gt = np.empty(n if t.shape[0] else 0, dtype=t.dtype)
    for j in prange(n):
        i = idx[j]
        go[j, 0], go[j, 1], go[j, 2] = o[i, 0], o[i, 1], o[i, 2]
        gd[j, 0], gd[j, 1], gd[j, 2] = d[i, 0], d[i, 1], d[i, 2]
        if t.shape[0]:
            gt[j] = t[i]
    return go, gd, gt
