"""Lambertian and Hapke fits on data drawn from them; e_fit against seed eq. (11) by hand."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.brdf import e_fit, fit_brdf
from calibration.brdf.models import FIT_MODELS, FreeParameters
from sim_core.materials import make_material
from sim_core.materials.goniometer import GoniometerTable
from tests.calibration.brdf.synthetic import measure


def test_lambertian_fit():
    syn = measure(make_material("lambertian", albedo=0.3), 3, noise=0.03)
    fit = fit_brdf(syn.table, "lambertian", seed=3)
    assert abs(fit.params["albedo"] - 0.3) <= 0.01 * 0.3
    assert fit.determined == {"albedo": True}
    assert np.array_equal(fit.outlier, syn.outlier)
    assert fit.material_spec() == {"kind": "lambertian", "params": {"albedo": fit.params["albedo"]}}
    report = fit.report()
    json.dumps(report, allow_nan=False)
    assert report["n_outliers"] == int(syn.outlier.sum())
    assert len(report["samples"]) == len(syn.table)


@pytest.mark.slow
def test_hapke_fit_on_data_drawn_from_it():
    truth = {"w": 0.6, "b0": 1.0, "h": 0.2, "phase_b": 0.3}
    syn = measure(make_material("hapke", **truth), 5, near="retro", noise=0.03)
    fit = fit_brdf(syn.table, "hapke", seed=5)
    tp = int(np.sum(fit.outlier & syn.outlier))
    assert tp / fit.outlier.sum() >= 0.9 and tp / syn.outlier.sum() >= 0.9
    assert fit.e_fit < 0.01
    for p, v in truth.items():
        # the truth within 4 sigma; determined parameters within 15 %
        assert abs(fit.params[p] - v) <= 4 * fit.uncertainty[p] + 1e-9, (p, fit.params[p])
        if fit.determined[p]:
            assert abs(fit.params[p] - v) <= 0.15 * abs(v), (p, fit.params[p])
    assert fit.determined["w"]
    assert fit.material().albedo_bound <= 1.0


def test_e_fit_is_seed_eq_11_by_hand():
    # (f_model cos θr - f_meas cos θr)^2 summed over (f_meas cos θr)^2 summed:
    # θr = 0: (0.2 - 0.1)^2 = 0.01 over 0.01; θr = 60: (0.25 - 0.25)^2 = 0 over 0.0625
    measured = np.array([0.1, 0.5])
    model = np.array([0.2, 0.5])
    assert e_fit(measured, model, np.array([0.0, 60.0])) == pytest.approx(0.01 / 0.0725)


def test_e_fit_of_a_fit_matches_its_definition():
    syn = measure(make_material("lambertian", albedo=0.5), 1, noise=0.03)
    fit = fit_brdf(syn.table, "lambertian", seed=1)
    keep = ~fit.outlier
    c = np.cos(np.radians(syn.table.reflection_zenith_deg[keep]))
    meas = syn.table.brdf_per_sr[keep] * c
    model = fit.model_brdf_per_sr[keep] * c
    assert fit.e_fit == pytest.approx(np.sum((model - meas) ** 2) / np.sum(meas ** 2), rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(1e-6, 1.0), st.floats(1.0, 3.0))
def test_internal_coordinates_round_trip_at_the_edges(a, b, m, n2):
    free = FreeParameters(FIT_MODELS["cook-torrance"])
    x = free.clip(np.array([a, b, m, n2]))
    assert x[0] + x[1] <= 1.0 + 1e-12
    u = free.to_internal(x)
    lo, hi = free.internal_bounds()
    assert np.all(u >= lo) and np.all(u <= hi)
    back = free.from_internal(u)
    assert np.allclose(back, x, atol=1e-12)
    free.build(back)  # the material accepts every point of the box


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(1e-3, 10.0), min_size=1, max_size=20), st.floats(0.1, 10.0))
def test_e_fit_is_zero_for_a_perfect_model_and_scale_free(values, scale):
    y = np.array(values)
    tr = np.linspace(0.0, 80.0, len(y))
    assert e_fit(y, y, tr) == 0.0
    assert e_fit(y * scale, 1.1 * y * scale, tr) == pytest.approx(0.01)
    assert math.isfinite(e_fit(y, 2 * y, tr))


def test_table_built_in_memory_and_std_column():
    mat = make_material("cook-torrance", kd=0.3, ks=0.5, m=0.1, n2=1.5)
    rng = np.random.default_rng(0)
    ti = np.repeat([20.0, 45.0, 60.0], 30)
    tr = rng.uniform(0, 80, 90)
    dphi = np.where(rng.random(90) < 0.5, 180.0, rng.uniform(0, 180, 90))
    f = mat.eval_local(*GoniometerTable(ti, tr, dphi, np.ones(90)).directions())
    std = 0.02 * f
    table = GoniometerTable(ti, tr, dphi, f + std * rng.normal(size=90), std)
    fit = fit_brdf(table, "cook-torrance", seed=2)
    assert fit.diagnostics["residuals"].startswith("chi")
    assert not fit.outlier.any()
    for p, v in {"kd": 0.3, "ks": 0.5, "m": 0.1, "n2": 1.5}.items():
        assert abs(fit.params[p] - v) <= 0.05 * v
