"""Every numeric option of every command has an allowed range: a value outside it exits with
code 2 and a message on stderr naming the option and the range; nothing runs."""

from __future__ import annotations

import contextlib
import io
import math

import pytest
import typer
from typer.testing import CliRunner

from service.cli.common import Range
from tests.service.cli.commands import NumericOption, numeric_options
from toftwin_cli import app

OPTIONS = numeric_options()
#: the app as click runs it, built once (typer builds it anew for every CliRunner call)
COMMAND = typer.main.get_command(app)


def _refusal(args: list[str]) -> Exception:
    """The error the command line stops with for ``args`` (what click prints on stderr with
    exit code ``exit_code``); the tests below check the printing itself once."""
    try:
        COMMAND.main(args=args, prog_name="toftwin", standalone_mode=False)
    except Exception as exc:
        return exc
    raise AssertionError(f"toftwin {' '.join(args)} was accepted")


def _outside(r: Range, kind: type) -> list[float]:
    """Values just outside ``r`` on both sides (the open end itself where an end is open)."""
    step = 1 if kind is int else max(1e-3 * abs(r.hi - r.lo), 1e-6)
    lo = r.lo if r.lo_open else r.lo - step
    hi = r.hi if r.hi_open else r.hi + step
    return [v for v in (lo, hi) if v not in r.also]


def _cases() -> list[tuple[NumericOption, str]]:
    cases = []
    for opt in OPTIONS:
        if opt.allowed is None:  # test_every_numeric_option_has_a_range reports it
            continue
        values = _outside(opt.allowed, opt.kind)
        cases += [(opt, str(int(v) if opt.kind is int else v)) for v in values]
        if opt.kind is float:
            cases += [(opt, "nan"), (opt, "inf")]
    return cases


def test_the_walk_finds_the_options_of_commands_and_sub_commands():
    names = {str(o) for o in OPTIONS}
    for expected in ("simulate --spp", "simulate --turntable-deg", "serve --port",
                     "serve --workers", "bench campaign --poses", "bench render --spp",
                     "calibrate rig --sweep-step", "calibrate brdf --wavelength-nm",
                     "devices check --turntable-address", "fit-object --frames",
                     "compare --near-m", "preview --scale"):
        assert expected in names, sorted(names)


@pytest.mark.parametrize("opt", OPTIONS, ids=str)
def test_every_numeric_option_has_a_range(opt):
    assert opt.allowed is not None, f"{opt} has no allowed range (service.cli.common.number_option)"
    assert math.isfinite(opt.allowed.lo) and math.isfinite(opt.allowed.hi)
    assert opt.allowed.lo < opt.allowed.hi


@pytest.mark.parametrize(("opt", "value"), _cases(), ids=lambda x: str(x))
def test_a_value_outside_the_range_exits_2_naming_the_option_and_the_range(opt, value):
    exc = _refusal([*opt.command, opt.name, value])
    assert getattr(exc, "exit_code", None) == 2, repr(exc)
    message = exc.format_message()
    assert f"'{opt.name}'" in message and f"is outside {opt.allowed}" in message, message


@pytest.mark.parametrize("args", [["bench", "campaign", "--poses", "-1"],
                                  ["simulate", "--turntable-deg", "nan"],
                                  ["serve", "--port", "70000"]])
def test_the_refusal_is_printed_on_stderr_with_exit_code_2(args):
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2 and res.stdout == ""
    err = " ".join(res.stderr.split())
    assert f"Invalid value for '{args[-2]}': " in err and "is outside" in err, err


def test_the_issue_example_bench_campaign_poses_minus_one():
    res = CliRunner().invoke(app, ["bench", "campaign", "--poses", "-1"])
    assert "Invalid value for '--poses': -1 is outside [1, 720]" in " ".join(res.stderr.split())


@pytest.mark.parametrize("command", sorted({o.command for o in OPTIONS}), ids=" ".join)
def test_the_help_states_each_range(command):
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        COMMAND.main(args=[*command, "--help"], prog_name="toftwin", standalone_mode=False)
    text = " ".join(out.getvalue().split())
    for opt in OPTIONS:
        if opt.command == command:
            assert f"{opt.name} " in text and f"Allowed: {opt.allowed}." in text, (opt, text)


