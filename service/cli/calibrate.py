"""``toftwin calibrate rig``: measure the twin's camera and rig parameters on the rig.

Runs the calibration sequence (:func:`service.lab.acquisition.run_rig_calibration`: the plan
acquired on the rig, then fitted) on the real rig (the operator swaps the board and the test
object when asked) or on the simulated lab (``--simulated``, optionally
``--reality FILE``: the lab's hidden truth), and writes ``DIR/calibration.yaml``,
``DIR/verdicts.json`` (every key's verdict), ``DIR/report.json``, ``DIR/report.html`` with the
residual plots and ``DIR/opencv_intrinsics.yml`` (the camera in OpenCV's form); it prints how
many keys are determined, not determined and unexplained, and the reason of each key that is
not determined.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from calibration.angles import (
    SWEEP_COUNT_RANGE,
    SWEEP_FROM_DEG,
    SWEEP_STEP_DEG,
    SWEEP_TO_DEG,
)
from service.cli import ranges
from service.cli.command_settings import (
    CameraSeedOption,
    CameraSppOption,
    OutFolderOption,
    RealityOption,
    open_command_rig,
    rig_settings,
)
from service.cli.common import (
    QuietOption,
    check_rig_options,
    command_group,
    console,
    fail_invalid,
    number_option,
    print_verdicts,
    print_warning,
    rig_scene,
    step_progress,
)
from sim_core.errors import InvalidInputError

if TYPE_CHECKING:
    from calibration.verdicts import Verdicts
    from drivers.sim.world import SimulatedWorld

#: the board sweep's inputs as the options name them (calibration.angles.sweep_angles)
SWEEP_OPTIONS = {"sweep": "--sweep-from/--sweep-to/--sweep-step", "from_deg": "--sweep-from",
                 "to_deg": "--sweep-to", "step_deg": "--sweep-step"}

calibrate_app = command_group("Measure the twin's camera and rig parameters.")

#: ``--scene`` of the rig's calibrations: the scene whose camera, turntable and solar simulator
#: the rig is
SceneOption = Annotated[
    str, typer.Option(help="Bundled scene name or scene file: camera pose, turntable, "
                      "solar simulator.")
]


class ConsoleOperator:
    """The operator at the real rig: asked on the terminal to swap what is on the turntable."""

    def mount(self, objects: Sequence | None, instruction: str) -> None:
        typer.confirm(f"{instruction[0].upper()}{instruction[1:]}; ready?", default=True,
                      abort=True, err=True)


def _operator(world: SimulatedWorld | None, materials: Mapping[str, Any] | None = None):
    """Who swaps what is on the turntable: the simulated lab's operator (mounting
    ``materials`` where a plan asks for them), or the one at the real rig (no world)."""
    from drivers.sim.operator import SimulatedOperator

    return ConsoleOperator() if world is None else SimulatedOperator(world, materials=materials)


@calibrate_app.command("rig")
def rig_command(
    out: OutFolderOption,
    simulated: Annotated[
        bool, typer.Option("--simulated", help="Calibrate the simulated lab's rig.")
    ] = False,
    reality: RealityOption = None,
    scene: SceneOption = "satellite_ground_test",
    frames_per_view: Annotated[
        int, number_option("--frames-per-view", help="Frames averaged per board view.",
                           allowed=ranges.FRAMES_PER_VIEW)
    ] = 4,
    sweep_from_deg: Annotated[
        float, number_option("--sweep-from", help="First angle of the board sweep [deg].",
                             allowed=ranges.TURNTABLE_DEG)
    ] = SWEEP_FROM_DEG,
    sweep_to_deg: Annotated[
        float, number_option("--sweep-to", help="Last angle of the board sweep (when a step "
                             "reaches it) [deg]; above --sweep-from.",
                             allowed=ranges.TURNTABLE_DEG)
    ] = SWEEP_TO_DEG,
    sweep_step_deg: Annotated[
        float, number_option("--sweep-step", help="Step of the board sweep [deg]; coarser is "
                             "quicker and measures less well; the sweep has "
                             f"{SWEEP_COUNT_RANGE[0]}-{SWEEP_COUNT_RANGE[1]} angles.",
                             allowed=ranges.SWEEP_STEP)
    ] = SWEEP_STEP_DEG,
    solar_reference_suns: Annotated[
        float | None,
        number_option("--solar-reference-suns",
                      help="A reference cell's reading at a set level of 1 sun [sun], used when "
                           "the frames do not determine the solar simulator's scale.",
                      allowed=ranges.REFERENCE_SUNS),
    ] = None,
    warmup: Annotated[
        bool, typer.Option("--warmup/--no-warmup", help="Run the warm-up stage first (about 18 "
                           "minutes of a fixed target after power-on: the depth's temperature "
                           "drift); --no-warmup for a camera already warm, its drift then "
                           "unmeasured.")
    ] = True,
    settling: Annotated[
        bool, typer.Option("--settling/--no-settling", help="Run the settling stage (frames "
                           "right after one move: the turntable's ringing); --no-settling "
                           "leaves it unmeasured.")
    ] = True,
    camera_spp: CameraSppOption = 32,
    seed: CameraSeedOption = 0,
    quiet: QuietOption = False,
    print_plan: Annotated[
        bool, typer.Option("--print-plan", help="Print the plan (what the sequence captures) "
                           "as JSON and stop, the rig untouched.")
    ] = False,
) -> None:
    """Run the whole calibration sequence and write DIR/calibration.yaml, DIR/verdicts.json
    (determined, not determined or unexplained, per key), its report and the camera in
    OpenCV's form (DIR/opencv_intrinsics.yml)."""
    from calibration.report import write_report
    from calibration.rig_sequence import build_rig_plan, rig_capture_plan, stage_counts
    from service.lab.acquisition import run_rig_calibration

    try:
        check_rig_options(out, reality, simulated)
        # the service's builder (POST /calibrations): the same plan for the same inputs
        plan = build_rig_plan(sweep_from_deg=sweep_from_deg, sweep_to_deg=sweep_to_deg,
                              sweep_step_deg=sweep_step_deg, frames_per_view=frames_per_view,
                              solar_reference_suns=solar_reference_suns, fields=SWEEP_OPTIONS,
                              **stage_counts(warmup=warmup, settling=settling))
        if print_plan:
            typer.echo(json.dumps(plan.summary(), indent=2))
            return
        source = rig_scene(scene)
    except InvalidInputError as exc:
        fail_invalid(exc)
    settings = rig_settings(simulated=simulated, reality=reality, camera_spp=camera_spp,
                            camera_integrator="direct", camera_seed=seed)
    with (open_command_rig(settings, source) as (rig, world),
          step_progress(quiet, "calibrating",
                        rig_capture_plan(plan, source.spec).n_captures) as progress):
        rig_name = "lab" if world is None else "simulated"
        try:
            result = run_rig_calibration(rig, _operator(world), source.spec, source.base_dir, plan,
                                         progress, rig_name=rig_name)
        except InvalidInputError as exc:
            fail_invalid(exc)
    paths = write_report(out, result)
    console.print(f"calibration written to {paths['calibration']} (report {paths['html']}, "
                  f"verdicts {paths['verdicts']})")
    print_verdicts(result.verdicts)


