"""Fixtures of the renderer's statistical tests: the small corner scene and its converged
reference, at the sizes the using module declares.

A module that uses them sets ``CORNER_WIDTH_PX`` (the corner's image width) and
``REFERENCE_SPP``/``REFERENCE_SEED`` (the reference's samples per pixel and seed; three
bounces); both are made once per module.
"""

from __future__ import annotations

import pytest

from sim_core.render import LightField, RenderSettings, render
from sim_core.scene import Scene
from tests.sim_core.scenes import small_example


@pytest.fixture(scope="module")
def corner(request: pytest.FixtureRequest) -> Scene:
    """The corner example (two albedo-0.5 walls and a floor) ``CORNER_WIDTH_PX`` wide."""
    return small_example("corner", width=request.module.CORNER_WIDTH_PX)


@pytest.fixture(scope="module")
def reference(request: pytest.FixtureRequest, corner: Scene) -> LightField:
    """The corner's light field converged far beyond the tests' own renders."""
    settings = RenderSettings(spp=request.module.REFERENCE_SPP, max_bounces=3,
                              seed=request.module.REFERENCE_SEED)
    return render(corner, settings).light_field
