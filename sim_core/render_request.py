"""A render request: everything that decides how one frame is simulated, as one value.

The request travels whole from where it is made (the API's request body, a campaign's pose, the
command line, a calibration procedure) to the worker that renders it
(:func:`sim_core.pipeline.simulate`): the render settings (integrator, samples per pixel,
bounces, seed, threads), one accuracy target, which effects to simulate and whether the sensor
is ideal. Nothing on the way unpacks it into loose fields and packs it again.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Literal

from sim_core.adaptive import INITIAL_SPP
from sim_core.render import RenderSettings
from sim_core.scene_spec import RenderSpec

Effects = Literal["auto", "all"]


@dataclass(frozen=True)
class AccuracyTarget:
    """How accurate the render must be; with no goal set, ``settings.spp`` samples everywhere.

    Attributes
    ----------
    range_error_mm : float or None
        Sample until every pixel that matters has a range standard error below this [mm]
        (:func:`sim_core.adaptive.render_adaptive`, starting from
        :data:`sim_core.adaptive.INITIAL_SPP`).
    noise_fraction : float or None
        Every pixel gets ``settings.spp`` samples, and those whose Monte Carlo error is still
        above this fraction of the sensor's noise get more
        (:func:`sim_core.adaptive.noise_fraction`).
    time_budget_s : float or None
        Spend this wall time [s] on the worst pixels (alone, or as a cap on the goals above).
    """

    range_error_mm: float | None = None
    noise_fraction: float | None = None
    time_budget_s: float | None = None

    @property
    def adaptive(self) -> bool:
        """Whether the render samples adaptively (any goal set) rather than a fixed spp."""
        return not (self.range_error_mm is None and self.noise_fraction is None
                    and self.time_budget_s is None)

    def initial_spp(self, settings: RenderSettings) -> int:
        """Samples every pixel gets before the adaptive rounds: ``settings.spp`` under a noise
        fraction (a floor the caller chose), else :data:`sim_core.adaptive.INITIAL_SPP`."""
        return settings.spp if self.noise_fraction is not None else INITIAL_SPP


@dataclass(frozen=True)
class RenderRequest:
    """One frame's render, whole (module docstring).

    Attributes
    ----------
    settings : RenderSettings
        Integrator, samples per pixel, bounces, seed, Russian roulette, threads.
    accuracy : AccuracyTarget
        The one accuracy target (default: ``settings.spp`` everywhere).
    effects : "auto" or "all"
        The effect planner's choice for this scene, or every effect
        (:func:`sim_core.plan.plan_effects`).
    ideal : bool
        Ideal sensor: no noise, SBI, ADC or depth errors.
    tolerance_mm : float or None
        The effect planner's depth tolerance [mm] (None: the sensor's own noise).
    """

    settings: RenderSettings = field(default_factory=RenderSettings)
    accuracy: AccuracyTarget = field(default_factory=AccuracyTarget)
    effects: Effects = "auto"
    ideal: bool = False
    tolerance_mm: float | None = None

    def with_seed(self, seed: int) -> RenderRequest:
        """The same request with the render's (and the sensor noise's) seed replaced."""
        return dataclasses.replace(self, settings=dataclasses.replace(self.settings, seed=seed))


def request_from_spec(
    render: RenderSpec,
    *,
    integrator: str | None = None,
    spp: int | None = None,
    max_bounces: int | None = None,
    seed: int | None = None,
    threads: int | None = None,
    accuracy: AccuracyTarget | None = None,
    effects: Effects = "auto",
    ideal: bool = False,
    tolerance_mm: float | None = None,
) -> RenderRequest:
    """The request for a scene's ``render:`` section, with what the caller overrides (the
    samples per pixel and the seed of an API request or a campaign's pose, the command line's
    integrator and bounces, the worker's threads); None keeps the scene's own value."""
    return RenderRequest(
        settings=RenderSettings(
            integrator=render.integrator if integrator is None else integrator,
            spp=render.spp if spp is None else spp,
            max_bounces=render.max_bounces if max_bounces is None else max_bounces,
            seed=render.seed if seed is None else seed,
            russian_roulette_from_bounce=render.russian_roulette_from_bounce,
            threads=threads,
        ),
        accuracy=accuracy or AccuracyTarget(),
        effects=effects,
        ideal=ideal,
        tolerance_mm=tolerance_mm,
    )
