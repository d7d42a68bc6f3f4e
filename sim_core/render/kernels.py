"""Compiled per-ray kernels of the wavefront integrator (numba).

Profiling the numpy version (line_profiler, corner scene, direct, 32 spp) showed about 1 us of
numpy work per path against ~0.1 us inside Embree: every step allocated and re-read (m, 3)
temporaries. These kernels fuse each step into one pass over the rays and run it on all cores
(``prange``); each ray's result depends only on that ray, so the output is identical for any
number of threads. Pixel accumulation is serial, in ray order, so sums are bit-reproducible.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

# The default OpenMP/TBB layers keep their threads spinning after a parallel region, which
# starves the Embree worker threads and numpy between kernels (measured: 2x slower frames on
# 2 cores). The workqueue layer parks its threads.
if numba.config.THREADING_LAYER == "default":
    numba.config.THREADING_LAYER = "workqueue"

# Relative and absolute offset of secondary-ray origins; see integrator.RAY_OFFSET_REL.
_OFFSET_REL = 1e-5
_OFFSET_MIN_M = 1e-6


@njit(cache=True, inline="always")
def _offset_scale(px, py, pz):
    m = max(abs(px), abs(py), abs(pz)) * _OFFSET_REL
    return m if m > _OFFSET_MIN_M else _OFFSET_MIN_M


@njit(cache=True, inline="always")
def _duff_frame(nx, ny, nz):
    """Branchless orthonormal basis (Duff et al. 2017) around a unit normal."""
    sign = 1.0 if nz >= 0.0 else -1.0
    # sign + nz has magnitude >= 1, so a is finite.
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx, b, sign + ny * ny * a, -ny)


@njit(cache=True, parallel=True)
def surface_points(o, d, t, prim, normals):
    """Hit points ``o + t d`` and face normals flipped to face the incoming ray.

    Returns p (m, 3), n (m, 3), wo = -d (m, 3).
    """
    m = t.shape[0]
    p = np.empty((m, 3))
    n = np.empty((m, 3))
    wo = np.empty((m, 3))
    for i in prange(m):
        f = prim[i]
        nx, ny, nz = normals[f, 0], normals[f, 1], normals[f, 2]
        if nx * d[i, 0] + ny * d[i, 1] + nz * d[i, 2] > 0.0:
            nx, ny, nz = -nx, -ny, -nz
        for k in range(3):
            p[i, k] = o[i, k] + t[i] * d[i, k]
            wo[i, k] = -d[i, k]
        n[i, 0], n[i, 1], n[i, 2] = nx, ny, nz
    return p, n, wo


@njit(cache=True, parallel=True)
def shading_frames(n, wo):
    """Tangent frames (t, b) around ``n`` and ``wo`` in those frames; all (m, 3)."""
    m = n.shape[0]
    tb = np.empty((m, 3))
    bb = np.empty((m, 3))
    wo_l = np.empty((m, 3))
    for i in prange(m):
        t0, t1, t2, b0, b1, b2 = _duff_frame(n[i, 0], n[i, 1], n[i, 2])
        tb[i, 0], tb[i, 1], tb[i, 2] = t0, t1, t2
        bb[i, 0], bb[i, 1], bb[i, 2] = b0, b1, b2
        w0, w1, w2 = wo[i, 0], wo[i, 1], wo[i, 2]
        wo_l[i, 0] = w0 * t0 + w1 * t1 + w2 * t2
        wo_l[i, 1] = w0 * b0 + w1 * b1 + w2 * b2
        wo_l[i, 2] = w0 * n[i, 0] + w1 * n[i, 1] + w2 * n[i, 2]
    return tb, bb, wo_l


@njit(cache=True, parallel=True)
def gather_local(w, idx, tb, bb, n):
    """Directions ``w[j]`` expressed in the frames of rows ``idx[j]``; (k, 3)."""
    k = idx.shape[0]
    out = np.empty((k, 3))
    for j in prange(k):
        i = idx[j]
        w0, w1, w2 = w[j, 0], w[j, 1], w[j, 2]
        out[j, 0] = w0 * tb[i, 0] + w1 * tb[i, 1] + w2 * tb[i, 2]
        out[j, 1] = w0 * bb[i, 0] + w1 * bb[i, 1] + w2 * bb[i, 2]
        out[j, 2] = w0 * n[i, 0] + w1 * n[i, 1] + w2 * n[i, 2]
    return out


@njit(cache=True, parallel=True)
def local_to_world(w_l, tb, bb, n):
    """Inverse of the shading-frame projection, renormalised; (m, 3)."""
    m = w_l.shape[0]
    out = np.empty((m, 3))
    for i in prange(m):
        x, y, z = w_l[i, 0], w_l[i, 1], w_l[i, 2]
        s = 0.0
        for k in range(3):
            v = x * tb[i, k] + y * bb[i, k] + z * n[i, k]
            out[i, k] = v
            s += v * v
        # The frames are orthonormal, so s is 1 up to rounding; 0 only for an invalid (zero)
        # sample, which is left as it is (its weight is 0 and the path is dropped).
        if s > 0.0:
            inv = 1.0 / np.sqrt(s)
            for k in range(3):
                out[i, k] *= inv
    return out


@njit(cache=True, parallel=True)
def point_light_setup(p, n, light_pos, min_distance_m):
    """Geometry of next-event estimation towards a point light, per vertex.

    Returns
    -------
    wi : (m, 3) unit direction to the light
    dist : (m,) distance to the light [m] (floored at ``min_distance_m``)
    cos_p : (m,) cosine between ``wi`` and the normal (<= 0: light behind the surface)
    origin : (m, 3) shadow-ray origin, offset off the surface towards the light
    t_max : (m,) shadow-ray length, stopping just short of the light
    """
    m = p.shape[0]
    wi = np.empty((m, 3))
    dist = np.empty(m)
    cos_p = np.empty(m)
    origin = np.empty((m, 3))
    t_max = np.empty(m)
    for i in prange(m):
        dx = light_pos[0] - p[i, 0]
        dy = light_pos[1] - p[i, 1]
        dz = light_pos[2] - p[i, 2]
        dd = np.sqrt(dx * dx + dy * dy + dz * dz)
        # A surface through the light itself would see I / 0^2.
        dd = dd if dd > min_distance_m else min_distance_m
        wx, wy, wz = dx / dd, dy / dd, dz / dd
        c = wx * n[i, 0] + wy * n[i, 1] + wz * n[i, 2]
        wi[i, 0], wi[i, 1], wi[i, 2] = wx, wy, wz
        dist[i] = dd
        cos_p[i] = c
        s = _offset_scale(p[i, 0], p[i, 1], p[i, 2])
        s = s if c >= 0.0 else -s
        for k in range(3):
            origin[i, k] = p[i, k] + s * n[i, k]
        ox = light_pos[0] - origin[i, 0]
        oy = light_pos[1] - origin[i, 1]
        oz = light_pos[2] - origin[i, 2]
        t_max[i] = np.sqrt(ox * ox + oy * oy + oz * oz) * (1.0 - 1e-6)
    return wi, dist, cos_p, origin, t_max


@njit(cache=True, parallel=True)
def offset_origins(p, n, w):
    """Points moved off their surface along ``n`` to the side of ``w``; (m, 3)."""
    m = p.shape[0]
    out = np.empty((m, 3))
    for i in prange(m):
        s = _offset_scale(p[i, 0], p[i, 1], p[i, 2])
        if n[i, 0] * w[i, 0] + n[i, 1] * w[i, 1] + n[i, 2] * w[i, 2] < 0.0:
            s = -s
        for k in range(3):
            out[i, k] = p[i, k] + s * n[i, k]
    return out


@njit(cache=True)
def accumulate_modulated(flat, contrib, length_m, psi_rad_m, out_dc, out_re, out_im):
    """Add contributions to DC and to each frequency's phasor (seed eqs. 17, 31), in order."""
    nf = psi_rad_m.shape[0]
    for j in range(flat.shape[0]):
        c = contrib[j]
        q = flat[j]
        out_dc[q] += c
        for k in range(nf):
            phase = psi_rad_m[k] * length_m[j]
            out_re[k, q] += c * np.cos(phase)
            out_im[k, q] -= c * np.sin(phase)


@njit(cache=True)
def accumulate(flat, contrib, out):
    """Add contributions to pixels, in order."""
    for j in range(flat.shape[0]):
        out[flat[j]] += contrib[j]


@njit(cache=True, parallel=True)
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
