"""``toftwin record`` and ``toftwin replay``: captures kept in a recording, compared again offline.

``record`` drives the rig (the real one, or the simulated lab with ``--simulated [--reality
FILE]``) through a campaign's poses (``--every-pose CAMPAIGN.json``, the body of ``POST
/api/v1/campaigns``) or takes ``--frames N`` at one rig state, and writes every raw frame with
the rig state read back for it into an HDF5 recording (:mod:`service.store.recording`); nothing
is simulated. ``replay`` runs the service's own campaign runner on such a recording, without a
rig, in a new data directory (``--out``): the same results, CSV and report a campaign writes,
and ``toftwin serve --data-dir DIR`` shows them on the operator page (docs/recordings.md).
"""

from __future__ import annotations

import json
import secrets
from pathlib import Path
from typing import Annotated, Any

import typer

from service.cli import ranges
from service.cli.command_settings import (
    RIG_OPTION_OF_FIELD,
    CameraSeedOption,
    CameraSppOption,
    RealityOption,
    load_settings,
    open_command_rig,
    rig_settings,
)
from service.cli.common import (
    console,
    err_console,
    fail_invalid,
    number_option,
    print_error,
    rig_scene,
)
from sim_core.errors import InvalidInputError

#: the files ``toftwin replay`` writes beside the service's data in its ``--out`` folder
RESULTS_CSV, RESULTS_JSON, REPORT_HTML = "results.csv", "results.json", "report.html"

CalibrationOption = Annotated[
    Path | None,
    typer.Option("--calibration", help="A calibration.yaml to apply (record: the one the rig's "
                 "moves wait for ringing with, kept in the recording; replay: instead of the "
                 "recorded one)."),
]


def record_command(
    out: Annotated[Path, typer.Option("--out", help="The recording to write (.h5, new).")],
    frames: Annotated[
        int, number_option("--frames", help="Frames at the one rig state (without "
                           "--every-pose).", allowed=ranges.RECORD_FRAMES)
    ] = 1,
    every_pose: Annotated[
        Path | None,
        typer.Option("--every-pose", help="A campaign file (JSON, the body of POST "
                     "/api/v1/campaigns): one frame per pose and repeat."),
    ] = None,
    turntable_deg: Annotated[
        float, number_option("--turntable-deg", help="Table angle of --frames [deg].",
                             allowed=ranges.TURNTABLE_DEG)
    ] = 0.0,
    suns: Annotated[
        float, number_option("--suns", help="Solar level of --frames [sun]; 0: lamp off.",
                             allowed=ranges.SOLAR_SUNS_OR_OFF)
    ] = 1.0,
    simulated: Annotated[
        bool, typer.Option("--simulated", help="Use the simulated lab's rig.")
    ] = False,
    reality: RealityOption = None,
    scene: Annotated[
        str, typer.Option(help="Bundled scene name or scene file: what is on the turntable "
                          "(a campaign file's scene wins).")
    ] = "satellite_ground_test",
    calibration: CalibrationOption = None,
    camera_spp: CameraSppOption = 32,
    seed: CameraSeedOption = 0,
) -> None:
    """Capture raw frames on the rig into an HDF5 recording that `toftwin replay` compares."""
    from drivers.errors import DeviceError
    from service.lab.requests import CampaignCreate
    from service.store.recording import RecordedCampaign, RecordingWriter
    from sim_core.twin_file import load_calibration, twin_hash

    try:
        if out.exists():
            raise InvalidInputError("--out", f"'{out}' exists; give a new file")
        if out.suffix.lower() not in (".h5", ".hdf5"):
            raise InvalidInputError("--out", f"'{out}': a recording is an .h5 file")
        if reality is not None and not simulated:
            raise InvalidInputError("--reality", "describes the simulated lab: needs --simulated")
        plan = (_campaign_file(every_pose) if every_pose is not None else CampaignCreate(
            name=f"{frames} frame(s) at {turntable_deg:g} deg",
            poses=[{"turntable_deg": turntable_deg, "solar_suns": suns, "repeats": frames}]))
        source = rig_scene(plan.scene) if isinstance(plan.scene, str) else (
            _inline_scene(plan.scene) if plan.scene is not None else rig_scene(scene))
        cal = load_calibration(calibration) if calibration is not None else None
    except InvalidInputError as exc:
        fail_invalid(exc)
    settings = rig_settings(simulated=simulated, reality=reality, camera_spp=camera_spp,
                            camera_integrator="path", camera_seed=seed)
    recorded = RecordedCampaign(
        name=plan.name, scene_name=source.name, scene=json.loads(source.to_json()),
        scene_base_dir=str(source.base_dir), mask=plan.mask.model_dump(mode="json"),
        seed=plan.seed, spp=plan.spp or settings.sim_spp,
        poses=[(p.turntable_deg, p.solar_suns, p.repeats) for p in plan.poses],
        calibration=None if cal is None else cal.model_dump(mode="json"),
        calibration_hash=None if cal is None else twin_hash(cal))
    writer = RecordingWriter(out, recorded)
    with open_command_rig(settings, source) as (rig, _world):
        try:
            n = _record(rig, writer, recorded, cal, settings.solar_stable_timeout_s)
        except DeviceError as exc:
            print_error(f"the rig failed: {exc}; the frames before it are in {out}")
            raise typer.Exit(code=1) from None
    console.print(f"{n} frame(s) of {len(recorded.poses)} pose(s) recorded in {out}")


