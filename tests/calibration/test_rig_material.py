"""The material on the rig (issue 14, §2): slices of a sample plate, the fit, what they determine.

The simulated lab holds a Cook–Torrance sample the procedure never sees (the simulated operator
mounts it); the procedure gets a perfect calibration of the rig (the reality's camera and rig
keys only) and must recover the parameters the slices determine within 5 %, hold the others at
the prior and say so.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from calibration.captures import AveragedCapture
from calibration.rig_material import (
    SAMPLE_NAME,
    MaterialSweepPlan,
    extract_slices,
    prior_material,
    sample_angles,
)
from calibration.rig_material.reference import PlateGeometry, ReferenceView
from calibration.rig_material.sweep import SampleCaptures
from drivers.sim.operator import SimulatedOperator
from drivers.sim.rig import simulated_rig
from drivers.sim.world import SimulatedWorld
from service.cli import app
from service.lab.acquisition import run_material_calibration
from sim_core.errors import InvalidInputError
from sim_core.materials import CookTorrance
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene_spec import load_scene_spec
from sim_core.twin_file import dump_yaml, write_calibration
from tests.calibration.realities import (
    perfect_calibration,
    random_reality,
    reality_seeds,
    with_world_effects,
)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
PRIOR = "white-matte-tile"
runner = CliRunner()


def _random_sample(seed: int) -> dict[str, float]:
    """Cook–Torrance parameters drawn at random within +-30 % of the prior's (the lab's guess of
    its material class; kd + ks <= 0.98).

    The slices fix only ks F(0; n2) of the specular pair, so the one held at the prior must be
    able to reach the sample's peak within the other's bounds: with the white matte tile as the
    prior, a sample with twice its ks and n2 near 2.2 would need n2 beyond 3 and leaves the
    lobe's width undetermined (which the fit then reports, instead of a value).
    """
    u = np.random.default_rng([seed, 142]).uniform
    prior = prior_material("cook-torrance", PRIOR)
    kd = float(prior.kd * u(0.7, 1.0))
    ks = float(min(prior.ks * u(0.7, 1.3), 0.98 - kd))
    return {"kd": kd, "ks": ks, "m": float(prior.m * u(0.7, 1.3)),
            "n2": float(prior.n2 * u(0.7, 1.3))}


def _measure(true: dict[str, float], reality_seed: int, plan: MaterialSweepPlan):
    """The sweep on a random reality with issue 27's effects in the world (warm-up drift,
    stray light, the table's settling); the rig's calibration knows them."""
    reality = with_world_effects(random_reality(reality_seed), reality_seed)
    world = SimulatedWorld(SPEC, EXAMPLES, RenderRequest(
        RenderSettings(integrator="direct", spp=32), effects="all"), reality=reality)
    operator = SimulatedOperator(world, {SAMPLE_NAME: {"kind": "cook-torrance",
                                                       "params": true}})
    with simulated_rig(frame_source=world, seed=reality_seed) as rig:
        return run_material_calibration(rig, operator, SPEC, EXAMPLES,
                                        perfect_calibration(reality), plan, "cook-torrance",
                                        PRIOR, seed=reality_seed)


def _check_recovery(result, true: dict[str, float]) -> dict[str, float]:
    """The determined parameters within 5 %, the others at the prior and reported so, the
    fitted BRDF equal to the true one on the slices; returns the relative errors."""
    fit = result.result
    prior = prior_material("cook-torrance", PRIOR)
    errors = {n: fit.parameters[n].value / true[n] - 1.0 for n in true}
    assert {"kd", "m"} <= set(fit.determined), fit.report()["parameters"]
    for name in fit.determined:
        assert abs(errors[name]) < 0.05, (name, errors, fit.report()["parameters"])
    for name in fit.at_prior:
        assert fit.parameters[name].value == getattr(prior, name)
        assert fit.fit.params[name] == getattr(prior, name) and name in fit.fit.fixed
        assert "not determined by these slices" in fit.parameters[name].reason
    report = result.report()
    assert {n for n, p in report["parameters"].items() if p["status"] == "prior"} \
        == set(fit.at_prior)
    # What is not determined trades within the slices: the fitted model reproduces them.
    wi, wo = fit.fit.table.directions()
    f_true = CookTorrance(**true).eval_local(wi, wo)
    f_fit = fit.fit.material().eval_local(wi, wo)
    assert np.max(np.abs(f_fit / f_true - 1.0)) < 0.03
    assert result.slices.check.warnings == []
    return errors


#: the random samples' sweep: every 5 deg to +-50 deg, 2 frames a state (the default plan,
#: every 5 deg to +-70 deg with 4 frames, takes ~5 min a sample on two cores and recovers the
#: same parameters: seed 1 within 0.6 %)
RANDOM_PLAN = MaterialSweepPlan(angles_deg=sample_angles("-50:50:5", "--angles"),
                                frames_per_state=2)


@pytest.mark.slow
# CI runs one random sample (2-2.5 min on two cores); TOFTWIN_MATERIAL_SEEDS=1-10 runs more
@pytest.mark.parametrize("seed", reality_seeds([1], variable="TOFTWIN_MATERIAL_SEEDS"))
def test_random_cook_torrance_samples_are_recovered(seed):
    true = _random_sample(seed)
    t0 = time.perf_counter()
    result = _measure(true, 100 + seed, RANDOM_PLAN)
    errors = _check_recovery(result, true)
    # issue 27: on the plan, the parameters issue 14 asked for stay determined, none wrong
    _check_verdicts(result, true)
    assert {"params.kd", "params.m"} <= {k for k, v in result.verdicts.items() if v.determined}
    print(f"\nseed {seed}: true {true}, errors "
          f"{({k: f'{100 * v:+.2f} %' for k, v in errors.items()})}, statuses "
          f"{({k: p.status for k, p in result.result.parameters.items()})}, rows "
          f"{({p.slice_name: len(p) for p in result.slices.parts})}, "
          f"seconds {({k: round(v) for k, v in result.seconds.items()})}, "
          f"total {time.perf_counter() - t0:.0f} s, verdicts {_verdict_table(result, true)}")


# -- the slices from synthetic views: the arithmetic and the refusals ---------------------------
def _capture(amplitude: float, intensity: float, shape) -> AveragedCapture:
    return AveragedCapture(
        turntable_angle_deg=0.0, solar_suns=0.0, shutter_open=False, n_frames=4,
        phase_images=np.zeros((1, 4, *shape)), intensity=np.full(shape, intensity),
        intensity_std=np.full(shape, 2.0), amplitude=np.full(shape, amplitude),
        phase_rad=np.zeros((1, *shape)), valid=np.ones(shape, dtype=bool),
        frequencies_hz=np.array([60.24e6]), exposure_s=500e-6)


def _view(zenith_deg: float, shape=(30, 40), plate=True, solar_intensity=None):
    """A plate of 20 x 30 pixels seen at ``zenith_deg`` (retro), measured amplitude 60 DN
    against a reference of 100 DN (albedo 0.5), the solar simulator adding 500 DN against a
    reference slope of 1000 DN."""
    mask = np.zeros(shape, dtype=bool)
    if plate:
        mask[5:25, 5:35] = True
    n = int(mask.sum())
    # Zeniths spread by 2 deg across the plate's columns, as a plate at 1 m spans.
    cols = np.nonzero(mask)[1]
    zen = np.radians(zenith_deg + (cols - 20) * 0.1)
    w = np.stack([np.sin(zen), np.zeros(n), np.cos(zen)], axis=1)
    sun = np.tile([np.sin(np.radians(30.0)), 0.0, np.cos(np.radians(30.0))], (n, 1))
    geometry = PlateGeometry(mask, w, w, sun)
    ref = ReferenceView(0.0, 0.5, np.full(shape, 100.0), np.full(shape, np.nan),
                        np.full(shape, 1000.0), np.full(shape, 2000.0), geometry)
    lamp = _capture(60.0, 100.0, shape)
    solar = _capture(60.0, 100.0 + 500.0 if solar_intensity is None else solar_intensity, shape)
    cap = SampleCaptures(0.0, lamp, np.full(shape, 0.5), solar)
    return cap, ref


def test_slices_are_measured_over_reference_times_albedo_over_pi():
    cap, ref = _view(20.0)
    slices = extract_slices([cap], [ref], bin_deg=1.0, min_pixels_per_bin=12)
    assert len(slices.retro) >= 2 and len(slices.solar) >= 2
    np.testing.assert_allclose(slices.retro.brdf_per_sr, 0.6 * 0.5 / math.pi, rtol=1e-12)
    np.testing.assert_allclose(slices.solar.brdf_per_sr, 0.5 * 0.5 / math.pi, rtol=1e-12)
    np.testing.assert_allclose(slices.retro.incidence_zenith_deg,
                               slices.retro.reflection_zenith_deg)
    assert np.all(np.abs(slices.retro.reflection_zenith_deg - 20.0) < 1.6)
    np.testing.assert_allclose(slices.solar.incidence_zenith_deg, 30.0, atol=1e-9)
    # Uncertainty from the frames: the rows' standard error, floored by the twin's error.
    assert np.all(slices.retro.brdf_std_per_sr < 0.01 * slices.retro.brdf_per_sr)
    table = slices.table()
    assert len(table) == len(slices.retro) + len(slices.solar)
    np.testing.assert_allclose(table.brdf_std_per_sr / table.brdf_per_sr, 0.01, rtol=0.01)


def test_solar_pixels_held_by_sbi_are_left_out():
    cap, ref = _view(20.0, solar_intensity=1900.0)  # 0.95 of SBI's 2000 DN
    slices = extract_slices([cap], [ref], bin_deg=1.0, min_pixels_per_bin=12)
    assert len(slices.retro) >= 2 and len(slices.solar) == 0


def test_no_plate_pixels_is_a_clear_error():
    cap, ref = _view(20.0, plate=False)
    with pytest.raises(InvalidInputError, match="no pixel of the sample plate"):
        extract_slices([cap], [ref], bin_deg=1.0, min_pixels_per_bin=12)


def test_angles_without_retro_coverage_are_a_clear_error():
    cap, ref = _view(84.0)  # every pixel beyond the usable zenith
    with pytest.raises(InvalidInputError, match="no usable retro-reflection rows") as exc:
        extract_slices([cap], [ref], bin_deg=1.0, min_pixels_per_bin=12)
    assert exc.value.field == "angles_deg"


def test_the_plan_refuses_bad_input():
    with pytest.raises(InvalidInputError, match="angles_deg"):
        MaterialSweepPlan(angles_deg=())
    with pytest.raises(InvalidInputError, match="edge-on"):
        MaterialSweepPlan(angles_deg=(0.0, 88.0))
    with pytest.raises(InvalidInputError, match="solar_suns"):
        MaterialSweepPlan(solar_suns=0.3)
    with pytest.raises(InvalidInputError, match="angles"):
        sample_angles("10:-10:5", "--angles")
    with pytest.raises(InvalidInputError, match="prior"):
        prior_material("cook-torrance", "thermal-control-film")  # a seed-microfacet preset
    assert sample_angles("-70:70:5", "--angles")[::14] == (-70.0, 0.0, 70.0)


def test_the_cli_refuses_bad_input(tmp_path):
    out = tmp_path / "m.yaml"
    for args, field in ((["--reality", str(tmp_path / "r.yaml")], "--reality"),
                        (["--sample-material", "white-matte-tile"], "--sample-material"),
                        (["--simulated", "--angles", "a:b"], "angles"),
                        (["--simulated", "--prior", "black-flannel"], "prior"),
                        (["--simulated", "--sample-material", "nothing"], "--sample-material")):
        res = runner.invoke(app, ["calibrate", "material", "--out", str(out), *args])
        assert res.exit_code == 2, (args, res.output)
        assert field in res.output
    assert not out.exists()


@pytest.mark.slow
def test_the_cli_writes_the_material_file_the_slices_and_the_report(tmp_path):
    out = tmp_path / "sample.yaml"
    reality = random_reality(7)
    (tmp_path / "reality.yaml").write_text(dump_yaml(reality), encoding="utf-8")
    write_calibration(tmp_path / "calibration.yaml", perfect_calibration(reality))
    res = runner.invoke(app, ["calibrate", "material", "--simulated", "--reality",
                              str(tmp_path / "reality.yaml"), "--calibration",
                              str(tmp_path / "calibration.yaml"), "--sample-material",
                              "black-glossy-tile", "--prior", PRIOR, "--angles", "-30:30:10",
                              "--frames-per-state", "2", "--out", str(out), "-q"])
    assert res.exit_code == 0, res.output
    written = yaml.safe_load(out.read_text(encoding="utf-8"))
    assert written["kind"] == "cook-torrance"
    report = json.loads((tmp_path / "sample.report.json").read_text(encoding="utf-8"))
    assert report["parameters"]["kd"]["status"] == "determined"
    assert abs(written["params"]["kd"] / 0.07 - 1.0) < 0.05
    held = [n for n, p in report["parameters"].items() if p["status"] == "prior"]
    assert held and "NOT DETERMINED" in res.stdout
    for name in held:
        assert written["params"][name] == getattr(prior_material("cook-torrance", PRIOR), name)
    from sim_core.materials.goniometer import read_goniometer_csv

    table = read_goniometer_csv(tmp_path / "sample.slices.csv")
    assert len(table) == written["fit"]["n_samples"]
    # issue 27: every parameter's verdict beside the material file, and printed
    verdicts = json.loads((tmp_path / "sample.verdicts.json").read_text(encoding="utf-8"))
    assert set(verdicts) == {f"params.{n}" for n in ("kd", "ks", "m", "n2")}
    assert verdicts["params.kd"]["verdict"] == "determined"
    for name in held:
        assert verdicts[f"params.{name}"]["verdict"] == "not determined"
        assert f"params.{name}: not determined" in res.stdout
    assert " keys: " in res.stdout and report["verdicts"] == verdicts


# -- verdicts on angle sets a user could choose (issue 27) ---------------------------------------
#: a determined parameter's target (issue 14): within 5 % of the truth
MATERIAL_TARGET_REL = 0.05


def _user_angles(seed: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """3-6 whole-degree angles drawn in [-90, 90] deg, as a user could type them: those the
    plan accepts (within +-85 deg, distinct) and those it refuses (edge-on)."""
    rng = np.random.default_rng([seed, 27])
    drawn = sorted({float(a) for a in rng.integers(-90, 91, size=int(rng.integers(3, 7)))})
    return (tuple(a for a in drawn if abs(a) <= 85.0),
            tuple(a for a in drawn if abs(a) > 85.0))


def _verdict_table(result, true: dict[str, float]) -> list[tuple[str, str, float, float]]:
    """(key, verdict, |err| / std, relative error) of each parameter the verdicts report."""
    rows = []
    for key, v in result.verdicts.items():
        name = key.removeprefix("params.")
        err = result.result.fit.params[name] - true[name]
        ratio = abs(err) / v.std if v.determined and v.std else math.nan
        rows.append((key, v.verdict, ratio, err / true[name]))
    return rows


def _check_verdicts(result, true: dict[str, float]) -> list[tuple[str, str, float, float]]:
    rows = _verdict_table(result, true)
    assert {k for k, *_ in rows} == {f"params.{n}" for n in true}
    for key, verdict, ratio, rel in rows:
        if verdict == "determined":
            assert ratio <= 3.0 or abs(rel) <= MATERIAL_TARGET_REL, (key, ratio, rel, rows)
        else:
            assert result.verdicts[key].reason
    return rows


@pytest.mark.slow
# CI runs two angle sets (~1 min each on two cores); TOFTWIN_MATERIAL_ANGLE_SEEDS=1-20 runs more
@pytest.mark.parametrize("seed", reality_seeds([1, 2], variable="TOFTWIN_MATERIAL_ANGLE_SEEDS"))
def test_no_parameter_is_determined_and_wrong_on_angles_a_user_could_choose(seed):
    true = _random_sample(seed)
    angles, refused = _user_angles(seed)
    for a in refused:
        with pytest.raises(InvalidInputError, match="edge-on"):
            MaterialSweepPlan(angles_deg=(*angles, a))
    if not angles:
        return  # every drawn angle edge-on: the plan refused them all (asserted above)
    plan = MaterialSweepPlan(angles_deg=angles, frames_per_state=2)
    t0 = time.perf_counter()
    try:
        result = _measure(true, 200 + seed, plan)
    except InvalidInputError as exc:  # too few views to fit: a clear refusal, no number
        assert exc.field in ("angles", "angles_deg", "slices", "sample"), exc
        print(f"\nseed {seed}: angles {angles}: refused: {exc}")
        return
    rows = _check_verdicts(result, true)
    print(f"\nseed {seed}: angles {angles} (refused {refused}), "
          f"{time.perf_counter() - t0:.0f} s, chi2 {result.evidence.reduced_chi2}")
    for key, verdict, ratio, rel in rows:
        print(f"  {key:10} {verdict:15} |err|/std {ratio:6.2f}  err {100 * rel:+6.2f} %  "
              f"std {result.verdicts[key].std}")