@calibrate_app.command("material")
def material_command(
    out: Annotated[Path, typer.Option("--out", help="Material file to write (YAML); the slices "
                                      "go to OUT.slices.csv, the report to OUT.report.json, "
                                      "each parameter's verdict to OUT.verdicts.json (OUT: the "
                                      "file without its suffix).")],
    simulated: Annotated[
        bool, typer.Option("--simulated", help="Measure on the simulated lab's rig.")
    ] = False,
    reality: RealityOption = None,
    sample_material: Annotated[
        str | None,
        typer.Option("--sample-material",
                     help="The simulated lab's sample: a preset name or a material file "
                          "(needs --simulated; default: the prior)."),
    ] = None,
    calibration: Annotated[
        Path | None,
        typer.Option("--calibration", help="The rig's calibration (toftwin calibrate rig); "
                     "default: the nominal twin."),
    ] = None,
    model: Annotated[str, typer.Option("--model", help="Material kind fitted.")] = "cook-torrance",
    prior: Annotated[
        str | None,
        typer.Option("--prior", help="Preset (or material file) holding the values of the "
                     "parameters the slices do not determine; default: the model's defaults."),
    ] = None,
    size_m: Annotated[
        float, number_option("--size-m", help="Side of the square sample [m].",
                             allowed=ranges.SAMPLE_SIZE)
    ] = 0.2,
    angles: Annotated[
        str, typer.Option("--angles", help="Turntable angles: FROM:TO:STEP or a list [deg].")
    ] = "-70:70:5",
    frames_per_state: Annotated[
        int, number_option("--frames-per-state", help="Frames averaged per rig state.",
                           allowed=ranges.FRAMES_PER_STATE)
    ] = 4,
    solar_suns: Annotated[
        float, number_option("--solar-suns", help="Solar simulator level of the solar slice "
                             "[sun]; 0 leaves it out.",
                             allowed=ranges.SOLAR_SUNS_OR_OFF)
    ] = 0.8,
    scene: SceneOption = "satellite_ground_test",
    camera_spp: CameraSppOption = 32,
    seed: Annotated[
        int, number_option("--seed", help="Noise seed of the simulated camera and the fit.",
                           allowed=ranges.CAMERA_SEED)
    ] = 0,
    quiet: QuietOption = False,
) -> None:
    """Measure a material's BRDF on the rig: a sample plate swept by the turntable (issue 14)."""
    from calibration.brdf.material_file import write_material_file
    from calibration.rig_material import MaterialSweepPlan, prior_material, sample_angles
    from calibration.rig_material.plan import SAMPLE_NAME
    from service.lab.acquisition import run_material_calibration
    from sim_core.twin_file import load_calibration

    try:
        if reality is not None and not simulated:
            raise InvalidInputError("--reality", "describes the simulated lab: needs --simulated")
        if sample_material is not None and not simulated:
            raise InvalidInputError("--sample-material", "is the simulated lab's sample: needs "
                                    "--simulated")
        plan = MaterialSweepPlan(angles_deg=sample_angles(angles, "--angles"), size_m=size_m,
                                 frames_per_state=frames_per_state, solar_suns=solar_suns)
        prior_mat = prior_material(model, _material_arg(prior, "--prior"))
        cal = load_calibration(calibration) if calibration is not None else None
        source = rig_scene(scene)
        # the simulated lab's sample (if the rig is the simulated lab's)
        truth = _material_arg(sample_material, "--sample-material")
        truth = truth if truth is not None else prior_mat
        truth = {SAMPLE_NAME: truth if isinstance(truth, str) else _spec_dict(truth)}
    except InvalidInputError as exc:
        fail_invalid(exc)
    settings = rig_settings(simulated=simulated, reality=reality, camera_spp=camera_spp,
                            camera_integrator="direct", camera_seed=seed)
    with (open_command_rig(settings, source) as (rig, world),
          step_progress(quiet, "measuring", plan.n_steps) as progress):
        try:
            result = run_material_calibration(rig, _operator(world, truth), source.spec,
                                              source.base_dir, cal,
                                              plan, model, prior_mat, progress, seed=seed)
        except InvalidInputError as exc:
            fail_invalid(exc)
    path = write_material_file(out, result.result.fit)
    csv_path = out.with_name(out.stem + ".slices.csv")
    result.slices.write_csv(csv_path)
    report_path = out.with_name(out.stem + ".report.json")
    _write_json(report_path, result.report())
    rows = ", ".join(f"{len(p)} {p.slice_name}" for p in result.slices.parts)
    console.print(f"{model} fitted to the rig's slices ({rows} rows)")
    for name, st in result.result.parameters.items():
        note = {"determined": f"± {st.uncertainty:.2g}", "conditional":
                f"± {st.uncertainty:.2g}  given the prior of the held ones",
                "prior": "held at the prior: NOT DETERMINED by these slices"}[st.status]
        console.print(f"  {name:>16} = {st.value:.4g}  {note}")
    for w in result.slices.check.warnings:
        print_warning(w)
    verdicts_path = _print_and_write_verdicts(out, result.verdicts)
    console.print(f"material file written to {path} (slices {csv_path}, report {report_path}, "
                  f"verdicts {verdicts_path})")


