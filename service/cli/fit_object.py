"""``toftwin fit-object``: the mounted object's pose offset and reflectance from its frames.

Drives the rig (the real one, or the simulated lab with ``--simulated [--reality FILE]``, the
same rig path as ``toftwin calibrate rig``) to each ``--angles`` turntable angle with the solar
simulator's shutter closed, averages ``--frames`` frames per angle, runs
:func:`calibration.object_twin.fit.fit_object` with the ``--calibration`` (or the nominal rig)
and writes ``DIR/object.yaml`` (the object file a scene's ``object_twin:`` names),
``DIR/object-report.json`` and ``DIR/verdicts.json`` (each key's verdict:
:mod:`calibration.object_twin.judgement`), each atomically.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

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
    check_rig_options,
    console,
    err_console,
    fail_invalid,
    number_option,
    print_verdicts,
    print_warning,
    rig_scene,
)
from sim_core.errors import InvalidInputError

#: default turntable angles [deg]: three views, the faces seen from three sides
DEFAULT_ANGLES = "-60,-30,0,30,60"


def fit_object_command(
    out: OutFolderOption,
    simulated: Annotated[
        bool, typer.Option("--simulated", help="Use the simulated lab's rig.")
    ] = False,
    reality: RealityOption = None,
    scene: Annotated[
        str, typer.Option(help="Bundled scene name or scene file: what is on the turntable.")
    ] = "satellite_ground_test",
    angles: Annotated[
        str, typer.Option("--angles", help="Reported turntable angles to capture [deg]: "
                          "FROM:TO:STEP or a list, 1-36 distinct angles in [-360, 360].")
    ] = DEFAULT_ANGLES,
    calibration: Annotated[
        Path | None,
        typer.Option("--calibration", help="The rig's calibration.yaml (default: the scene's "
                     "own calibration, else the nominal rig)."),
    ] = None,
    frames: Annotated[
        int, number_option("--frames", help="Frames averaged per angle.",
                           allowed=ranges.FIT_FRAMES)
    ] = 32,
    camera_spp: CameraSppOption = 32,
    seed: CameraSeedOption = 0,
) -> None:
    """Capture the mounted object at --angles, fit its pose and reflectance: DIR/object.yaml."""
    from calibration.angles import parse_angles
    from calibration.object_twin.fit import fit_object
    from calibration.object_twin.plan import (
        FIT_ANGLES,
        captures_in_order,
        object_fit_capture_plan,
    )
    from calibration.verdicts import VERDICTS_FILE, write_verdicts
    from service.lab.acquisition import NO_MOUNTS, acquire
    from sim_core.files import atomic_write
    from sim_core.scene import scene_twin
    from sim_core.twin_file import load_calibration, write_object_twin

    try:
        check_rig_options(out, reality, simulated)
        plan = object_fit_capture_plan(parse_angles(angles, field="--angles", limits=FIT_ANGLES),
                                       frames, field="--angles")
        source = rig_scene(scene)
        cal = (load_calibration(calibration) if calibration is not None
               else scene_twin(source.spec.model_copy(update={"object_twin": None}),
                               source.base_dir))
    except InvalidInputError as exc:
        fail_invalid(exc)
    settings = rig_settings(simulated=simulated, reality=reality, camera_spp=camera_spp,
                            camera_integrator="path", camera_seed=seed)
    with open_command_rig(settings, source) as (rig, world):
        rig_name = "lab" if world is None else "simulated"
        captures = acquire(rig, NO_MOUNTS, plan,
                           lambda _done, _total, message: err_console.print(message),
                           settle_for=cal)
    try:
        err_console.print("fitting the object twin")
        fit = fit_object(source.spec, source.base_dir, cal, captures_in_order(plan, captures),
                         rig_name=rig_name)
    except InvalidInputError as exc:
        fail_invalid(exc)
    out.mkdir(parents=True)
    path = write_object_twin(out / "object.yaml", fit.object_twin)
    report = atomic_write(out / "object-report.json",
                          json.dumps(fit.report, indent=2, allow_nan=False) + "\n")
    off = fit.object_twin.mount.pose_offset
    console.print(f"object twin written to {path} (report {report}): offset "
                  f"{[round(v * 1e3, 2) for v in off.position_m]} mm, "
                  f"{[round(v, 3) for v in off.rotation_deg]} deg")
    for view in fit.report["dropped_views"]:
        print_warning(f"{view['turntable_angle_deg']:g} deg: {view['reason']}",
                      label="view left out:")
    print_verdicts(fit.verdicts)
    console.print(f"verdicts written to {write_verdicts(out / VERDICTS_FILE, fit.verdicts)}")
