"""Renderers that turn a posed scene into a :class:`LightField`."""

from sim_core.render.integrator import (
    ProgressiveRenderer,
    RenderResult,
    RenderSettings,
    render,
)
from sim_core.render.lightfield import LightField

__all__ = ["LightField", "ProgressiveRenderer", "RenderResult", "RenderSettings", "render"]
