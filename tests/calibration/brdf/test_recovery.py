"""The presets of the seed paper's Table 1 and the relay-wall paper's Table 2, recovered from
200 noisy goniometer samples with 10 % gross outliers (``synthetic.py``: 3 % log-normal noise,
outliers x2..x5 or /2../5, four incidence angles, denser near the specular peak).

Every determined parameter within 5 % (``kd = 0`` of the black shield: within 0.05 ks),
outlier flags with precision and recall >= 0.9, on several campaigns (seeds). The thermal
control film's ``ks``, ``f0`` and Fresnel exponent are not determined by such data (``F0`` =
0.775 makes the Fresnel term nearly constant, so only ``ks * f0`` shows): the fit must say so,
and recovers ``ks`` when ``f0`` and the exponent are pinned at a prior.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.brdf import fit_brdf
from calibration.brdf.evidence import brdf_verdicts
from sim_core.materials import PRESETS
from tests.calibration.brdf.synthetic import measure
from tests.calibration.realities import reality_seeds

NOISE = 0.03
SEEDS = (11, 12, 13)


def _flags_ok(fit, syn) -> tuple[float, float]:
    tp = int(np.sum(fit.outlier & syn.outlier))
    return tp / max(int(fit.outlier.sum()), 1), tp / int(syn.outlier.sum())


def _check_recovery(name: str, seed: int) -> None:
    kind, truth = PRESETS[name]
    syn = measure(name, seed, noise=NOISE)
    fit = fit_brdf(syn.table, kind, seed=seed)
    precision, recall = _flags_ok(fit, syn)
    assert precision >= 0.9 and recall >= 0.9, (precision, recall)
    for p, v in truth.items():
        got = fit.params[p]
        assert fit.determined[p], (p, got, fit.uncertainty[p])
        if v == 0.0:
            assert abs(got) <= 0.05 * truth["ks"], (p, got)
        else:
            assert abs(got - v) <= 0.05 * v, (p, got, v)
        # the reported uncertainty is honest: the truth within 4 sigma (or 0.5 % for tiny ones)
        assert abs(got - v) <= max(4 * fit.uncertainty[p], 0.005 * max(abs(v), 0.01)), \
            (p, got, v, fit.uncertainty[p])
    assert fit.e_fit < 0.01
    # issue 27: on the campaign issue 14 asked for, every parameter stays determined
    verdicts = brdf_verdicts(fit, seed=seed)
    assert all(verdicts[f"params.{p}"].determined for p in truth), verdicts.to_json()
    _check_verdicts(fit, verdicts, truth)


#: a determined parameter's target (issue 14): within 5 % (a zero within 0.05 ks)
TARGET_REL = 0.05


def _check_verdicts(fit, verdicts, truth) -> list[tuple[str, str, float, float]]:
    """Every determined parameter within 3 of its std of the truth, or within its target;
    returns (key, verdict, |err| / std, error) per parameter."""
    rows = []
    for p, v in truth.items():
        key = f"params.{p}"
        verdict = verdicts[key]
        err = fit.params[p] - v
        ratio = abs(err) / verdict.std if verdict.determined and verdict.std else math.nan
        rows.append((key, verdict.verdict, ratio, err))
        if verdict.determined:
            target = TARGET_REL * (v if v else truth["ks"])
            assert ratio <= 3.0 or abs(err) <= target, (key, ratio, err, verdicts.to_json())
        else:
            assert verdict.reason
    return rows


def test_black_glossy_tile_is_recovered():
    _check_recovery("black-glossy-tile", 0)


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", ["black-protective-shield", "white-matte-tile",
                                  "black-glossy-tile", "silicon-solar-cell"])
def test_preset_is_recovered(name, seed):
    _check_recovery(name, seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS[:2])
def test_thermal_control_film_reports_what_it_cannot_determine(seed):
    _, truth = PRESETS["thermal-control-film"]
    syn = measure("thermal-control-film", seed, noise=NOISE)
    fit = fit_brdf(syn.table, "seed-microfacet", seed=seed)
    precision, recall = _flags_ok(fit, syn)
    assert precision >= 0.9 and recall >= 0.9
    for p in ("kd", "sigma"):
        assert fit.determined[p]
        assert abs(fit.params[p] - truth[p]) <= 0.05 * truth[p]
    assert not fit.determined["fresnel_exponent"]
    assert not (fit.determined["ks"] and fit.determined["f0"])
    # what the data do show: the specular scale ks * F0
    product = fit.params["ks"] * fit.params["f0"]
    assert abs(product - truth["ks"] * truth["f0"]) <= 0.05 * truth["ks"] * truth["f0"]
    # with F0 and the exponent pinned at a prior, ks is determined and recovered
    pinned = fit_brdf(syn.table, "seed-microfacet", seed=seed,
                      fixed={"f0": truth["f0"], "fresnel_exponent": truth["fresnel_exponent"]})
    assert pinned.determined["ks"] and not pinned.determined["f0"]
    assert pinned.fixed == {"f0": truth["f0"], "fresnel_exponent": truth["fresnel_exponent"]}
    assert abs(pinned.params["ks"] - truth["ks"]) <= 0.05 * truth["ks"]


def _user_incidences(seed: int) -> tuple[float, ...]:
    """3-6 distinct incidence zeniths a user could set: whole degrees drawn in [-89, 89], the
    goniometer's zenith their magnitude."""
    rng = np.random.default_rng([seed, 27])
    while True:
        drawn = {float(abs(a)) for a in rng.integers(-89, 90, size=int(rng.integers(3, 7)))}
        if len(drawn) >= 3:
            return tuple(sorted(drawn))


@pytest.mark.slow
# ~10 s a campaign; TOFTWIN_BRDF_ANGLE_SEEDS=1-20 runs more
@pytest.mark.parametrize("seed", reality_seeds([1, 2, 3], variable="TOFTWIN_BRDF_ANGLE_SEEDS"))
def test_no_parameter_is_determined_and_wrong_on_incidences_a_user_could_choose(seed):
    names = ["black-protective-shield", "white-matte-tile", "black-glossy-tile",
             "silicon-solar-cell"]
    name = names[seed % len(names)]
    kind, truth = PRESETS[name]
    incidences = _user_incidences(seed)
    syn = measure(name, seed, noise=NOISE, incidence_deg=incidences)
    fit = fit_brdf(syn.table, kind, seed=seed)
    rows = _check_verdicts(fit, brdf_verdicts(fit, seed=seed), truth)
    print(f"\nseed {seed}: {name}, incidence {incidences}")
    for key, verdict, ratio, err in rows:
        print(f"  {key:22} {verdict:15} |err|/std {ratio:6.2f}  err {err:+.4g}")
