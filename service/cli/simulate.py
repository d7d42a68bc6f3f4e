"""``toftwin simulate`` and ``toftwin preview``: one frame without the service."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from service.cli.common import bounded, choice, console, err_console, fail_invalid, progress_bar
from sim_core.errors import InvalidInputError


def simulate(
    scene: Annotated[Path, typer.Argument(help="Scene file (YAML or JSON).")],
    out: Annotated[Path, typer.Option("--out", help="Output directory.")],
    spp: Annotated[int | None, typer.Option(help="Samples per pixel (1-65536).")] = None,
    max_bounces: Annotated[
        int | None, typer.Option("--max-bounces", help="Surface interactions per path (1-16).")
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Random seed (>= 0).")] = None,
    integrator: Annotated[
        str | None, typer.Option(help="direct or path (default: the scene's).")
    ] = None,
    ideal: Annotated[
        bool, typer.Option("--ideal", help="Ideal sensor: no noise, SBI or ADC.")
    ] = False,
    effects: Annotated[
        str, typer.Option(help="auto: simulate only what the scene calls for; all: everything.")
    ] = "auto",
    explain: Annotated[bool, typer.Option("--explain", help="Print the effect plan.")] = False,
    effect_tolerance_mm: Annotated[
        float | None,
        typer.Option("--effect-tolerance-mm", help="Range change below which an effect is off."),
    ] = None,
    threads: Annotated[
        int | None, typer.Option(help="Embree threads (default: all cores).")
    ] = None,
    turntable_deg: Annotated[
        float | None, typer.Option("--turntable-deg", help="Override the turntable angle [deg].")
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
    target_range_error_mm: Annotated[
        float | None,
        typer.Option("--target-range-error-mm",
                     help="Sample adaptively until the range standard error is below this."),
    ] = None,
    time_budget_s: Annotated[
        float | None,
        typer.Option("--time-budget-s", help="Best accuracy within this many seconds."),
    ] = None,
    noise_fraction: Annotated[
        float | None,
        typer.Option("--noise-fraction",
                     help="At least --spp samples, more where the Monte Carlo error (depth and "
                     "grey) is above this fraction of the sensor's own noise (0.05 to 2)."),
    ] = None,
    calibration: Annotated[
        Path | None,
        typer.Option("--calibration", help="Calibration file to apply (docs/calibration.md); "
                     "replaces the scene's own 'calibration'."),
    ] = None,
) -> None:
    """Render SCENE and write frame.npz, frame.json and PNG previews into --out."""
    from sim_core.adaptive import NOISE_FRACTION_RANGE
    from sim_core.pipeline import save_frame
    from sim_core.pipeline import simulate as run_simulation
    from sim_core.render import RenderSettings
    from sim_core.scene import build_scene
    from sim_core.scene_spec import load_scene_spec
    from sim_core.twin_file import load_calibration

    try:
        spec = load_scene_spec(scene)
        r = spec.render
        settings = RenderSettings(
            integrator=choice("--integrator", integrator or r.integrator, ("direct", "path")),
            spp=bounded("--spp", spp if spp is not None else r.spp, 1, 65536),
            max_bounces=bounded(
                "--max-bounces", max_bounces if max_bounces is not None else r.max_bounces, 1, 16
            ),
            seed=bounded("--seed", seed if seed is not None else r.seed, 0, 2**63 - 1),
            russian_roulette_from_bounce=r.russian_roulette_from_bounce,
            threads=None if threads is None else bounded("--threads", threads, 1, 256),
        )
        choice("--effects", effects, ("auto", "all"))
        if effect_tolerance_mm is not None and not 0.0 < effect_tolerance_mm <= 1e4:
            raise InvalidInputError(
                "--effect-tolerance-mm", f"{effect_tolerance_mm} is outside (0, 10000] mm"
            )
        lo, hi = NOISE_FRACTION_RANGE
        if noise_fraction is not None and not lo <= noise_fraction <= hi:
            raise InvalidInputError("--noise-fraction",
                                    f"{noise_fraction} is outside [{lo:g}, {hi:g}]")
        twin = None if calibration is None else load_calibration(calibration)
        built = build_scene(spec, base_dir=scene.parent, turntable_deg=turntable_deg, twin=twin)
    except InvalidInputError as exc:
        fail_invalid(exc)
        return
    # Nothing is written to --out before the scene and settings are known to be valid.
    try:
        with progress_bar(quiet) as progress:
            task = progress.add_task("rendering", total=settings.spp)
            frame = run_simulation(
                built, settings, effects=effects, ideal=ideal,
                tolerance_mm=effect_tolerance_mm,
                progress=lambda done, total: progress.update(task, completed=done),
                target_range_error_mm=target_range_error_mm,
                time_budget_s=time_budget_s,
                target_noise_fraction=noise_fraction,
            )
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
    scale: Annotated[int, typer.Option(help="Pixel magnification (1-8).")] = 2,
) -> None:
    """Grey and depth side by side (depth colour-coded near -> far) as one PNG."""
    from sim_core.frame_io import read_frame
    from sim_core.preview import side_by_side

    try:
        image = side_by_side(read_frame(frame_dir), bounded("--scale", scale, 1, 8))
    except FileNotFoundError as exc:
        err_console.print(f"[bold red]error:[/] {exc}")
        raise typer.Exit(code=2) from None
    except InvalidInputError as exc:
        fail_invalid(exc)
        return
    image.save(out)
    console.print(f"wrote {out}")
