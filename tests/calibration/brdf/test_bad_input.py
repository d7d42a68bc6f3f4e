"""Bad goniometer data and angle sets that cannot determine a model give clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.brdf import FitSettings, fit_brdf
from sim_core.errors import InvalidInputError
from sim_core.materials.goniometer import GoniometerTable, read_goniometer_csv

HEADER = "incidence_zenith_deg,reflection_zenith_deg,azimuth_difference_deg,brdf_per_sr"


def _csv(tmp_path, text: str):
    p = tmp_path / "data.csv"
    p.write_text(text, encoding="utf-8")
    return p


@pytest.mark.parametrize(("text", "field", "words"), [
    ("incidence_zenith_deg,reflection_zenith_deg,brdf_per_sr\n30,30,0.5\n",
     "azimuth_difference_deg", "missing column"),
    (f"{HEADER}\n30,30,180,-0.5\n", "brdf_per_sr", "row 1"),
    (f"{HEADER}\n30,30,180,nan\n", "brdf_per_sr", "finite"),
    (f"{HEADER}\n30,inf,180,0.5\n", "reflection_zenith_deg", "finite"),
    (f"{HEADER}\n-5,30,180,0.5\n", "incidence_zenith_deg", "[0, 90)"),
    (f"{HEADER}\n30,95,180,0.5\n", "reflection_zenith_deg", "[0, 90)"),
    (f"{HEADER}\n30,30,400,0.5\n", "azimuth_difference_deg", "[0, 360]"),
    (f"{HEADER}\n30,30,180,abc\n", "brdf_per_sr", "not a number"),
    (f"{HEADER}\n", "path", "no rows"),
    (f"{HEADER},brdf_std_per_sr\n30,30,180,0.5,0\n", "brdf_std_per_sr", "(0, inf]"),
    (f"{HEADER},wavelength_nm\n30,30,180,0.5,850\n30,40,180,0.5,940\n", "wavelength_nm",
     "choose one"),
])
def test_bad_csv_names_the_column(tmp_path, text, field, words):
    with pytest.raises(InvalidInputError) as err:
        read_goniometer_csv(_csv(tmp_path, text))
    assert err.value.field == field
    assert words in str(err.value)


def test_missing_file(tmp_path):
    with pytest.raises(InvalidInputError, match="does not exist"):
        read_goniometer_csv(tmp_path / "nope.csv")


def test_one_direction_pair_cannot_determine_a_model():
    table = GoniometerTable([30.0], [30.0], [180.0], [0.5])
    with pytest.raises(InvalidInputError) as err:
        fit_brdf(table, "cook-torrance")
    assert err.value.field == "angles"
    assert "1 distinct direction pair" in str(err.value) and "4 free parameter" in str(err.value)


def test_many_samples_at_one_configuration_cannot_determine_a_model():
    rng = np.random.default_rng(0)
    n = 50
    table = GoniometerTable(np.full(n, 40.0), np.full(n, 35.0), np.full(n, 180.0),
                            0.3 * np.exp(0.03 * rng.normal(size=n)))
    with pytest.raises(InvalidInputError, match="1 distinct direction pair"):
        fit_brdf(table, "seed-microfacet")


def test_too_few_configurations_for_the_free_parameters():
    table = GoniometerTable([30, 30, 30, 30], [20, 30, 40, 50], [180] * 4, [0.1, 0.5, 0.1, 0.05])
    with pytest.raises(InvalidInputError, match="4 distinct direction pair"):
        fit_brdf(table, "cook-torrance")
    # pinning two parameters leaves two free: four pairs are enough
    fit = fit_brdf(table, "cook-torrance", fixed={"n2": 1.5, "kd": 0.0})
    assert set(fit.fixed) == {"n2", "kd"}


def test_zero_measurement_without_std():
    table = GoniometerTable([30, 30, 30], [20, 30, 40], [180] * 3, [0.1, 0.0, 0.1])
    with pytest.raises(InvalidInputError) as err:
        fit_brdf(table, "lambertian")
    assert err.value.field == "brdf_per_sr" and "row 2" in str(err.value)


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"model": "phong"}, "model"),
    ({"model": "cook-torrance", "fixed": {"roughness": 0.1}}, "fixed"),
    ({"model": "cook-torrance", "fixed": {"n2": 4.0}}, "fixed.n2"),
    ({"model": "cook-torrance", "fixed": {"kd": 0.7, "ks": 0.6}}, "fixed.ks"),
    ({"model": "lambertian", "fixed": {"albedo": 0.5}}, "fixed"),
])
def test_bad_arguments_name_the_field(kwargs, field):
    table = GoniometerTable([30, 30, 30], [20, 30, 40], [180] * 3, [0.1, 0.1, 0.1])
    with pytest.raises(InvalidInputError) as err:
        fit_brdf(table, **kwargs)
    assert err.value.field == field


def test_bad_settings_name_the_setting():
    with pytest.raises(InvalidInputError) as err:
        FitSettings(outlier_relative_error=0.0)
    assert err.value.field == "settings.outlier_relative_error"
    with pytest.raises(InvalidInputError):
        FitSettings(ransac_min_trials=50, ransac_max_trials=10)


def test_a_lobe_the_angles_never_see_is_reported_undetermined():
    # all samples far from the mirror direction of a narrow lobe: the diffuse part is
    # determined, the lobe's roughness and index are not
    rng = np.random.default_rng(1)
    n = 60
    ti = np.full(n, 30.0)
    tr = rng.uniform(0.0, 60.0, n)
    dphi = rng.uniform(0.0, 60.0, n)  # on the light's side, far from the specular peak
    from sim_core.materials import material_preset
    f = material_preset("black-glossy-tile").eval_local(
        *GoniometerTable(ti, tr, dphi, np.ones(n)).directions())
    fit = fit_brdf(GoniometerTable(ti, tr, dphi, f * np.exp(0.03 * rng.normal(size=n))),
                   "cook-torrance", seed=1)
    assert fit.determined["kd"]
    assert abs(fit.params["kd"] - 0.07) <= 0.05 * 0.07
    assert not fit.determined["m"] and not fit.determined["n2"]