def test_a_value_inside_a_range_with_an_extra_value_is_taken():
    r = Range(0.8, 1.2, unit="sun", also=(0.0,))
    assert [r.contains(v) for v in (0.0, 0.8, 1.2, 0.5, 1.3)] == [True, True, True, False, False]
    assert str(r) == "[0.8, 1.2] sun or 0"


def _refused(make, value) -> bool:
    """Whether the home refuses ``value`` (any validation error)."""
    try:
        make(value)
    except (ValueError, TypeError):  # pydantic's ValidationError, InvalidInputError
        return True
    return False


def _edges(r: Range, kind: type = float) -> tuple[list[float], list[float]]:
    """(values at the closed ends, values just outside or at the open ends)."""
    inside = [v for v, is_open in ((r.lo, r.lo_open), (r.hi, r.hi_open)) if not is_open]
    return inside, _outside(r, kind)


def _copies():
    """Each range the command line copies, and how its home is asked about one value."""
    from calibration.brdf.fit import FitSettings
    from calibration.rig_material.plan import MaterialSweepPlan
    from calibration.rig_sequence import build_rig_plan
    from service.cli import ranges
    from service.lab import requests
    from service.settings import Settings
    from sim_core.adaptive import NOISE_FRACTION_RANGE, render_adaptive

    def setting(name):
        return lambda v: Settings(token="a-long-enough-token", **{name: v})

    def adaptive(name):
        def ask(v):  # the checks come first: past them, no scene (None) fails otherwise
            try:
                render_adaptive(None, None, **{name: v})
            except AttributeError:
                return
        return ask

    def sweep(name):
        return lambda v: MaterialSweepPlan(**{name: v})

    assert Range(*NOISE_FRACTION_RANGE) == ranges.NOISE_FRACTION
    defaults = Settings.model_fields
    assert (ranges.BENCH_POSES.hi, ranges.BENCH_REPEATS.hi, ranges.BENCH_SPP.hi) == (
        defaults["max_poses"].default, defaults["max_repeats"].default,
        defaults["max_spp"].default)
    return {
        "PORT": (setting("port"), int), "WORKERS": (setting("workers"), int),
        "THREADS": (setting("sim_threads"), int), "CAMERA_SPP": (setting("camera_spp"), int),
        "CAMERA_SEED": (setting("camera_seed"), int),
        "TURNTABLE_DEG": (lambda v: requests.SimulationCreate(turntable_deg=v), float),
        "MASK_DISTANCE": (lambda v: requests.MaskSpec(near_m=v), float),
        "FIT_FRAMES": (lambda v: requests.ObjectFitIn(frames=v), int),
        "TURNING_SPEED": (lambda v: requests.CampaignCreate(
            name="t", poses=[{"turntable_deg": 0.0}], turning_deg_s=v), float),
        "TARGET_RANGE_ERROR": (lambda v: adaptive("target_range_error_m")(v * 1e-3), float),
        "TIME_BUDGET": (adaptive("time_budget_s"), float),
        "NOISE_FRACTION": (adaptive("target_noise_fraction"), float),
        "SAMPLE_SIZE": (sweep("size_m"), float),
        "FRAMES_PER_STATE": (sweep("frames_per_state"), int),
        "SOLAR_SUNS_OR_OFF": (sweep("solar_suns"), float),
        "OUTLIER_THRESHOLD": (lambda v: FitSettings(outlier_relative_error=v), float),
        "FRAMES_PER_VIEW": (lambda v: build_rig_plan(frames_per_view=v), int),
        "REFERENCE_SUNS": (lambda v: build_rig_plan(solar_reference_suns=v), float),
    }


def test_each_copied_range_is_that_of_its_home():
    from service.cli import ranges

    for name, (make, kind) in _copies().items():
        r = getattr(ranges, name)
        inside, outside = _edges(r, kind)
        for v in inside + list(r.also):
            assert not _refused(make, kind(v)), (name, v)
        for v in outside:
            assert _refused(make, kind(v)), (name, v)