def _print_and_write_verdicts(out: Path, verdicts: Verdicts) -> Path:
    """Print the verdicts; write them beside the output file (``OUT.verdicts.json``)."""
    from calibration.verdicts import verdicts_beside, write_verdicts

    print_verdicts(verdicts)
    return write_verdicts(verdicts_beside(out), verdicts)


def _material_arg(value: str | None, option: str):
    """A preset name, or the ``{kind, params}`` of a material file (None stays None)."""
    if value is None:
        return None
    if Path(value).suffix.lower() in (".yaml", ".yml", ".json"):
        from sim_core.materials.material_file import read_material_file

        kind, params = read_material_file(value)
        return {"kind": kind, "params": params}
    from sim_core.materials import PRESETS

    if value not in PRESETS:
        raise InvalidInputError(option, f"'{value}' is neither a preset ({', '.join(PRESETS)}) "
                                "nor a material file (.yaml, .json)")
    return value


def _spec_dict(material) -> dict:
    from dataclasses import fields

    return {"kind": material.name,
            "params": {f.name: getattr(material, f.name) for f in fields(material)}}


def _write_json(path: Path, data: dict) -> None:
    import json

    from sim_core.files import atomic_write

    atomic_write(path, json.dumps(data, indent=2, allow_nan=False))


