"""The harness must catch broken materials: each check is run on a deliberately wrong model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim_core.materials import BSDFSample, Lambertian, SeedMicrofacet
from sim_core.materials.microfacet import finish_sample

from . import harness


class UniformPdfClaim(Lambertian):
    """Samples cosine-weighted but claims a uniform-hemisphere pdf."""

    def pdf_local(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return np.where((wi[:, 2] > 0) & (wo[:, 2] > 0), 1.0 / (2.0 * np.pi), 0.0)


class TooBright(Lambertian):
    """Reflects 3 % more than it receives."""

    def eval_local(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return 1.03 * super().eval_local(wi, wo)

    @property
    def albedo_bound(self) -> float:
        return 1.0


class SlightlyWideSampler(SeedMicrofacet):
    """Samples a lobe 5 % wider (in α) than the one its pdf describes."""

    def sample_local(self, wo: np.ndarray, u: np.ndarray) -> BSDFSample:
        params = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        wider = SeedMicrofacet(**{**params, "sigma": self.sigma * 1.05**2})
        return finish_sample(self, wider.sample_local(wo, u).wi, wo)


class WeightOffByTwoPercent(SeedMicrofacet):
    """Correct sampler and pdf, but a weight 2 % too low (e.g. a dropped factor)."""

    def sample_local(self, wo: np.ndarray, u: np.ndarray) -> BSDFSample:
        s = super().sample_local(wo, u)
        return BSDFSample(wi=s.wi, pdf=s.pdf, weight=0.98 * s.weight)


WO = harness.direction_deg(35.0, 30.0)


def test_chi2_rejects_a_pdf_that_does_not_describe_the_sampler() -> None:
    assert harness.chi2_goodness_of_fit(UniformPdfClaim(albedo=0.5), WO).p_value < 1e-6
    with pytest.raises(AssertionError, match="chi2"):
        harness.check_chi2(UniformPdfClaim(albedo=0.5), WO)


def test_chi2_rejects_a_sampler_five_percent_too_wide() -> None:
    material = SlightlyWideSampler(ks=0.6, kd=0.1, sigma=0.05)
    assert harness.chi2_goodness_of_fit(material, WO).p_value < 1e-6
    # while the correct model passes on the same samples
    glossy = SeedMicrofacet(ks=0.6, kd=0.1, sigma=0.05)
    assert harness.chi2_goodness_of_fit(glossy, WO).p_value > 1e-3


def test_albedo_consistency_rejects_a_wrong_pdf_and_a_wrong_weight() -> None:
    with pytest.raises(AssertionError, match="sampled albedo"):
        harness.check_albedo_consistency(UniformPdfClaim(albedo=0.5), WO)
    with pytest.raises(AssertionError, match="sampled albedo"):
        harness.check_albedo_consistency(WeightOffByTwoPercent(ks=0.6, kd=0.3, sigma=0.2), WO)


def test_energy_check_rejects_a_material_reflecting_three_percent_too_much() -> None:
    wos = np.stack([harness.direction_deg(0.0), harness.direction_deg(80.0)])
    with pytest.raises(AssertionError, match="sampled albedo"):
        harness.check_albedo_at_most_one(TooBright(albedo=1.0), wos)