def _record(rig: Any, writer: Any, recorded: Any, cal: Any, stable_timeout_s: float) -> int:
    """Each pose and repeat: move, capture one frame, append it with the state read back."""
    from drivers.rig import RigState
    from service.lab.settling import settled_moves
    from service.store.recording import RecordedUnit

    n = 0
    for index, (angle, suns, repeats) in enumerate(recorded.poses):
        target = RigState(angle, suns, shutter_open=suns > 0)
        for repeat in range(repeats):
            err_console.print(f"pose {index} ({angle:g} deg, {suns:g} sun), repeat {repeat}")
            with rig.hold(), settled_moves(rig, cal):
                state = rig.apply(target, wait_stable_s=stable_timeout_s if suns > 0 else None)
                raws = rig.capture(1, target=target)
                use_case = rig.camera.use_case.name
            writer.append(RecordedUnit(index, repeat, state, use_case, 0.0, raws))
            n += 1
    return n


def _campaign_file(path: Path) -> Any:
    """``--every-pose``: a campaign body, validated as the service validates it."""
    from pydantic import ValidationError

    from service.lab.requests import CampaignCreate

    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InvalidInputError("--every-pose", f"cannot read '{path}': {exc}") from None
    try:
        plan = CampaignCreate.model_validate_json(text)
    except ValidationError as exc:
        e = exc.errors()[0]
        where = ".".join(str(p) for p in e["loc"])
        raise InvalidInputError(f"--every-pose {where}".strip(), e["msg"]) from None
    if plan.source != "rig" or plan.turning_deg_s is not None or plan.object_fit is not None:
        raise InvalidInputError("--every-pose", "record takes stop-and-go poses of the rig "
                                "(no source, turning_deg_s or object_fit)")
    return plan


def _inline_scene(data: dict[str, Any]) -> Any:
    from service.lab.scenes import resolve_scene
    from service.settings import EXAMPLES_DIR

    return resolve_scene(data, EXAMPLES_DIR, max_objects=10000)


