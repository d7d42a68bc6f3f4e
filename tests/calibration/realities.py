"""Random realities for the calibration round trips: plausible ranges, never one set of values.

Code under test never sees these: it gets frames from the simulated lab built with them.
"""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from sim_core.camera import CAMERA_PRESETS
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.geometry import rotation_matrix_xyz_deg
from sim_core.scene_spec import ObjectPose
from sim_core.twin_file import CalibrationFile, RealityFile, TwinParameters, parse_reality

PRESET = CAMERA_PRESETS["pmd-camboard-pico-flexx"]
#: range of a radian of phase at 60.24 MHz [m]
M_PER_RAD = SPEED_OF_LIGHT_M_S / (4.0 * np.pi * 60.24e6)


#: the environment variable that widens (or narrows) a round trip's set of realities
SEEDS_VARIABLE = "TOFTWIN_REALITY_SEEDS"


def reality_seeds(default: Sequence[int], variable: str = SEEDS_VARIABLE) -> list[int]:
    """The seeds a round trip draws its realities from: ``default`` (what CI runs), or the
    environment's ``TOFTWIN_REALITY_SEEDS`` as a list of seeds and ranges (``151-160,171``).

    CI's slow suite has a time budget: it runs a few realities per round trip, every run the
    same; a wider sweep is one variable away, e.g. ``TOFTWIN_REALITY_SEEDS=151-170 pytest -m
    slow tests/service/api/test_object_fit_realities.py``.

    >>> reality_seeds([1, 2], variable="TOFTWIN_NO_SUCH_VARIABLE")
    [1, 2]
    """
    text = os.environ.get(variable, "").strip()
    return parse_seeds(text, variable) if text else list(default)


def parse_seeds(text: str, field: str = "--seeds") -> list[int]:
    """Seeds and ranges (``151-160,171``) as a list; an error naming ``field`` otherwise.

    >>> parse_seeds("3-5,9")
    [3, 4, 5, 9]
    """
    seeds: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        try:
            first, last = int(lo), int(hi or lo)
        except ValueError:
            raise ValueError(
                f"{field}: {part!r} is not a seed or a range like 151-160") from None
        if not 0 <= first <= last or last - first > 10_000:
            raise ValueError(f"{field}: {part!r} is not an increasing range of seeds >= 0")
        seeds.extend(range(first, last + 1))
    return seeds


#: issue 14's object realities: mount offsets up to this per axis [m] and [deg], scales in range
OBJECT_OFFSET_M = 0.010
OBJECT_ROTATION_DEG = 2.0
REFLECTANCE_SCALES = (0.8, 1.2)


