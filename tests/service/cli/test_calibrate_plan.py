"""The same calibration plan from the command line and the service for the same inputs.

``toftwin calibrate rig --print-plan`` (its options through typer, as an operator types them)
against ``POST /calibrations``' request model (:class:`service.lab.requests.CalibrationCreate`,
whose :meth:`plan` the job runs): both refuse, or both give the same plan to the bit.
"""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError
from typer.testing import CliRunner

from service.cli import app
from service.lab.requests import CalibrationCreate
from sim_core.errors import InvalidInputError

REFUSED = "refused"


def cli_plan(out, sweep_from=None, sweep_to=None, sweep_step=None, frames_per_view=None,
             solar_reference_suns=None, warmup=None, settling=None) -> dict | str:
    """The plan ``toftwin calibrate rig --print-plan`` prints, or REFUSED (exit code 2)."""
    args = ["calibrate", "rig", "--simulated", "--out", str(out), "--print-plan"]
    for option, v in (("--sweep-from", sweep_from), ("--sweep-to", sweep_to),
                      ("--sweep-step", sweep_step), ("--frames-per-view", frames_per_view),
                      ("--solar-reference-suns", solar_reference_suns)):
        if v is not None:
            args += [option, repr(v)]
    for name, on in (("warmup", warmup), ("settling", settling)):
        if on is not None:
            args.append(f"--{'' if on else 'no-'}{name}")
    res = CliRunner().invoke(app, args)
    if res.exit_code == 2:
        return REFUSED
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def service_plan(sweep_from=None, sweep_to=None, sweep_step=None, frames_per_view=None,
                 solar_reference_suns=None, warmup=None, settling=None) -> dict | str:
    """The plan of ``POST /calibrations`` with the same inputs, or REFUSED (a 422)."""
    sweep = {k: v for k, v in (("from_deg", sweep_from), ("to_deg", sweep_to),
                               ("step_deg", sweep_step)) if v is not None}
    body = {k: v for k, v in (("sweep", sweep or None), ("frames_per_view", frames_per_view),
                              ("solar_reference_suns", solar_reference_suns),
                              ("warmup_stage", warmup), ("settling_stage", settling))
            if v is not None}
    try:
        plan = CalibrationCreate.model_validate(json.loads(json.dumps(body))).plan()
    except (ValidationError, InvalidInputError):
        return REFUSED
    return json.loads(json.dumps(plan.summary()))


@pytest.mark.parametrize("inputs", [
    {},  # the defaults: -55 ... 55 every 5 deg, 4 frames
    {"sweep_step": 10.0},
    {"sweep_from": -30.0, "sweep_to": 30.0, "sweep_step": 20.0, "frames_per_view": 1},
    {"sweep_step": 2.2},  # the CLI summed -55 + i * 2.2 unrounded; the service rounded
    {"sweep_step": 0.5},  # the CLI refused below 1 deg, the service took it
    {"sweep_step": 45.0},  # three angles: the CLI refused above 30 deg, the service took it
    {"sweep_step": 60.0},  # two angles: both refuse
    {"sweep_step": 95.0},
    {"sweep_from": 10.0, "sweep_to": -10.0},
    {"sweep_from": -360.0, "sweep_to": 360.0, "sweep_step": 0.5},  # 1441 angles
    {"solar_reference_suns": 0.005},  # the CLI took it, the service refused
    {"solar_reference_suns": 7.0},  # the service took it, the sequence refused it at its end
    {"frames_per_view": 65},
    {"warmup": False},  # a camera already warm: no warm-up stage
    {"settling": False, "warmup": True},
    {"warmup": False, "settling": False, "sweep_step": 10.0},
])
def test_the_cli_and_the_service_give_the_same_plan(tmp_path, inputs):
    from_cli = cli_plan(tmp_path / "out", **inputs)
    assert from_cli == service_plan(**inputs)
    assert not (tmp_path / "out").exists()  # --print-plan writes nothing
    if from_cli != REFUSED:  # a stage left out has no captures; one kept, the default's
        assert (from_cli["warmup_captures"] == 0) == (inputs.get("warmup") is False)
        assert (from_cli["settling_frames"] == 0) == (inputs.get("settling") is False)


finite = {"allow_nan": False, "allow_infinity": False}


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sweep_from=st.none() | st.floats(-400, 400, **finite),
       sweep_to=st.none() | st.floats(-400, 400, **finite),
       sweep_step=st.none() | st.floats(0.1, 100, **finite),
       frames_per_view=st.none() | st.integers(0, 70),
       solar_reference_suns=st.none() | st.floats(0, 6, **finite))
def test_random_inputs_give_the_same_plan_or_the_same_refusal(
        tmp_path, sweep_from, sweep_to, sweep_step, frames_per_view, solar_reference_suns):
    inputs = {"sweep_from": sweep_from, "sweep_to": sweep_to, "sweep_step": sweep_step,
              "frames_per_view": frames_per_view, "solar_reference_suns": solar_reference_suns}
    from_cli = cli_plan(tmp_path / "out", **inputs)
    assert from_cli == service_plan(**inputs), inputs
    event("refused" if from_cli == REFUSED else "planned")  # --hypothesis-show-statistics
    if from_cli != REFUSED:
        angles = from_cli["sweep_deg"]
        assert 3 <= len(angles) <= 721 and all(math.isfinite(a) for a in angles)