def replay_command(
    recording: Annotated[Path, typer.Argument(help="The recording (.h5) to replay.")],
    out: Annotated[Path, typer.Option("--out", help="Output folder (must not exist): the "
                                      "service data, results.csv, results.json, report.html.")],
    calibration: CalibrationOption = None,
    scene: Annotated[
        str | None, typer.Option(help="Bundled scene name or scene file, instead of the "
                                 "recorded scene.")
    ] = None,
    spp: Annotated[
        int | None, number_option("--spp", help="Samples per pixel of the simulations "
                                  "(default: the recording's).", allowed=ranges.REPLAY_SPP)
    ] = None,
    workers: Annotated[
        int | None, number_option("--workers", help="Simulation workers (default: the "
                                  "service's, TOFTWIN_WORKERS).", allowed=ranges.WORKERS)
    ] = None,
) -> None:
    """Compare every recorded frame with the twin again, offline: a campaign's results."""
    from service.lab.calibration import Twin
    from service.lab.campaigns import create_replay, recorded_scene
    from service.store import queries
    from service.store.recording import Recording
    from sim_core.twin_file import load_calibration, parse_twin

    try:
        if out.exists():
            raise InvalidInputError("--out", f"'{out}' exists; give a new folder")
        rec = Recording(recording)
        cal = (load_calibration(calibration) if calibration is not None else
               None if rec.campaign.calibration is None else parse_twin(rec.campaign.calibration))
    except InvalidInputError as exc:
        fail_invalid(exc)
    settings = load_settings(None, {**RIG_OPTION_OF_FIELD, "workers": "--workers"},
                             token=secrets.token_urlsafe(24), data_dir=out, workers=workers)
    with _replay_stack(settings) as (sessions, store, runner):
        try:
            source = rig_scene(scene) if scene is not None else recorded_scene(rec.campaign,
                                                                               settings)
            cid = create_replay(sessions, rec, settings.data_dir,
                                name=f"replay of {recording.name}",
                                scene=source, twin=Twin.of(cal), spp=spp)
        except InvalidInputError as exc:
            fail_invalid(exc)
        runner.start(cid)
        runner.wait()
        _write_results(sessions, store, cid, out)
        with sessions() as s:
            row = queries.require_campaign(s, cid)
            state, error, done = row.state, row.error, len(queries.done_units(s, cid))
    if state != "completed":
        print_error(f"the replay ended {state}: {error}; {done} unit(s) compared, in {out}")
        raise typer.Exit(code=1)
    console.print(f"{done} frame(s) of {recording.name} compared: {out / RESULTS_CSV}, "
                  f"{out / REPORT_HTML} (campaign {cid} in {out})")


def _replay_stack(settings: Any) -> Any:
    """The service's database, frame store, executor and campaign runner in ``settings``'s data
    directory, with no rig (a replay needs none); closed when the block is left."""
    import contextlib

    from service.compute.executors import make_executor
    from service.lab.background import BackgroundRunner
    from service.lab.rig_lease import RigLease
    from service.lab.runner import CampaignRunner
    from service.store.database import init_db, make_engine
    from service.store.frame_files import FrameStore

    @contextlib.contextmanager
    def stack() -> Any:
        Path(settings.data_dir).mkdir(parents=True)
        engine = make_engine(settings.database)
        executor = make_executor(settings.executor, settings.workers, settings.threads_per_job,
                                 settings.dask_address)
        try:
            sessions = init_db(engine)
            store = FrameStore(Path(settings.data_dir) / "frames")
            background = BackgroundRunner(RigLease(None, "a replay uses no rig",
                                                   settings.rig_wait_s), settings.stop_wait_s)
            yield sessions, store, CampaignRunner(sessions, background, store, executor,
                                                  settings)
        finally:
            executor.close()
            engine.dispose()

    return stack()


def _write_results(sessions: Any, store: Any, cid: str, out: Path) -> None:
    from service.export.report import campaign_report
    from service.export.results_table import result_rows, results_csv
    from sim_core.files import atomic_write

    rows = result_rows(sessions, cid)
    atomic_write(out / RESULTS_CSV, "".join(results_csv(rows)))
    atomic_write(out / RESULTS_JSON, json.dumps(rows, indent=1, allow_nan=False) + "\n")
    atomic_write(out / REPORT_HTML, campaign_report(sessions, store, cid))
