"""``toftwin bench accuracy``: what accuracy costs in time.

For each scene, render a reference once at high quality (path integrator, 5 bounces, many
samples, every effect on, ideal sensor so that only rendering error is measured), then sweep
integrator, samples per pixel, bounces and the effect plan (auto / all), and measure for every
setting the wall time and the error against the reference inside the object mask:

- ``range_rmse_mm``: RMS range error (wrap-aware), Monte Carlo noise and model bias together;
- ``multipath_bias_mm``: mean signed range error, the bias of too few bounces;
- ``grey_rel_rmse``: RMS error of the amplitude relative to the reference's mean amplitude.

Writes ``accuracy.csv`` (one row per setting), ``accuracy.png`` (error against time, Pareto
front marked) and ``accuracy_summary.json`` (the fitted slope of error against render time for
the path integrator: Monte Carlo error falls as 1/sqrt(time), slope -0.5).
"""

from __future__ import annotations

import csv
import io
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from sim_core.errors import InvalidInputError
from sim_core.files import atomic_write
from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import EXAMPLES_DIR, load_scene_spec
from sim_core.tof import ambiguity_range_m
from sim_core.tracing import RayTracer

#: the example scenes of the sweep (``examples/NAME.yaml``); ``--scene`` picks some of them
SCENES = ("plane", "corner", "corner_glossy", "satellite_ground_test")
FULL = {"spp": (1, 4, 16, 64, 256, 1024), "bounces": (1, 2, 3, 5), "reference_spp": 4096}
QUICK = {"spp": (1, 4, 16, 64), "bounces": (1, 2, 3), "reference_spp": 1024}
REFERENCE_BOUNCES = 5
#: the slope fit uses the path integrator with the sweep's largest bounce count, spp >= this
SLOPE_MIN_SPP = 4


@dataclass
class Row:
    scene: str
    integrator: str
    spp: int
    bounces: int
    effects: str
    seconds: float
    render_seconds: float
    range_rmse_mm: float
    multipath_bias_mm: float
    grey_rel_rmse: float
    pareto: bool = False


def errors(image, ref, f0: float) -> tuple[float, float, float]:
    """Range RMSE [mm], mean range error [mm] and relative grey RMSE inside the mask."""
    mask = ref.valid & image.valid
    if not mask.any():
        return float("nan"), float("nan"), float("nan")
    u = ambiguity_range_m(f0)
    d = image.range_m[mask] - ref.range_m[mask]
    d = (d + 0.5 * u) % u - 0.5 * u  # a wrap is not an error of 2.5 m
    g = image.amplitude[mask] - ref.amplitude[mask]
    return (
        float(np.sqrt(np.mean(d * d)) * 1e3),
        float(np.mean(d) * 1e3),
        float(np.sqrt(np.mean(g * g)) / max(float(np.mean(ref.amplitude[mask])), 1e-300)),
    )


def pareto_flags(seconds: list[float], err: list[float]) -> list[bool]:
    """True for settings no other setting beats in both time and error."""
    flags = []
    for i, (t, e) in enumerate(zip(seconds, err, strict=True)):
        dominated = any(
            (t2 <= t and e2 <= e) and (t2 < t or e2 < e)
            for j, (t2, e2) in enumerate(zip(seconds, err, strict=True)) if j != i
        )
        flags.append(not dominated and np.isfinite(e))
    return flags


def run_accuracy_benchmark(
    out_dir: Path | None, quick: bool, console: Console, scenes: tuple[str, ...] = SCENES,
    sweep: dict | None = None,
) -> list[Row]:
    cfg = dict(sweep or (QUICK if quick else FULL))
    unknown = [n for n in scenes if not (EXAMPLES_DIR / f"{n}.yaml").is_file()]
    if unknown:
        raise InvalidInputError(
            "scene", f"no example scene {', '.join(map(repr, unknown))} in {EXAMPLES_DIR}; "
            f"allowed: {', '.join(SCENES)} or any other examples/NAME.yaml")
    rows: list[Row] = []
    for name in scenes:
        path = EXAMPLES_DIR / f"{name}.yaml"
        scene = build_scene(load_scene_spec(path), base_dir=path.parent)
        f0 = scene.camera.modulation_frequencies_hz[0]
        with RayTracer(scene.triangles_m, scene.camera.position_m) as tracer:
            t0 = time.perf_counter()
            ref = simulate(scene, RenderRequest(RenderSettings(
                integrator="path", spp=cfg["reference_spp"], max_bounces=REFERENCE_BOUNCES,
                seed=987_654), effects="all", ideal=True), tracer=tracer)
            console.print(f"{name}: reference ({cfg['reference_spp']} spp, "
                          f"{REFERENCE_BOUNCES} bounces) in {time.perf_counter() - t0:.1f} s")
            scene_rows = []
            for b in cfg["bounces"]:
                integrator = "direct" if b == 1 else "path"
                for effects in ("auto", "all"):
                    for spp in cfg["spp"]:
                        st = RenderSettings(integrator=integrator, spp=spp, max_bounces=b,
                                            seed=spp * 31 + b)
                        frame = simulate(scene, RenderRequest(st, effects=effects, ideal=True),
                                         tracer=tracer)
                        rmse, bias, grey = errors(frame.image, ref.image, f0)
                        scene_rows.append(Row(
                            name, integrator, spp, b, effects, frame.timings_s["total"],
                            frame.timings_s["render"], rmse, bias, grey))
            flags = pareto_flags([r.seconds for r in scene_rows],
                                 [r.range_rmse_mm for r in scene_rows])
            for r, p in zip(scene_rows, flags, strict=True):
                r.pareto = p
            rows.extend(scene_rows)
    _print_table(rows, console)
    summary = slopes(rows)
    for scene, s in summary.items():
        console.print(f"{scene}: range RMSE ~ render_time^{s['slope']:.2f} for the path "
                      f"integrator ({s['bounces']} bounces, spp >= {SLOPE_MIN_SPP}; "
                      "Monte Carlo predicts -0.5)")
    if out_dir is not None:
        write_outputs(Path(out_dir), rows, summary)
        console.print(f"wrote {out_dir}/accuracy.csv, accuracy.png, accuracy_summary.json")
    return rows


