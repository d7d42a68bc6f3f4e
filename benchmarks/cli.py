"""``toftwin bench ...``: the command group of the benchmarks, which print figures.

One module per benchmark: the renderer's in :mod:`benchmarks.renderer` (sim_core only), the
campaign's in :mod:`benchmarks.campaign` (the service's). Each is imported when its command runs,
so ``--help`` answers without loading the renderer. The group is added to the ``toftwin`` app
by :mod:`toftwin_cli`; it takes its option ranges and printing from :mod:`service.cli.common`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from service.cli import ranges
from service.cli.common import (
    command_group,
    console,
    fail_invalid,
    int_list,
    number_option,
    print_error,
)
from sim_core.errors import InvalidInputError

bench_app = command_group("Benchmarks that print figures.")


@bench_app.command("render")
def bench_render(
    scenes: Annotated[
        list[Path] | None, typer.Argument(help="Scene files (default: the bundled examples).")
    ] = None,
    spp: Annotated[
        list[int] | None, number_option("--spp", help="Samples per pixel to try (repeatable).",
                                        allowed=ranges.SPP)
    ] = None,
    bounces: Annotated[
        list[int] | None, number_option("--bounces", help="Bounce counts to try (repeatable).",
                                        allowed=ranges.MAX_BOUNCES)
    ] = None,
    threads: Annotated[
        int | None, number_option("--threads", help="Embree threads.", allowed=ranges.THREADS)
    ] = None,
) -> None:
    """Seconds per frame, rays per second and the share of time inside Embree."""
    from benchmarks.renderer.render import run_render_benchmark

    try:
        run_render_benchmark(
            scenes or None, spp or [16, 64, 256], bounces or [1, 2, 3], threads, console
        )
    except InvalidInputError as exc:
        fail_invalid(exc)


@bench_app.command("accuracy")
def bench_accuracy(
    out: Annotated[Path | None, typer.Option("--out", help="Directory for CSV, PNG, JSON.")] = None,
    quick: Annotated[bool, typer.Option("--quick", help="Reduced sweep (minutes).")] = False,
    scene: Annotated[
        list[str] | None,
        typer.Option(help="Example scene (examples/NAME.yaml) to sweep, repeatable "
                          "(default: plane, corner, corner_glossy, satellite_ground_test)."),
    ] = None,
) -> None:
    """Accuracy against time: error of every setting against a high-quality reference."""
    from benchmarks.renderer.accuracy import SCENES, run_accuracy_benchmark

    try:
        run_accuracy_benchmark(out, quick, console, tuple(scene) if scene else SCENES)
    except InvalidInputError as exc:
        fail_invalid(exc)


@bench_app.command("mitsuba")
def bench_mitsuba(
    quick: Annotated[bool, typer.Option("--quick", help="Tiny sweep (seconds).")] = False,
    spp: Annotated[
        list[str] | None,
        typer.Option(help="Samples per pixel of the speed table, comma-separated (16,64,256)."),
    ] = None,
    bounces: Annotated[
        list[str] | None,
        typer.Option(help="Bounce counts of the speed table, comma-separated (1,2,3)."),
    ] = None,
    convergence: Annotated[
        bool,
        typer.Option(help="Also the high-spp reference check and the time to 2 % DC error."),
    ] = True,
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Write every figure to this JSON file.")
    ] = None,
) -> None:
    """Our renderer against Mitsuba 3 on the corner: time ratio, image agreement, time to 2 %."""
    from benchmarks.renderer.mitsuba import run_mitsuba_comparison

    try:
        spps = int_list("--spp", spp or ["16,64,256"], ranges.SPP.lo, ranges.SPP.hi)
        bounce_counts = int_list("--bounces", bounces or ["1,2,3"], ranges.MAX_BOUNCES.lo,
                                 ranges.MAX_BOUNCES.hi)
    except InvalidInputError as exc:
        fail_invalid(exc)
    try:
        res = run_mitsuba_comparison(
            console, spps=spps, bounces=bounce_counts, quick=quick, convergence=convergence
        )
    except RuntimeError as exc:
        print_error(str(exc))
        raise typer.Exit(code=1) from None
    if json_out is not None:
        json_out.write_text(json.dumps(res, indent=2, default=float))
        console.print(f"figures written to {json_out}")


@bench_app.command("ground-test")
def bench_ground_test(
    spp: Annotated[int, number_option("--spp", help="Samples per pixel.",
                                      allowed=ranges.SPP)] = 64,
    seed: Annotated[int, number_option("--seed", help="Random seed.", allowed=ranges.SEED)] = 0,
) -> None:
    """Seed Fig. 14: grey and depth statistics with and without solar simulator and SBI."""
    from benchmarks.renderer.ground_test import run_ground_test

    run_ground_test(spp, seed, console)


@bench_app.command("turning")
def bench_turning(
    speed: Annotated[float, number_option("--speed-deg-s", help="Turning speed [deg/s].",
                                          allowed=ranges.TURNING_SPEED)] = 10.0,
    poses: Annotated[int, number_option("--poses", help="Poses in the sweep.",
                                        allowed=ranges.BENCH_POSES)] = 5,
    step: Annotated[float, number_option("--step-deg", help="Angle between the poses [deg].",
                                         allowed=ranges.TURNING_STEP)] = 10.0,
    spp: Annotated[int, number_option("--spp", help="Samples per pixel of the simulations.",
                                      allowed=ranges.BENCH_SPP)] = 8,
    camera_spp: Annotated[
        int, number_option("--camera-spp", help="Samples per pixel of the camera twin.",
                           allowed=ranges.CAMERA_SPP)
    ] = 8,
    reality: Annotated[Path | None, typer.Option(
        "--reality", help="Reality file of the simulated lab (default: a table that rings "
        "a little after every move).")] = None,
    out: Annotated[Path | None, typer.Option("--out", help="JSON file of the figures.")] = None,
) -> None:
    """A campaign that captures while turning on the simulated lab: poses per minute against
    stop and go, and the depth error at edges."""
    from benchmarks.turning import run_turning_campaign

    try:
        run_turning_campaign(speed, poses, step, spp, camera_spp, reality, out, console)
    except InvalidInputError as exc:
        fail_invalid(exc)


@bench_app.command("campaign")
def bench_campaign(
    poses: Annotated[int, number_option("--poses", help="Poses per campaign.",
                                        allowed=ranges.BENCH_POSES)] = 12,
    repeats: Annotated[int, number_option("--repeats", help="Repeats per pose.",
                                          allowed=ranges.BENCH_REPEATS)] = 1,
    spp: Annotated[int, number_option("--spp", help="Samples per pixel of the simulations.",
                                      allowed=ranges.BENCH_SPP)] = 16,
    camera_spp: Annotated[
        int, number_option("--camera-spp", help="Samples per pixel of the camera twin.",
                           allowed=ranges.CAMERA_SPP)
    ] = 8,
    workers: Annotated[
        list[int] | None, number_option("--workers", help="Local worker counts (repeatable).",
                                        allowed=ranges.WORKERS)
    ] = None,
    dask: Annotated[
        bool, typer.Option("--dask", help="Also on a LocalCluster with 1 and 2 workers.")
    ] = False,
    rounds: Annotated[int, number_option("--rounds", help="Timed campaigns per configuration.",
                                         allowed=ranges.BENCH_ROUNDS)] = 1,
    out: Annotated[Path | None, typer.Option("--out", help="JSON file of the figures.")] = None,
) -> None:
    """Poses per minute of a simulated campaign, and where the time goes per pose."""
    from benchmarks.campaign import run_campaign_benchmark

    run_campaign_benchmark(poses, repeats, spp, camera_spp, workers or [1, 2], dask, out,
                           console, rounds)
