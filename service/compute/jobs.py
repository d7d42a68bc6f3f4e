"""Simulation jobs: everything a worker needs travels with the job; arrays come back.

A :class:`SimulationJob` holds the scene spec as JSON-able data, the bytes of every mesh file
it references, the rig state to pose it for and the render settings. :func:`run_job` runs in a
worker process (a local pool or a Dask worker on another machine): it writes the meshes to a
temporary folder, builds the scene, simulates, and returns a :class:`SimulationResult`: the
frame's files as :func:`~sim_core.pipeline.save_frame` writes them (compressed ``.npz`` arrays,
``frame.json``, PNG previews - compressing on the worker keeps that cost off the service) and
the arrays the comparison needs (the reconstructed image and the object ids).

The same job gives the same frame bit for bit on any worker: the seed is in the job and the
renderer's results do not depend on the number of threads.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sim_core.render_request import RenderRequest
from sim_core.scene_spec import SceneSpec

#: One render at a time per process: every render in this process - jobs on a threaded executor
#: or a multi-threaded Dask worker, and the simulated camera's frames
#: (:func:`service.lab.rig_builder.open_rig`) - takes this lock. A render already uses all
#: cores, so two at once would only compete. (sim_core is thread-safe on its own: its few
#: parallel numba kernels, which numba's ``workqueue`` layer cannot run from two threads at
#: once, take :data:`sim_core.numba_runtime.PARALLEL_KERNEL_LOCK`.)
RENDER_LOCK = threading.Lock()


@dataclass(frozen=True)
class SimulationJob:
    """One frame to simulate.

    Attributes
    ----------
    scene : dict
        ``SceneSpec.model_dump(mode="json")``; file mesh paths are keys of ``meshes``.
    meshes : dict of str to bytes
        Contents of every mesh file, keyed by the path as written in the spec.
    turntable_deg : float or None
        Turntable angle to pose the scene for [deg] (None: the spec's).
    solar_suns : float or None
        Solar simulator level reaching the scene [sun]; 0 with the shutter closed.
    request : RenderRequest
        The render, whole (:class:`sim_core.render_request.RenderRequest`: settings with the
        worker's threads, accuracy target, effects, ideal sensor).
    scene_name : str
    extra : dict
        Written into the frame's ``frame.json`` (rig state, object names, ...).
    twin : dict or None
        The calibration to apply (``CalibrationFile.model_dump(mode="json")``, or a calibration
        combined with an object twin: :func:`sim_core.twin_file.parse_twin`), resolved by the
        service (its active calibration, the scene's own files, a campaign's fitted object);
        None: nominal. The worker never reads a twin file itself: the scene's ``calibration``
        and ``object_twin`` keys are ignored here.
    """

    scene: dict[str, Any]
    meshes: dict[str, bytes]
    turntable_deg: float | None
    solar_suns: float | None
    request: RenderRequest
    scene_name: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    twin: dict[str, Any] | None = None
    #: contents of the goniometer tables of tabulated materials, keyed by ``params.table``
    tables: dict[str, bytes] = field(default_factory=dict)
    #: the turntable's speed while the frame is taken [deg/s] (0: at rest): ``turntable_deg``
    #: is then its angle at the frame's start and each phase step is rendered at its own
    #: angle (:func:`sim_core.pipeline.simulate_in_motion`), as the camera took it
    turntable_speed_deg_s: float = 0.0
    #: the measured frame's reported illumination temperature [degC]: a twin with
    #: ``camera.temperature`` applies its drift at it (None: not reported, no drift)
    illumination_temperature_c: float | None = None


def _material_specs(spec: SceneSpec):
    """Every ``MaterialSpec`` of the scene's objects (boards bring two)."""
    from sim_core.scene_spec import MaterialSpec

    for obj in spec.objects:
        for m in (obj.material, getattr(obj.mesh, "black", None),
                  getattr(obj.mesh, "white", None)):
            if isinstance(m, MaterialSpec):
                yield m


def make_job(
    spec: SceneSpec,
    base_dir: Path,
    *,
    turntable_deg: float | None,
    solar_suns: float | None,
    request: RenderRequest,
    scene_name: str = "",
    extra: dict[str, Any] | None = None,
    twin: dict[str, Any] | None = None,
    turntable_speed_deg_s: float = 0.0,
    illumination_temperature_c: float | None = None,
) -> SimulationJob:
    """A job for ``spec`` posed at the given rig state, rendered as ``request`` asks, with its
    mesh and table files packed in."""
    from sim_core.scene import inline_material_files

    spec = inline_material_files(spec, base_dir)  # the worker has not the scene's folder
    meshes: dict[str, bytes] = {}
    for obj in spec.objects:
        if obj.mesh.kind == "file":
            p = Path(obj.mesh.path)
            meshes[obj.mesh.path] = (p if p.is_absolute() else Path(base_dir) / p).read_bytes()
    tables: dict[str, bytes] = {}
    for m in _material_specs(spec):
        table = m.params.get("table") if m.kind == "tabulated" else None
        if isinstance(table, str) and table not in tables:
            p = Path(table)
            tables[table] = (p if p.is_absolute() else Path(base_dir) / p).read_bytes()
    return SimulationJob(
        scene=spec.model_dump(mode="json"),
        meshes=meshes,
        tables=tables,
        turntable_deg=turntable_deg,
        solar_suns=solar_suns,
        request=request,
        scene_name=scene_name,
        extra=dict(extra or {}),
        twin=twin,
        turntable_speed_deg_s=turntable_speed_deg_s,
        illumination_temperature_c=illumination_temperature_c,
    )


@dataclass
class SimulationResult:
    """What comes back from a worker.

    Attributes
    ----------
    files : dict of str to bytes
        ``frame.npz``, ``frame.json``, ``grey.png``, ``depth.png`` and ``raw.npz``.
    image : ToFImage
        The simulated frame's reconstruction (compared with the measured one).
    object_id : (H, W) int32
        Object index per pixel (-1: none), for the simulator's object mask.
    scene_hash : str
    effect_plan : dict
    timings_s : dict
        The simulation's stage timings (``total`` included) and ``save`` (writing the files).
    worker : str
        Host and process that ran the job.
    grey_full_scale : float
        The frame's grey full scale (``grey_preview_full_scale`` of its ``frame.json``).
    """

    files: dict[str, bytes]
    image: Any
    object_id: Any
    scene_hash: str
    effect_plan: dict[str, Any]
    timings_s: dict[str, float]
    worker: str
    grey_full_scale: float = 0.0


def _local_tables(obj: dict[str, Any], tables: dict[str, bytes], folder: Path) -> dict:
    """``obj`` (scene JSON) with its tabulated materials' tables written to ``folder`` and
    named by their local file."""

    def local(m: Any) -> Any:
        if not isinstance(m, dict) or m.get("kind") != "tabulated":
            return m
        table = (m.get("params") or {}).get("table")
        if table not in tables:
            return m
        name = f"table_{hashlib.sha256(table.encode()).hexdigest()[:12]}.csv"
        (folder / name).write_bytes(tables[table])
        return {**m, "params": {**m["params"], "table": name}}

    out = {**obj, "material": local(obj.get("material"))}
    mesh = obj.get("mesh", {})
    if isinstance(mesh, dict) and ("black" in mesh or "white" in mesh):
        out["mesh"] = {**mesh, **{k: local(mesh[k]) for k in ("black", "white") if k in mesh}}
    return out


def _step_scenes(job: SimulationJob, spec: Any, folder: str, built: Any, twin: Any):
    """For a frame taken while the table turns: each phase step's angle (n_f, 4) and the scene
    posed at each (keyed by the angle rounded to 1e-9 deg); None at rest or when the turn
    during the frame is below the tolerance (one render)."""
    from sim_core.scene import build_scene
    from sim_core.subframes import moves_during_frame, phase_step_angles_deg

    if job.turntable_speed_deg_s == 0.0:
        return None
    start_deg = (job.turntable_deg if job.turntable_deg is not None
                 else (spec.turntable.angle_deg if spec.turntable else 0.0))
    cam = built.camera
    angles = phase_step_angles_deg(lambda dt: start_deg + job.turntable_speed_deg_s * dt,
                                   len(cam.modulation_frequencies_hz), cam.exposure_s)
    if not moves_during_frame(angles):
        return None
    scenes = {round(float(a), 9): build_scene(
                  spec, folder, turntable_deg=float(a), solar_suns=job.solar_suns, twin=twin,
                  illumination_temperature_c=job.illumination_temperature_c)
              for a in angles.ravel()}
    return angles, scenes


def run_job(job: SimulationJob) -> SimulationResult:
    """Simulate ``job`` on this worker."""
    import socket
    import time

    from sim_core.pipeline import save_frame, simulate, simulate_in_motion
    from sim_core.scene import build_scene
    from sim_core.scene_spec import parse_scene_spec
    from sim_core.twin_file import parse_twin

    twin = None if job.twin is None else parse_twin(job.twin)
    with tempfile.TemporaryDirectory(prefix="toftwin-job-") as tmp:
        scene = dict(job.scene)
        # resolved by the service: ``job.twin`` (the calibration and the object twin)
        scene["calibration"] = scene["object_twin"] = None
        if job.meshes:
            objects = []
            for i, obj in enumerate(scene.get("objects", [])):
                mesh = obj.get("mesh", {})
                if mesh.get("kind") == "file":
                    local = Path(tmp) / f"{i}_{Path(mesh['path']).name}"
                    local.write_bytes(job.meshes[mesh["path"]])
                    obj = {**obj, "mesh": {**mesh, "path": local.name}}
                objects.append(obj)
            scene["objects"] = objects
        if job.tables:
            scene["objects"] = [_local_tables(obj, job.tables, Path(tmp))
                                for obj in scene.get("objects", [])]
        spec = parse_scene_spec(scene)
        built = build_scene(
            spec, tmp, turntable_deg=job.turntable_deg, solar_suns=job.solar_suns, twin=twin,
            illumination_temperature_c=job.illumination_temperature_c,
        )
        step_scenes = _step_scenes(job, spec, tmp, built, twin)
    with RENDER_LOCK:
        if step_scenes is None:
            frame = simulate(built, job.request)
        else:
            angles, scenes = step_scenes
            frame = simulate_in_motion(lambda a: scenes[round(a, 9)], angles, job.request)
    worker = f"{socket.gethostname()}:{os.getpid()}"
    frame.extra.update({"kind": "simulated", **job.extra, "worker": worker})
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="toftwin-frame-") as out:
        save_frame(out, frame, scene_name=job.scene_name)
        files = {p.name: p.read_bytes() for p in sorted(Path(out).iterdir()) if p.is_file()}
    timings = {k: float(v) for k, v in frame.timings_s.items()}
    timings["save"] = time.perf_counter() - t0
    return SimulationResult(
        files=files, image=frame.image, object_id=frame.light_field.object_id,
        scene_hash=frame.scene_hash, effect_plan=frame.plan.to_dict(), timings_s=timings,
        worker=worker, grey_full_scale=float(frame.grey_full_scale or 0.0),
    )


def warm_up(tabulated: bool = False) -> int:
    """Import the renderer and load its compiled kernels (the first frame would otherwise pay).

    ``bounce`` without code for tabulated materials (what most scenes need), and with
    ``tabulated`` its second compilation too, with that code
    (:attr:`sim_core.render.kernels.SceneTables.mat_data`). In a fresh install each is about a
    minute of compiling on a 2-core machine (63 and 77 s seen), afterwards numba's cache. The
    service warms the first only: a scene with a tabulated material pays the second once.
    """
    from dataclasses import replace

    from sim_core.materials import material_preset
    from sim_core.materials.idw import goniometer_measurement
    from sim_core.materials.tabulated import Tabulated
    from sim_core.pipeline import simulate
    from sim_core.render import RenderSettings
    from sim_core.render_request import RenderRequest
    from sim_core.scene import build_scene
    from sim_core.scene_spec import parse_scene_spec

    spec = parse_scene_spec(
        {
            "camera": {
                "pose": {"position_m": [0, 0, 0], "look_at_m": [0, 0, 1], "up": [0, -1, 0]},
                "width_px": 16,
                "height_px": 12,
            },
            "objects": [
                {
                    "name": "plane",
                    "mesh": {"kind": "rectangle", "size_m": [2, 2]},
                    "material": {"kind": "lambertian", "params": {"albedo": 0.5}},
                    "pose": {"position_m": [0, 0, 1], "rotation_deg": [180, 0, 0]},
                }
            ],
        }
    )
    scene = build_scene(spec)
    variants = [scene.materials]
    if tabulated:
        table = goniometer_measurement(material_preset("white-matte-tile"), 15.0,
                                       retro_gap_deg=0.0)
        variants.append((Tabulated(table),))
    request = RenderRequest(RenderSettings(integrator="path", spp=1, max_bounces=2, threads=1))
    with RENDER_LOCK:
        for materials in variants:
            simulate(replace(scene, materials=materials), request)
    return os.getpid()
