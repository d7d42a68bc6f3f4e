"""The goniometer table: its CSV reader's errors and its angle convention."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim_core.errors import InvalidInputError
from sim_core.materials import material_preset
from sim_core.materials.goniometer import (
    GoniometerTable,
    angles_from_directions,
    read_goniometer_csv,
)

HEADER = "incidence_zenith_deg,reflection_zenith_deg,azimuth_difference_deg,brdf_per_sr"


def _write(tmp_path, text: str):
    path = tmp_path / "gonio.csv"
    path.write_text(text, encoding="utf-8")
    return path


def test_reads_columns_in_any_order_and_folds_the_azimuth(tmp_path):
    path = _write(tmp_path, "brdf_per_sr,azimuth_difference_deg,reflection_zenith_deg,"
                            "incidence_zenith_deg,note\n0.5,180,30,30,a\n0.2,270,40,30,b\n")
    table = read_goniometer_csv(path)
    assert len(table) == 2
    assert table.azimuth_difference_deg.tolist() == [180.0, 90.0]
    assert table.brdf_std_per_sr is None and table.wavelength_nm is None


def test_mirror_plane_is_azimuth_180():
    """At Δφ = 180 and θi = θr the viewer sits at the mirror direction: a glossy peak."""
    glossy = material_preset("black-glossy-tile")
    mirror = GoniometerTable([40.0], [40.0], [180.0], [0.0]).directions()
    retro = GoniometerTable([40.0], [40.0], [0.0], [0.0]).directions()
    assert glossy.eval_local(*mirror)[0] > 10 * glossy.eval_local(*retro)[0]
    wi, wo = retro
    np.testing.assert_allclose(wi, wo, atol=1e-12)


@given(st.floats(0, 89.9), st.floats(0, 89.9), st.floats(0, 180))
def test_angles_from_directions_inverts_directions(ti, tr, phi):
    wi, wo = GoniometerTable([ti], [tr], [phi], [0.1]).directions()
    ti2, tr2, phi2 = angles_from_directions(wi, wo)
    assert ti2[0] == pytest.approx(ti, abs=1e-6)
    assert tr2[0] == pytest.approx(tr, abs=1e-6)
    if ti > 1e-3 and tr > 1e-3:  # a zenith direction has no azimuth
        assert phi2[0] == pytest.approx(phi, abs=1e-4)


@pytest.mark.parametrize(("text", "field"), [
    ("incidence_zenith_deg,reflection_zenith_deg,brdf_per_sr\n30,30,0.1\n",
     "azimuth_difference_deg"),
    (HEADER + "\n30,30,180,-0.1\n", "brdf_per_sr"),
    (HEADER + "\n30,30,180,nan\n", "brdf_per_sr"),
    (HEADER + "\n30,30,180,inf\n", "brdf_per_sr"),
    (HEADER + "\n30,30,180,abc\n", "brdf_per_sr"),
    (HEADER + "\n-5,30,180,0.1\n", "incidence_zenith_deg"),
    (HEADER + "\n30,90,180,0.1\n", "reflection_zenith_deg"),
    (HEADER + "\n30,30,400,0.1\n", "azimuth_difference_deg"),
    (HEADER + ",brdf_std_per_sr\n30,30,180,0.1,0\n", "brdf_std_per_sr"),
    (HEADER + "\n", "path"),
])
def test_bad_csv_names_the_column(tmp_path, text, field):
    with pytest.raises(InvalidInputError) as err:
        read_goniometer_csv(_write(tmp_path, text))
    assert err.value.field == field


def test_bands_are_chosen_or_refused(tmp_path):
    path = _write(tmp_path, HEADER + ",wavelength_nm\n30,30,180,0.1,850\n30,30,180,0.3,905\n")
    with pytest.raises(InvalidInputError, match="2 bands") as err:
        read_goniometer_csv(path)
    assert err.value.field == "wavelength_nm"
    table = read_goniometer_csv(path, wavelength_nm=850)
    assert table.brdf_per_sr.tolist() == [0.1] and table.wavelength_nm == 850.0
    with pytest.raises(InvalidInputError, match="850, 905 nm"):
        read_goniometer_csv(path, wavelength_nm=940)


def test_missing_file_is_named(tmp_path):
    with pytest.raises(InvalidInputError, match="does not exist"):
        read_goniometer_csv(tmp_path / "none.csv")
