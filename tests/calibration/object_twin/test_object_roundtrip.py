"""The object fit on the simulated lab recovers a hidden, randomly drawn object reality.

Issue 14's must-show: a reality with the mount up to 10 mm and 2 deg off and reflectance scales
in 0.8-1.2; the rig counts as calibrated (:func:`tests.calibration.realities.
perfect_calibration`: the reality's camera and rig keys, never its object keys); the frames come
only from the simulated lab. Each reality takes minutes (renders for the refinement).
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.captures import average_frames
from calibration.object_twin.fit import fit_object
from drivers.rig import Rig, RigState
from drivers.sim.world import SimulatedWorld
from sim_core.geometry import rotation_matrix_xyz_deg
from sim_core.render import RenderSettings
from sim_core.scene_spec import load_scene_spec
from tests.calibration.realities import perfect_calibration, random_reality
from tests.sim_core.scenes import EXAMPLES

pytestmark = [pytest.mark.slow, pytest.mark.timeout(3600)]

SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
MOUNTED = tuple(o.name for o in SPEC.objects if o.on_turntable)
#: issue 14's targets
POSITION_M, ROTATION_DEG, SCALE_REL = 0.001, 0.2, 0.03
ANGLES_DEG = (-60.0, -30.0, 0.0, 30.0, 60.0)
FRAMES = 32


def capture_views(reality, seed, angles=ANGLES_DEG, frames=FRAMES):
    """Averaged frames of the mounted object at ``angles`` from the simulated lab."""
    world = SimulatedWorld(SPEC, EXAMPLES, RenderSettings(integrator="path", spp=32,
                                                          max_bounces=2), reality=reality)
    with Rig.simulated(frame_source=world, seed=seed) as rig:
        caps = []
        for a in angles:
            rig.apply(RigState(a, 0.0, False))
            caps.append(average_frames(rig.capture(frames)))
    return caps


def pose_errors(fitted, truth) -> tuple[float, float]:
    """Position error [m] and the angle of the rotation error [deg]."""
    dp = np.linalg.norm(np.subtract(fitted.position_m, truth.position_m))
    dr = rotation_matrix_xyz_deg(fitted.rotation_deg) @ rotation_matrix_xyz_deg(
        truth.rotation_deg).T
    angle = np.degrees(np.arccos(np.clip((np.trace(dr) - 1.0) / 2.0, -1.0, 1.0)))
    return float(dp), float(angle)


@pytest.mark.parametrize("seed", [141, 142, 143, 144, 145])
def test_object_fit_recovers_a_random_object_reality(seed):
    reality = random_reality(seed, nominal_power_w=SPEC.illumination.power_w,
                             object_twin_names=MOUNTED)
    calibration = perfect_calibration(reality)
    assert calibration.model_dump().keys().isdisjoint({"mount", "objects"})
    fit = fit_object(SPEC, EXAMPLES, calibration, capture_views(reality, seed))
    dp, dr = pose_errors(fit.object_twin.mount.pose_offset, reality.mount.pose_offset)
    objects = fit.report["objects"]
    scale_err = {n: e["reflectance_scale"] / reality.objects[n].reflectance_scale - 1.0
                 for n, e in objects.items() if e["determined"]}
    print(f"object round trip {seed}: position {dp * 1e3:.2f} mm, rotation {dr:.3f} deg, "
          f"scales {({n: round(v, 4) for n, v in scale_err.items()})}, "
          f"{fit.report['seconds']['total']:.0f} s")
    for name in ("body", "panel_left", "panel_right"):
        assert objects[name]["determined"], objects[name]
    assert dp <= POSITION_M, fit.report["refined"]
    assert dr <= ROTATION_DEG, fit.report["refined"]
    for name, err in scale_err.items():
        assert abs(err) <= SCALE_REL, (name, objects[name])