def random_reality(seed: int, nominal_power_w: float = 1.0, wiggling_mm: float = 15.0,
                   pattern_mm: float = 4.0, object_differences: bool = False,
                   object_twin_names: Sequence[str] = ()) -> RealityFile:
    """A reality drawn from plausible ranges (issue 13's round trip).

    ``object_twin_names`` (issue 14's object round trip): the mount's pose offset is drawn up to
    :data:`OBJECT_OFFSET_M` per axis and :data:`OBJECT_ROTATION_DEG` about each axis, and each
    named object gets a reflectance scale in :data:`REFLECTANCE_SCALES`; drawn from a stream of
    their own, so the other keys are those of the same seed without it. Overrides
    ``object_differences``' mount offset.
    """
    rng = np.random.default_rng(seed)
    u = rng.uniform
    tilt = np.radians(u(0.0, 1.5))
    azim = u(-np.pi, np.pi)
    axis = [float(np.sin(tilt) * np.cos(azim)), float(np.sin(tilt) * np.sin(azim)),
            float(np.cos(tilt))]
    data = {
        "camera": {
            "fx_px": float(PRESET["fx_px"] * u(0.97, 1.03)),
            "fy_px": float(PRESET["fy_px"] * u(0.97, 1.03)),
            "cx_px": float(PRESET["cx_px"] + u(-3.0, 3.0)),
            "cy_px": float(PRESET["cy_px"] + u(-3.0, 3.0)),
            "distortion": {"k1": float(u(-0.15, 0.05)), "k2": float(u(-0.05, 0.05)),
                           "p1": float(u(-1e-3, 1e-3)), "p2": float(u(-1e-3, 1e-3)), "k3": 0.0},
            "depth": {
                "phase_offset_rad": [float(u(-0.1, 0.1))],
                "wiggling": [{"harmonic": int(rng.integers(2, 5)),
                              "amplitude_rad": wiggling_mm * 1e-3 / M_PER_RAD,
                              "phase_rad": float(u(-np.pi, np.pi))}],
                "pixel_offset_m": {"sigma": pattern_mm * 1e-3, "correlation_px": float(u(8, 20)),
                                   "seed": int(rng.integers(0, 2**31))},
            },
            "sensor": {"adc_gain_e_per_dn": float(u(8.0, 40.0)),
                       "read_noise_e": float(u(15.0, 50.0))},
        },
        "illumination": {"power_w": float(nominal_power_w * u(0.8, 1.3))},
        "turntable": {"axis_point_m": [float(u(-0.005, 0.005)), float(u(-0.005, 0.005)), 0.0],
                      "axis_direction": axis, "zero_offset_deg": float(u(-1.0, 1.0))},
        "solar_simulator": {"irradiance_scale": float(u(0.9, 1.15))},
    }
    if object_differences:
        data["mount"] = {"pose_offset": {"position_m": [float(u(-3e-3, 3e-3)) for _ in range(3)],
                                         "rotation_deg": [0.0, 0.0, float(u(-1.0, 1.0))]}}
    if object_twin_names:
        v = np.random.default_rng([seed, 14]).uniform
        data["mount"] = {"pose_offset": {
            "position_m": [float(v(-OBJECT_OFFSET_M, OBJECT_OFFSET_M)) for _ in range(3)],
            "rotation_deg": [float(v(-OBJECT_ROTATION_DEG, OBJECT_ROTATION_DEG))
                             for _ in range(3)]}}
        data["objects"] = {name: {"reflectance_scale": float(v(*REFLECTANCE_SCALES))}
                           for name in object_twin_names}
    return parse_reality(data)


def perfect_calibration(reality: RealityFile) -> CalibrationFile:
    """The calibration a perfect rig calibration would give: the reality's camera and rig keys
    (camera, illumination, turntable, solar simulator) only, never its object keys (mount pose,
    reflectance), which the object fit must estimate from the frames."""
    return CalibrationFile(**{k: getattr(reality, k) for k in TwinParameters.model_fields})


def pose_errors(fitted: ObjectPose, truth: ObjectPose) -> tuple[float, float]:
    """A fitted mount offset's position error [m] and the angle of its rotation error [deg]."""
    dp = np.linalg.norm(np.subtract(fitted.position_m, truth.position_m))
    dr = rotation_matrix_xyz_deg(fitted.rotation_deg) @ rotation_matrix_xyz_deg(
        truth.rotation_deg).T
    angle = np.degrees(np.arccos(np.clip((np.trace(dr) - 1.0) / 2.0, -1.0, 1.0)))
    return float(dp), float(angle)


#: issue 27's camera effects: plausible ranges of the warm-up drift and the stray light
DRIFT_MM_PER_C = (0.1, 1.0)
ILLUMINATION_START_C = 25.0
ILLUMINATION_END_C = 45.0
WARMUP_TIME_CONSTANT_S = (300.0, 1200.0)
STRAY_LIGHT_FRACTION = (0.005, 0.03)
STRAY_LIGHT_RADIUS_PX = (20.0, 80.0)


def random_camera_effects(seed: int) -> dict:
    """Issue 27's camera keys drawn at random: ``{"temperature": ..., "stray_light": ...}``.

    The illumination warms from 25 to 45 degC with a time constant in
    :data:`WARMUP_TIME_CONSTANT_S`, the range drifts by :data:`DRIFT_MM_PER_C` per degree (of
    either sign: a real camera's drift may shorten or lengthen), one number for every frequency;
    the stray light takes a fraction in :data:`STRAY_LIGHT_FRACTION` with a kernel radius in
    :data:`STRAY_LIGHT_RADIUS_PX`. Drawn from a stream of its own (``[seed, 27]``).
    """
    v = np.random.default_rng([seed, 27]).uniform
    drift = float(v(*DRIFT_MM_PER_C)) * (1.0 if v() < 0.5 else -1.0)
    return {
        "temperature": {"illumination_start_c": ILLUMINATION_START_C,
                        "illumination_end_c": ILLUMINATION_END_C,
                        "time_constant_s": float(v(*WARMUP_TIME_CONSTANT_S)),
                        "depth_drift_mm_per_c": drift},
        "stray_light": {"fraction": float(v(*STRAY_LIGHT_FRACTION)),
                        "kernel_radius_px": float(v(*STRAY_LIGHT_RADIUS_PX))},
    }


