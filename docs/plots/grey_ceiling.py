"""docs/calibration.md's "The noise ceiling and render noise": how far a twin with the *true*
reality stays from the grey noise ceiling, with fixed spp or rendered to a fraction of the
sensor's noise.

For a random reality of the simulated lab (:func:`tests.calibration.realities.random_reality`)
and each turntable angle at 1 sun: the lab's world is rendered once (seed ``LAB_SEED``) and
exposed twice (the ceiling: two captures differ by sensor noise only), the twin with the same
reality once (another seed) and exposed once; the grey PSNR of capture against capture and of
capture against twin over the mounted objects' pixels, and the seconds each render took.
``K_LAB`` and ``K_TWIN`` are noise fractions (:func:`sim_core.adaptive.noise_fraction`) or
``none`` for ``SPP`` everywhere.

Run from the repository root::

    PYTHONPATH=. python docs/plots/grey_ceiling.py SEED ANGLES K_LAB K_TWIN [SPP] [LAB_SEED]

e.g. ``151 -60,0 none none 64`` (fixed 64 spp) against ``151 -60,0 0.25 0.35 64``; a few
seconds per angle.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from calibration.angles import parse_angles
from sim_core.metrics import compare_images
from sim_core.pipeline import expose_light, render_light
from sim_core.render import RenderSettings
from sim_core.render_request import AccuracyTarget, RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import load_scene_spec
from tests.calibration.realities import random_reality
from tests.sim_core.scenes import EXAMPLES

SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
MOUNTED = tuple(o.name for o in SPEC.objects if o.on_turntable)
#: the grey image's full scale [DN] for both sides of every comparison
GREY_FULL_SCALE_DN = 2048.0


def _fraction(text: str) -> float | None:
    return None if text == "none" else float(text)


def main(seed: int, angles: list[float], k_lab: float | None, k_twin: float | None,
         spp: int = 64, lab_seed: int = 11) -> None:
    reality = random_reality(seed, nominal_power_w=SPEC.illumination.power_w,
                             object_twin_names=MOUNTED)
    mounted_ids = [i for i, o in enumerate(SPEC.objects) if o.on_turntable]
    fs = (GREY_FULL_SCALE_DN, GREY_FULL_SCALE_DN)
    print("angle [deg] | lab s | twin s | ceiling dB | true twin dB | short by dB")
    for angle in angles:
        scene = build_scene(SPEC, EXAMPLES, turntable_deg=angle, solar_suns=1.0, twin=reality)
        renders = []
        for render_seed, k in ((lab_seed, k_lab), (lab_seed + 11, k_twin)):
            t0 = time.perf_counter()
            settings = RenderSettings(integrator="path", spp=spp, max_bounces=2,
                                      seed=render_seed)
            request = RenderRequest(settings, AccuracyTarget(noise_fraction=k), effects="all")
            light = render_light(scene, request)
            renders.append((light, time.perf_counter() - t0))
        (lab, lab_s), (twin, twin_s) = renders
        first = expose_light(scene, lab, noise_rng=np.random.default_rng(1))
        second = expose_light(scene, lab, noise_rng=np.random.default_rng(2))
        twin_frame = expose_light(scene, twin, noise_rng=np.random.default_rng(3))
        mask = np.isin(twin.light_field.object_id, mounted_ids)
        ceiling = compare_images(first.image, second.image, mask, grey_full_scale=fs).grey
        true_twin = compare_images(first.image, twin_frame.image, mask, grey_full_scale=fs).grey
        print(f"{angle:11.0f} | {lab_s:5.1f} | {twin_s:6.1f} | {ceiling.psnr_db:10.2f} | "
              f"{true_twin.psnr_db:12.2f} | {ceiling.psnr_db - true_twin.psnr_db:11.2f}")


if __name__ == "__main__":
    a = sys.argv[1:]
    main(int(a[0]), list(parse_angles(a[1], field="ANGLES")), _fraction(a[2]), _fraction(a[3]),
         *(int(v) for v in a[4:6]))
