"""The object fit with a view its model cannot explain: left out with its reason, the others
fitted without it (issue 27: a view the model cannot explain is dropped with its reason, or the
parameters it drives are marked)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from calibration.angles import parse_angles
from calibration.object_twin.fit import fit_object
from calibration.object_twin.plan import captures_in_order, object_fit_capture_plan
from calibration.verdicts import CHI2_UNEXPLAINED
from service.cli.command_settings import open_command_rig, rig_settings
from service.cli.common import rig_scene
from service.lab.acquisition import NO_MOUNTS, acquire
from tests.calibration.realities import perfect_calibration, random_reality

NAMES = ["body", "panel_left", "panel_right", "pedestal"]
ANGLES = "-40,-10,20,50"
#: the view the lamp lit brighter than the others, and by how much
GLITCH, GLITCH_GAIN = 3, 1.3


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_a_view_the_model_cannot_explain_is_left_out_with_its_reason(
        tmp_path, monkeypatch):
    # render noise a quarter of the sensor's (tests/service/cli/test_fit_object.py says why)
    monkeypatch.setenv("TOFTWIN_CAMERA_NOISE_FRACTION", "0.25")
    reality = random_reality(146, object_twin_names=NAMES)
    (tmp_path / "reality.yaml").write_text(json.dumps(reality.model_dump(mode="json")))
    calibration = perfect_calibration(reality)
    plan = object_fit_capture_plan(parse_angles(ANGLES, field="angles"), 8)
    source = rig_scene("satellite_ground_test")
    settings = rig_settings(simulated=True, reality=tmp_path / "reality.yaml", camera_spp=32,
                            camera_integrator="path", camera_seed=3)
    with open_command_rig(settings, source) as (rig, _world):
        captures = captures_in_order(plan, acquire(rig, NO_MOUNTS, plan, lambda *_: None,
                                                   settle_for=calibration))
    # the illumination 30 % brighter for one view (a power glitch no twin knows of): its
    # ranges are right, its amplitudes are not
    c = captures[GLITCH]
    captures[GLITCH] = dataclasses.replace(
        c, phase_images=c.phase_images * GLITCH_GAIN, intensity=c.intensity * GLITCH_GAIN,
        intensity_std=c.intensity_std * GLITCH_GAIN, amplitude=c.amplitude * GLITCH_GAIN)
    glitch_deg = c.turntable_angle_deg

    fit = fit_object(source.spec, source.base_dir, calibration, captures)

    report = fit.report
    said = json.dumps({k: report.get(k) for k in ("refined", "dropped_views",
                                                  "with_every_view")}, default=str)[:3000]
    assert [d["turntable_angle_deg"] for d in report["dropped_views"]] == [glitch_deg], said
    assert "does not explain this view" in report["dropped_views"][0]["reason"]
    every = report["with_every_view"]["refined"]["reduced_chi2_per_view"]
    assert every[GLITCH] > CHI2_UNEXPLAINED
    assert len(report["refined"]["reduced_chi2_per_view"]) == len(captures) - 1
    # what the refit would claim determined is unexplained: a cause that fails one view may
    # bias the others too (calibration.object_twin.judgement.after_dropped_views); the
    # estimate of the three other views is still the target away at most
    for key in ("mount.pose_offset.position_m", "mount.pose_offset.rotation_deg"):
        verdict = fit.verdicts[key]
        assert not verdict.determined
        assert verdict.verdict == "not determined" or f"{glitch_deg:+g} deg" in verdict.reason
    truth = reality.mount.pose_offset
    pose = fit.object_twin.mount.pose_offset
    assert np.max(np.abs(np.subtract(pose.position_m, truth.position_m))) < 1e-3
    assert np.max(np.abs(np.subtract(pose.rotation_deg, truth.rotation_deg))) < 0.2