BRDF_MODELS = ("seed-microfacet", "cook-torrance", "lambertian", "hapke")


def _parse_fixed(items: Sequence[str]) -> dict[str, float]:
    """``["m=0.1", "n2=1.5"]`` -> ``{"m": 0.1, "n2": 1.5}``; an input error naming ``--fix``."""
    fixed: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not sep or not name.strip() or not math.isfinite(value):
            raise InvalidInputError("--fix", f"{item!r} is not NAME=VALUE with a finite number")
        fixed[name.strip()] = value
    return fixed


@calibrate_app.command("brdf")
def brdf_command(
    data: Annotated[Path, typer.Argument(help="Goniometer CSV: incidence_zenith_deg, "
                                         "reflection_zenith_deg, azimuth_difference_deg, "
                                         "brdf_per_sr (optional wavelength_nm, brdf_std_per_sr).")],
    model: Annotated[str, typer.Option("--model", help=f"One of {', '.join(BRDF_MODELS)}.")],
    out: Annotated[Path, typer.Option("--out", help="Material file to write (YAML); each "
                                      "parameter's verdict goes to OUT.verdicts.json (OUT: the "
                                      "file without its suffix).")],
    wavelength_nm: Annotated[
        float | None,
        number_option("--wavelength-nm", help="Band to fit when the file holds several [nm].",
                      allowed=ranges.WAVELENGTH),
    ] = None,
    fix: Annotated[
        list[str] | None,
        typer.Option("--fix", help="Pin a parameter: NAME=VALUE (repeatable)."),
    ] = None,
    outlier_threshold: Annotated[
        float, number_option("--outlier-threshold",
                             help="Relative error beyond which a sample is an outlier.",
                             allowed=ranges.OUTLIER_THRESHOLD)
    ] = 0.25,
    seed: Annotated[
        int, number_option("--seed", help="Seed of RANSAC and differential evolution.",
                           allowed=ranges.FIT_SEED)
    ] = 0,
) -> None:
    """Fit a material model to goniometer data and write a material file (issue 14)."""
    from calibration.brdf import FitSettings, fit_brdf
    from calibration.brdf.evidence import brdf_verdicts
    from calibration.brdf.material_file import write_material_file
    from service.cli.common import choice
    from sim_core.materials.goniometer import read_goniometer_csv

    try:
        choice("--model", model, BRDF_MODELS)
        settings = FitSettings(outlier_relative_error=outlier_threshold)
        fixed = _parse_fixed(fix or [])
        table = read_goniometer_csv(data, wavelength_nm=wavelength_nm)
        fit = fit_brdf(table, model, fixed=fixed, seed=seed, settings=settings)
    except InvalidInputError as exc:
        fail_invalid(exc)
    verdicts = brdf_verdicts(fit, held_reasons={n: f"held at {v:g} (--fix), not fitted"
                                                for n, v in fixed.items()}, seed=seed)
    path = write_material_file(out, fit)
    console.print(f"{fit.kind} fitted to {len(table)} samples of {data}"
                  + (f" at {table.wavelength_nm:g} nm" if table.wavelength_nm else ""))
    for name, value in fit.params.items():
        if name in fit.fixed:
            note = "fixed"
        else:
            note = f"± {fit.uncertainty[name]:.2g}" + ("" if fit.determined[name]
                                                      else "  NOT DETERMINED by these data")
        console.print(f"  {name:>16} = {value:.4g}  {note}")
    console.print(f"  e_fit (seed eq. 11) = {100 * fit.e_fit:.3g} % over the inliers, "
                  f"{100 * fit.e_fit_all:.3g} % over all samples")
    console.print(f"  outliers flagged: {fit.n_outliers} of {len(table)} (relative error beyond "
                  f"{100 * outlier_threshold:g} %)")
    verdicts_path = _print_and_write_verdicts(out, verdicts)
    console.print(f"material file written to {path} (verdicts {verdicts_path})")