def slopes(rows: list[Row]) -> dict:
    """Fitted exponent of range RMSE against render time, per scene (path, all effects)."""
    out = {}
    bounces = max(r.bounces for r in rows)
    for scene in dict.fromkeys(r.scene for r in rows):
        sel = [r for r in rows if r.scene == scene and r.integrator == "path"
               and r.bounces == bounces and r.effects == "all"
               and r.spp >= SLOPE_MIN_SPP and np.isfinite(r.range_rmse_mm)
               and r.range_rmse_mm > 0]
        if len(sel) >= 2:
            slope = np.polyfit(np.log([r.render_seconds for r in sel]),
                               np.log([r.range_rmse_mm for r in sel]), 1)[0]
            out[scene] = {"slope": float(slope), "points": len(sel), "bounces": bounces}
    return out


def _print_table(rows: list[Row], console: Console) -> None:
    table = Table(title="accuracy against time (ideal sensor; errors against the reference)")
    for col in ("scene", "integrator", "bounces", "effects", "spp", "s", "range RMSE mm",
                "bias mm", "grey rel", "pareto"):
        table.add_column(col, justify="right")
    for r in rows:
        table.add_row(r.scene, r.integrator, str(r.bounces), r.effects, str(r.spp),
                      f"{r.seconds:.2f}", f"{r.range_rmse_mm:.3g}", f"{r.multipath_bias_mm:.3g}",
                      f"{r.grey_rel_rmse:.3g}", "*" if r.pareto else "")
    console.print(table)


def write_outputs(out: Path, rows: list[Row], summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fields = list(asdict(rows[0]).keys())
    fh = io.StringIO(newline="")
    w = csv.DictWriter(fh, fieldnames=fields)
    w.writeheader()
    for r in rows:
        w.writerow(asdict(r))
    atomic_write(out / "accuracy.csv", fh.getvalue())
    atomic_write(out / "accuracy_summary.json", json.dumps(summary, indent=2, sort_keys=True))

    scenes = list(dict.fromkeys(r.scene for r in rows))
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.2 * len(scenes), 4.4), squeeze=False)
    markers = {1: "o", 2: "s", 3: "^", 5: "D"}
    for ax, scene in zip(axes[0], scenes, strict=True):
        sr = [r for r in rows if r.scene == scene and np.isfinite(r.range_rmse_mm)]
        for b in sorted({r.bounces for r in sr}):
            for effects, fill in (("auto", True), ("all", False)):
                pts = sorted([r for r in sr if r.bounces == b and r.effects == effects],
                             key=lambda r: r.spp)
                if not pts:
                    continue
                label = f"{'direct' if b == 1 else f'path, {b} bounces'}, {effects}"
                ax.plot([r.seconds for r in pts], [r.range_rmse_mm for r in pts],
                        marker=markers.get(b, "x"), linestyle=":", label=label,
                        markerfacecolor=None if fill else "none")
        front = sorted([r for r in sr if r.pareto], key=lambda r: r.seconds)
        ax.step([r.seconds for r in front], [r.range_rmse_mm for r in front], where="post",
                color="k", linewidth=1.5, label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time per frame [s]")
        ax.set_ylabel("range RMSE vs reference [mm]")
        slope = summary.get(scene, {}).get("slope")
        ax.set_title(scene + (f"  (slope {slope:.2f})" if slope is not None else ""))
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    atomic_write(out / "accuracy.png", lambda fh: fig.savefig(fh, format="png", dpi=110))
    plt.close(fig)
