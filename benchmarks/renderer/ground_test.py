"""``toftwin bench ground-test``: the seed's Fig. 14 comparison on the satellite ground test.

Renders ``satellite_ground_test.yaml`` twice with the same seed: as the peer method models it
(the camera's own light only: solar simulator shutter closed, no SBI) and as the seed's method
does (solar simulator at its level, SBI active), and prints the grey and depth statistics of
both inside the satellite's mask (the seed removed the background by hand; here the
simulator's object mask does it).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from sim_core.metrics import depth_mm_16bit, grey_8bit, mask_from_objects
from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import EXAMPLES_DIR, load_scene_spec

EXAMPLE = EXAMPLES_DIR / "satellite_ground_test.yaml"
SATELLITE_PARTS = ("body", "panel_left", "panel_right")


def run_ground_test(spp: int, seed: int, console: Console, path: Path = EXAMPLE) -> dict:
    spec = load_scene_spec(path)
    settings = RenderSettings(integrator=spec.render.integrator, spp=spp,
                              max_bounces=spec.render.max_bounces, seed=seed)
    rows = {}
    for label, suns, sbi in (("camera light only, no SBI (peer)", 0.0, False),
                             ("solar simulator 1 sun + SBI (seed)", None, True)):
        scene = build_scene(spec, base_dir=path.parent, solar_suns=suns)
        scene = dataclasses.replace(scene, sensor=dataclasses.replace(scene.sensor,
                                                                      sbi_enabled=sbi))
        frame = simulate(scene, RenderRequest(settings))
        ids = [scene.object_names.index(n) for n in SATELLITE_PARTS]
        mask = mask_from_objects(frame.light_field.object_id, ids)
        grey = grey_8bit(frame.image.amplitude, frame.grey_full_scale).astype(np.float64)
        depth = depth_mm_16bit(frame.image.range_m).astype(np.float64)
        valid = mask & frame.image.valid
        rows[label] = {
            "grey_mean": float(grey[mask].mean()), "grey_var": float(grey[mask].var()),
            "depth_mean_mm": float(depth[mask].mean()), "depth_var_mm2": float(depth[mask].var()),
            "valid_fraction": float(valid.sum() / max(mask.sum(), 1)),
            "pixels": int(mask.sum()),
            "sbi": frame.plan.enabled("sbi"), "ambient": frame.plan.enabled("ambient"),
        }
    table = Table(
        title=f"satellite ground test, inside the satellite mask ({spp} spp, seed {seed})"
    )
    for col in ("setting", "grey mean", "grey var", "depth mean [mm]", "depth var [mm^2]",
                "valid"):
        table.add_column(col, justify="right")
    for label, r in rows.items():
        table.add_row(label, f"{r['grey_mean']:.2f}", f"{r['grey_var']:.1f}",
                      f"{r['depth_mean_mm']:.1f}", f"{r['depth_var_mm2']:.3g}",
                      f"{100 * r['valid_fraction']:.0f} %")
    console.print(table)
    console.print("Invalid pixels count as 0 in grey and depth (the camera tools' convention, "
                  "as in the seed's Table 5).")
    return rows
