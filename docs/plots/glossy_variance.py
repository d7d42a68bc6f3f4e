"""The table of docs/performance.md's "Variance on glossy materials": per-pixel range noise of
each sampling variant at equal spp on the glossy corner (and the Lambertian one).

For every variant, one render of the example scene (path, 3 bounces, seed 7, 2 threads) and,
per pixel, the Monte Carlo standard error of the range at the first modulation frequency
(60.24 MHz; :func:`sim_core.adaptive.range_standard_error_m`, from the per-sample phasor
covariance) scaled to 1024 spp, so that the figures compare with issue 16's; then its RMS over
the floor's pixels and over the walls'. Variance per sample does not depend on the machine;
the ray count says what the roulette saved.

Run from the repository root::

    PYTHONPATH=. python docs/plots/glossy_variance.py [SPP] [SCENE ...]

(default 256 spp, scenes ``corner_glossy`` and ``corner``; about a minute per scene).
"""

from __future__ import annotations

import dataclasses
import sys

import numpy as np

from sim_core.adaptive import range_standard_error_m
from sim_core.materials.base import Material
from sim_core.materials.microfacet import FixedLobeMixture, MicrofacetMixture
from sim_core.render import RenderSettings, render
from sim_core.scene import Scene, build_scene
from sim_core.scene_spec import load_scene_spec

#: the spp the noise is reported at (issue 16's figures)
REPORT_SPP = 1024
BOUNCES = 3
NO_ROULETTE = BOUNCES + 1


def _lobes(scene: Scene, choice: str) -> Scene:
    """``scene`` with every microfacet material's lobe choice replaced: ``"albedo"`` (the
    renderer's own), ``"ks/(ks+kd)"`` (the former one) or ``"50/50"`` (the naive mixture)."""
    def swap(m: Material) -> Material:
        if choice == "albedo" or not isinstance(m, MicrofacetMixture):
            return m
        if choice == "50/50":
            return FixedLobeMixture(m)
        ks, kd = m.ks, m.kd  # both microfacet models have them
        return FixedLobeMixture(m, p_spec=ks / (ks + kd))
    return dataclasses.replace(scene, materials=tuple(swap(m) for m in scene.materials))


VARIANTS = (  # (label, lobe choice, russian_roulette_from_bounce)
    ("before: lobes by ks/(ks+kd), roulette from bounce 3", "ks/(ks+kd)", 3),
    ("lobes by ks/(ks+kd), no roulette", "ks/(ks+kd)", NO_ROULETTE),
    ("naive 50/50 mixture, roulette from bounce 3", "50/50", 3),
    ("naive 50/50 mixture, no roulette (issue 16's reference)", "50/50", NO_ROULETTE),
    ("lobes by albedo at wo, roulette from bounce 3", "albedo", 3),
    ("now: lobes by albedo at wo, no roulette within 3 bounces", "albedo",
     RenderSettings().russian_roulette_from_bounce),
)


def noise_rms_mm(scene: Scene, spp: int, rr_from_bounce: int) -> tuple[float, float, float]:
    """RMS range noise at REPORT_SPP on the floor (object 0) and the walls [mm], and Mrays."""
    res = render(scene, RenderSettings(spp=spp, max_bounces=BOUNCES, seed=7, threads=2,
                                       russian_roulette_from_bounce=rr_from_bounce))
    lf = res.light_field
    noise_mm = range_standard_error_m(lf) * np.sqrt(lf.samples_per_pixel / REPORT_SPP) * 1e3
    ok = np.isfinite(noise_mm)
    floor, walls = ok & (lf.object_id == 0), ok & (lf.object_id > 0)
    return (float(np.sqrt(np.mean(noise_mm[floor] ** 2))),
            float(np.sqrt(np.mean(noise_mm[walls] ** 2))), res.rays_traced / 1e6)


def main(argv: list[str]) -> None:
    spp = int(argv[0]) if argv else 256
    scenes = argv[1:] or ["corner_glossy", "corner"]
    print(f"| scene | variant | floor mm | walls mm | Mrays ({spp} spp) |")
    print("|---|---|---|---|---|")
    for name in scenes:
        path = f"examples/{name}.yaml"
        scene = build_scene(load_scene_spec(path), base_dir="examples")
        has_lobes = any(isinstance(m, MicrofacetMixture) for m in scene.materials)
        for label, choice, rr in VARIANTS:
            if choice != "albedo" and not has_lobes:
                continue
            floor, walls, mrays = noise_rms_mm(_lobes(scene, choice), spp, rr)
            print(f"| {name} | {label} | {floor:.2f} | {walls:.2f} | {mrays:.1f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
