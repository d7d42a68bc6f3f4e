"""Renderers that turn a posed scene into a :class:`LightField`."""

from sim_core.render.integrator import RenderResult, RenderSettings, render
from sim_core.render.lightfield import LightField

__all__ = ["LightField", "RenderResult", "RenderSettings", "render"]
