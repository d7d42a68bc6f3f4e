"""``toftwin simulate`` and ``toftwin preview``: one frame without the service."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from service.cli import ranges
from service.cli.common import (
    QuietOption,
    choice,
    console,
    fail_invalid,
    number_option,
    print_error,
    progress_bar,
)
from service.cli.render_options import (
    CalibrationFileOption,
    IntegratorOption,
    MaxBouncesOption,
    TurntableDegOption,
)
from sim_core.errors import InvalidInputError


def simulate(
    scene: Annotated[Path, typer.Argument(help="Scene file (YAML or JSON).")],
    out: Annotated[Path, typer.Option("--out", help="Output directory.")],
    spp: Annotated[
        int | None, number_option("--spp", help="Samples per pixel (default: the scene's).",
                                  allowed=ranges.SPP)
    ] = None,
    max_bounces: MaxBouncesOption = None,
    seed: Annotated[
        int | None, number_option("--seed", help="Random seed.",
                                  allowed=ranges.SEED)
    ] = None,
    integrator: IntegratorOption = None,
    ideal: Annotated[
        bool, typer.Option("--ideal", help="Ideal sensor: no noise, SBI or ADC.")
    ] = False,
    effects: Annotated[
        str, typer.Option(help="auto: simulate only what the scene calls for; all: everything.")
    ] = "auto",
    explain: Annotated[bool, typer.Option("--explain", help="Print the effect plan.")] = False,
    effect_tolerance_mm: Annotated[
        float | None,
        number_option("--effect-tolerance-mm", help="Range change below which an effect is off.",
                      allowed=ranges.EFFECT_TOLERANCE),
    ] = None,
    threads: Annotated[
        int | None, number_option("--threads", help="Embree threads (default: all cores).",
                                  allowed=ranges.THREADS)
    ] = None,
    turntable_deg: TurntableDegOption = None,
    quiet: QuietOption = False,
    target_range_error_mm: Annotated[
        float | None,
        number_option("--target-range-error-mm", help="Sample adaptively until the range "
                      "standard error is below this.", allowed=ranges.TARGET_RANGE_ERROR),
    ] = None,
    time_budget_s: Annotated[
        float | None,
        number_option("--time-budget-s", help="Best accuracy within this many seconds.",
                      allowed=ranges.TIME_BUDGET),
    ] = None,
    noise_fraction: Annotated[
        float | None,
        number_option("--noise-fraction",
                      help="At least --spp samples, more where the Monte Carlo error (depth and "
                      "grey) is above this fraction of the sensor's own noise.",
                      allowed=ranges.NOISE_FRACTION),
    ] = None,
    calibration: CalibrationFileOption = None,
) -> None:
    """Render SCENE and write frame.npz, frame.json and PNG previews into --out."""
    from sim_core.pipeline import save_frame
    from sim_core.pipeline import simulate as run_simulation
    from sim_core.render_request import AccuracyTarget, request_from_spec
    from sim_core.scene import build_scene
    from sim_core.scene_spec import load_scene_spec
    from sim_core.twin_file import load_calibration

    try:
        spec = load_scene_spec(scene)
        request = request_from_spec(
            spec.render,
            integrator=None if integrator is None else choice(
                "--integrator", integrator, ("direct", "path")),
            spp=spp, max_bounces=max_bounces, seed=seed, threads=threads,
            accuracy=AccuracyTarget(range_error_mm=target_range_error_mm,
                                    noise_fraction=noise_fraction, time_budget_s=time_budget_s),
            effects=choice("--effects", effects, ("auto", "all")), ideal=ideal,
            tolerance_mm=effect_tolerance_mm,
        )
        twin = None if calibration is None else load_calibration(calibration)
        built = build_scene(spec, base_dir=scene.parent, turntable_deg=turntable_deg, twin=twin)
    except InvalidInputError as exc:
        fail_invalid(exc)
        return
    # Nothing is written to --out before the scene and settings are known to be valid.
    try:
        with progress_bar(quiet) as progress:
            task = progress.add_task("rendering", total=request.settings.spp)
            frame = run_simulation(
                built, request, progress=lambda done, total: progress.update(task, completed=done))
    except InvalidInputError as exc:
        fail_invalid(exc)
        return
    if explain:
        console.print(frame.plan.explain(), markup=False, highlight=False)
    if frame.adaptive is not None:
        a = frame.adaptive
        console.print(
            f"adaptive sampling: range standard error <= {a.achieved_range_error_mm:.3g} mm "
            f"(p95 {a.achieved_range_error_p95_mm:.3g} mm) over {a.pixels_that_matter} pixels, "
            f"{a.spp_min}-{a.spp_max} spp (mean {a.spp_mean:.0f}), {a.rounds} rounds, "
            f"{a.seconds:.2f} s"
            + ("" if a.achieved_noise_fraction is None else
               f"; Monte Carlo error <= {a.achieved_noise_fraction:.2f} of the sensor's noise")
        )
    save_frame(out, frame, scene_name=spec.name)
    t = frame.timings_s
    console.print(
        f"wrote {out}/frame.npz ({frame.image.valid.sum()} valid pixels) in {t['total']:.2f} s, "
        f"{frame.rays_traced / max(t['render'], 1e-9) / 1e6:.2f} Mrays/s, "
        f"{100 * frame.embree_share:.0f} % in Embree"
    )


def preview(
    frame_dir: Annotated[Path, typer.Argument(help="A directory holding frame.npz.")],
    out: Annotated[Path, typer.Option("--out", help="PNG file to write.")],
    scale: Annotated[int, number_option("--scale", help="Pixel magnification.",
                                        allowed=ranges.PREVIEW_SCALE)] = 2,
) -> None:
    """Grey and depth side by side (depth colour-coded near -> far) as one PNG."""
    from sim_core.frame_io import read_frame
    from sim_core.preview import side_by_side

    try:
        image = side_by_side(read_frame(frame_dir), scale)
    except FileNotFoundError as exc:
        print_error(str(exc))
        raise typer.Exit(code=2) from None
    except InvalidInputError as exc:
        fail_invalid(exc)
        return
    image.save(out)
    console.print(f"wrote {out}")
