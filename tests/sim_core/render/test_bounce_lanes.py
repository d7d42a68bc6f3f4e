"""Shading in lanes (:func:`sim_core.render.kernels.bounce`, issue 30) against shading lane by
lane.

``bounce`` evaluates a block of rays of one analytic material kind in SIMD lanes, every lane
whether its value is used or not, and a block that mixes kinds lane by lane, only where a value
is used. Both must give the same bits: the same rays, once sorted by material kind (uniform
blocks) and once interleaved (mixed blocks), give the same shadow rays and the same continuing
paths, value for value.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim_core.render import RenderSettings, kernels
from sim_core.render.integrator import _Context
from sim_core.render.kernels import LANES, Paths
from sim_core.tracing import RayTracer
from tests.sim_core.scenes import example


def _chunk(scene, passes: int = 2):
    """Camera rays of every pixel of ``scene`` and Embree's answer for them."""
    tracer = RayTracer(scene.triangles_m, scene.camera.position_m, threads=1)
    ctx = _Context(scene, RenderSettings(spp=passes, ambient=True), tracer,
                   scene.camera.position_m)
    pixels = np.arange(ctx.npix)
    d, keys = kernels.primary_rays(5, pixels, np.zeros(ctx.npix, np.int64), passes, ctx.u_px,
                                   ctx.v_px, 1.0, ctx.camera)
    m = d.shape[0]
    rng = np.random.default_rng(2)
    paths = Paths(np.zeros_like(d), d, np.arange(m, dtype=np.int64), keys,
                  rng.uniform(0.0, 2.0, m), rng.uniform(0.05, 1.0, m))
    tfar, prim = tracer.intersect32(paths.o, paths.d)
    tracer.close()
    return ctx, paths, tfar, prim


def _take(paths: Paths, tfar, prim, order):
    return Paths(*(np.ascontiguousarray(f[order]) for f in paths)), tfar[order], prim[order]


def _by_slot(shadow, nxt):
    """The outputs keyed by the path's slot (and, for shadow rays, by the source)."""
    sh = {}
    for k in range(shadow.slot.shape[0]):
        key = (int(shadow.slot[k]), bool(shadow.is_ambient[k]))
        assert key not in sh
        sh[key] = (*shadow.o[k].view(np.uint32), *shadow.d[k].view(np.uint32),
                   shadow.t_max[k].view(np.uint32), shadow.contribution[k].view(np.uint64),
                   shadow.length[k].view(np.uint64))
    nx = {int(nxt.slot[k]): (*nxt.o[k].view(np.uint32), *nxt.d[k].view(np.uint32), nxt.key[k],
                             nxt.length[k].view(np.uint64), nxt.throughput[k].view(np.uint64))
          for k in range(nxt.slot.shape[0])}
    return sh, nx


def _kinds_per_block(kinds: np.ndarray, live: np.ndarray) -> list[set]:
    return [set(kinds[a:a + LANES][live[a:a + LANES]].tolist())
            for a in range(0, kinds.size, LANES)]


@pytest.mark.parametrize("bounce_index", [1, 3], ids=["first-bounce", "with-roulette"])
def test_uniform_blocks_in_lanes_equal_mixed_blocks_lane_by_lane(bounce_index):
    # Microfacet panels, Lambertian walls, the sun and the camera source's angular profile.
    scene = example("satellite_ground_test", solar_suns=1.0)
    ctx, paths, tfar, prim = _chunk(scene)
    kinds = np.where(prim >= 0, ctx.tables.mat_kind[ctx.tables.tri_mat[np.maximum(prim, 0)]],
                     -1)
    # the rays that met the satellite's microfacet panels, as many that met a Lambertian
    # surface and some that met nothing
    mic = np.flatnonzero(kinds == 1)
    assert mic.size > 2000
    rng = np.random.default_rng(4)
    pick = np.concatenate([mic, rng.choice(np.flatnonzero(kinds == 0), mic.size, replace=False),
                           np.flatnonzero(kinds < 0)[:100]])
    paths, tfar, prim = _take(paths, tfar, prim, np.sort(pick))
    kinds = kinds[np.sort(pick)]
    hit = prim >= 0
    assert set(kinds[hit].tolist()) == {0, 1}  # Lambertian and seed microfacet both met
    # Order A: sorted by kind, so nearly every block is of one kind (in lanes).
    order_a = np.argsort(kinds, kind="stable")
    # Order B: the kinds interleaved, so every block mixes them (lane by lane).
    lam, mic = np.flatnonzero(kinds == 0), np.flatnonzero(kinds == 1)
    k = min(lam.size, mic.size)
    order_b = np.concatenate([np.stack([lam[:k], mic[:k]], axis=1).ravel(), lam[k:], mic[k:],
                              np.flatnonzero(kinds < 0)])
    assert sorted(order_b.tolist()) == list(range(kinds.size))
    blocks_a = _kinds_per_block(kinds[order_a], hit[order_a])
    blocks_b = _kinds_per_block(kinds[order_b], hit[order_b])
    assert sum(len(b) == 1 for b in blocks_a) >= 0.9 * len(blocks_a)
    assert sum(len(b) == 2 for b in blocks_b) >= 0.5 * len(blocks_b)
    outputs = []
    for order in (order_a, order_b):
        p, t, f = _take(paths, tfar, prim, order)
        shadow, nxt = kernels.bounce(p, t, f, ctx.tables, ctx.light, ctx.ambient, ctx.origin,
                                     bounce_index, 2, True)
        assert shadow.slot.size > 0.5 * hit.sum() and nxt.slot.size > 0
        assert shadow.is_ambient.any()  # the sun's contributions are in the comparison
        outputs.append(_by_slot(shadow, nxt))
    assert outputs[0][0] == outputs[1][0]
    assert outputs[0][1] == outputs[1][1]