@calibrate_app.command("intrinsics")
def intrinsics_command(
    images: Annotated[
        list[Path], typer.Argument(help="Images of the board: 8 or 16-bit PNG, JPEG, TIFF, a "
                                   "frame folder or its frame.npz; a folder means every image "
                                   "and frame folder in it, sorted by name. One camera, one "
                                   "image size.")],
    board: Annotated[str, typer.Option("--board", help="charuco or chessboard.")],
    squares: Annotated[str, typer.Option("--squares", help="WxH: the board's SQUARES across "
                                         "and down (not inner corners: a chessboard of 9 x 6 "
                                         "inner corners is 10x7), each 3-40.")],
    square_mm: Annotated[float, number_option("--square-mm", help="Side of a square [mm].",
                                              allowed=ranges.BOARD_SIDE_MM)],
    out: Annotated[Path, typer.Option("--out", help="Output folder: calibration.yaml, "
                                      "verdicts.json, opencv_intrinsics.yml (replaced if "
                                      "there).")],
    marker_mm: Annotated[
        float | None, number_option("--marker-mm", help="ChArUco: side of a marker [mm], "
                                    "below --square-mm.", allowed=ranges.BOARD_SIDE_MM)
    ] = None,
    dictionary: Annotated[
        str | None, typer.Option("--dictionary", help="ChArUco: the ArUco dictionary, e.g. "
                                 "DICT_4X4_50, DICT_5X5_100.")
    ] = None,
    fit_k3: Annotated[
        bool, typer.Option("--k3/--no-k3", help="Fit the sixth-order radial term k3 (wide "
                           "angles); default: held at 0.")
    ] = False,
) -> None:
    """Intrinsics and distortion of any camera from its images of a board: per view the
    corners and the reprojection error, every key's verdict, the file in the project's and
    OpenCV's forms (docs/calibration.md)."""
    from datetime import UTC, datetime

    from calibration.photo_intrinsics import calibrate_photos, make_board, write_outputs

    try:
        spec = make_board(board, squares, square_mm, marker_mm, dictionary)
        cal = calibrate_photos(images, spec, fit_k3=fit_k3)
        paths = write_outputs(out, cal, datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"))
    except InvalidInputError as exc:
        fail_invalid(exc)
    _print_photo_calibration(cal)
    print_verdicts(cal.verdicts)
    console.print(f"calibration written to {paths['calibration']} (OpenCV's form "
                  f"{paths['opencv']}, verdicts {paths['verdicts']})")


def _print_photo_calibration(cal) -> None:
    """The per-view table and the estimates with their standard deviations."""
    from rich.table import Table

    h, w = cal.image_shape
    table = Table(title=f"{cal.board.describe()}; images {w} x {h} px")
    for col in ("view", "corners", "RMS [px]", "refused because"):
        table.add_column(col)
    for v in cal.views:
        table.add_row(v.name, str(v.corners), "" if v.rms_px is None else f"{v.rms_px:.3f}",
                      v.reason or "")
    console.print(table)
    res = cal.result
    console.print(f"{len(res.per_view_rms_px)} views, {res.n_corners} corners, reprojection RMS "
                  f"{res.rms_px:.3f} px; model test: reduced chi-square "
                  f"{cal.model.reduced_chi2:.2f} over {cal.model.cells} cells")
    for name, value in cal.parameters.items():
        key = f"camera.{name}" if name.endswith("_px") else f"camera.distortion.{name}"
        std = cal.verdicts[key].std
        note = f"± {std:.3g}" if isinstance(std, float) else ""
        console.print(f"  {key:>24} = {value:.6g}  {note}  {cal.verdicts[key].verdict}")