def with_camera_effects(reality: RealityFile, seed: int) -> RealityFile:
    """``reality`` with issue 27's camera effects of ``seed`` (:func:`random_camera_effects`)."""
    data = reality.model_dump(mode="json", exclude_defaults=True)
    data.setdefault("camera", {}).update(random_camera_effects(seed))
    return parse_reality(data)


#: issue 27's turntable settling: plausible ranges of the table's ringing after a move
SETTLING_AMPLITUDE_DEG = (0.1, 0.8)
SETTLING_FREQUENCY_HZ = (1.0, 6.0)
SETTLING_DAMPING_RATIO = (0.03, 0.2)


def random_settling(seed: int) -> dict:
    """Issue 27's ``turntable.settling`` drawn at random (a stream of its own, ``[seed, 2727]``):
    amplitude, natural frequency and damping ratio in :data:`SETTLING_AMPLITUDE_DEG`,
    :data:`SETTLING_FREQUENCY_HZ` and :data:`SETTLING_DAMPING_RATIO`."""
    v = np.random.default_rng([seed, 2727]).uniform
    return {"amplitude_deg": float(v(*SETTLING_AMPLITUDE_DEG)),
            "frequency_hz": float(v(*SETTLING_FREQUENCY_HZ)),
            "damping_ratio": float(v(*SETTLING_DAMPING_RATIO))}


def with_world_effects(reality: RealityFile, seed: int) -> RealityFile:
    """``reality`` with all three of issue 27's effects of ``seed``: the camera's warm-up drift
    and stray light (:func:`random_camera_effects`) and the table's settling
    (:func:`random_settling`)."""
    data = with_camera_effects(reality, seed).model_dump(mode="json", exclude_defaults=True)
    data.setdefault("turntable", {})["settling"] = random_settling(seed)
    return parse_reality(data)


def resumable_sweep(seeds: str, out: Path, run_seed: Callable[[int, Path], dict],
                    table: Callable[[list[dict]], str]) -> list[dict]:
    """Issue 27's sweeps (``tests.calibration.verdict_sweep``, ``rig_sweep``): ``run_seed`` for
    every seed of ``seeds`` (seeds and ranges, :func:`parse_seeds`) into
    ``out/<seed>``, each line of ``table`` printed as its seed ends; a seed whose
    ``summary.json`` exists is read, not run again. The summaries, in the seeds' order."""
    summaries: list[dict] = []
    for seed in parse_seeds(seeds):
        path = out / str(seed) / "summary.json"
        if path.exists():
            summaries.append(json.loads(path.read_text()))
        else:
            summaries.append(run_seed(seed, out / str(seed)))
        print(table(summaries[-1:]).splitlines()[-1], flush=True)
    print(table(summaries))
    return summaries


def sweep_main(argv: list[str] | None, description: str, table: Callable[[list[dict]], str],
               failed: Callable[[dict], bool],
               run_seed_of: Callable[[argparse.Namespace], Callable[[int, Path], dict]],
               more_arguments: Callable[[argparse.ArgumentParser], None] | None = None) -> int:
    """A sweep's command line (``--seeds``, ``--out`` and ``more_arguments``'s):
    :func:`resumable_sweep` with the seed runner ``run_seed_of`` makes from the arguments; exit
    status 1 when ``failed`` holds for any row of any seed."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--seeds", default="201-220", help="seeds and ranges, e.g. 201-220,230")
    parser.add_argument("--out", type=Path, required=True)
    if more_arguments is not None:
        more_arguments(parser)
    args = parser.parse_args(argv)
    summaries = resumable_sweep(args.seeds, args.out, run_seed_of(args), table)
    return 1 if any(failed(r) for s in summaries for r in s["rows"]) else 0
