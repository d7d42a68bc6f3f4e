"""``toftwin bench render``: seconds per frame, ray throughput and the Embree share.

For each scene, integrator setting, spp and bounce count it renders one frame (after one warm-up
frame per scene that builds the Embree scene and warms caches) and prints:

- seconds per frame (wall clock),
- rays traced per second (primary, shadow and bounce rays together),
- where the worker threads' time went, as shares of the machine's capacity (wall time x
  threads): inside Embree queries, in the compiled kernels (camera rays, shading and next-event
  estimation, accumulation), and the rest (Python glue and numpy buffers, waiting, per-frame
  setup),
- for reference, raw Embree throughput on a batch of this scene's primary rays.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from sim_core.render import RenderSettings, render
from sim_core.scene import build_scene
from sim_core.scene_spec import EXAMPLES_DIR, load_scene_spec
from sim_core.tracing import RayTracer

DEFAULT_SCENES = (
    "plane.yaml", "corner.yaml", "corner_glossy.yaml", "satellite_ground_test.yaml",
)


def default_scene_paths() -> list[Path]:
    return [EXAMPLES_DIR / name for name in DEFAULT_SCENES]


def raw_embree_mrays_per_s(tracer: RayTracer, scene, n_rays: int = 1 << 20) -> float:
    """Throughput of bare closest-hit queries on random primary rays of ``scene`` [Mrays/s]."""
    rng = np.random.default_rng(0)
    intr = scene.camera.intrinsics
    u = rng.uniform(-0.5, intr.width_px - 0.5, n_rays)
    v = rng.uniform(-0.5, intr.height_px - 0.5, n_rays)
    d = scene.camera.pixel_directions_world(u, v)
    o = np.zeros_like(d)
    tracer.intersect(o, d)  # warm-up
    t0 = time.perf_counter()
    tracer.intersect(o, d)
    return n_rays / (time.perf_counter() - t0) / 1e6


def run_render_benchmark(
    scenes: list[Path] | None,
    spps: list[int],
    bounces: list[int],
    threads: int | None,
    console: Console,
) -> list[dict]:
    """Run the sweep, print a table, return its rows."""
    rows: list[dict] = []
    table = Table(title="toftwin render benchmark (one frame per row, 224 x 171)")
    for col in ("scene", "integrator", "spp", "bounces", "s/frame", "Mrays/s", "Embree %",
                "kernels %", "other %"):
        table.add_column(col, justify="right")
    for path in scenes or default_scene_paths():
        spec = load_scene_spec(path)
        scene = build_scene(spec, base_dir=path.parent)
        with RayTracer(scene.triangles_m, scene.camera.position_m, threads=threads) as tracer:
            raw = raw_embree_mrays_per_s(tracer, scene)
            console.print(
                f"{spec.name}: {scene.n_triangles} triangles, raw Embree primary rays "
                f"{raw:.1f} Mrays/s on {tracer.threads} thread(s)"
            )
            render(scene, RenderSettings(integrator="direct", spp=1, threads=threads), tracer)
            for b in bounces:
                integrator = "direct" if b == 1 else "path"
                for spp in spps:
                    settings = RenderSettings(
                        integrator=integrator, spp=spp, max_bounces=b, seed=1, threads=threads
                    )
                    res = render(scene, settings, tracer)
                    capacity = res.seconds * res.threads
                    st = res.stage_thread_seconds
                    kernels = (st["camera_rays"] + st["shading"] + st["accumulation"]) / capacity
                    row = {
                        "scene": spec.name,
                        "integrator": integrator,
                        "spp": spp,
                        "bounces": b,
                        "seconds": res.seconds,
                        "mrays_per_s": res.rays_traced / res.seconds / 1e6,
                        "embree_share": res.embree_share,
                        "kernel_share": kernels,
                        "other_share": max(0.0, 1.0 - res.embree_share - kernels),
                        "raw_embree_mrays_per_s": raw,
                    }
                    rows.append(row)
                    table.add_row(
                        spec.name, integrator, str(spp), str(b), f"{res.seconds:.3f}",
                        f"{row['mrays_per_s']:.2f}", f"{100 * res.embree_share:.0f}",
                        f"{100 * kernels:.0f}", f"{100 * row['other_share']:.0f}",
                    )
    console.print(table)
    return rows
