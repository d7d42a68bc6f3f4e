"""Named material presets from the papers, and the factory that builds materials by name.

``PRESETS`` maps a preset name to ``(kind, params)``; ``make_material(kind, **params)`` builds
any model, ``material_preset(name)`` builds a preset.

Sources
-------
- ``thermal-control-film``, ``silicon-solar-cell``: seed paper (Yan et al., Remote Sens. 14,
  2868, 2022), Table 1, 850 nm fits of eqs. (9)-(10).
- ``black-protective-shield``, ``white-matte-tile``, ``black-glossy-tile``: Cook–Torrance
  NLOS relay-wall paper, the per-material averages over θi = 30°, 40°, 50° stated below its
  Table 2 as ``[kd, ks, m, n2]``.
- ``black-flannel``: the black light-absorbing flannel background of the seed paper's ground
  test (its Section 4). The paper gives no reflectance; 0.02 is an assumed value typical of
  black velvet-like absorbers.
- ``white-diffuse`` (0.9), ``grey-diffuse`` (0.5): generic diffuse reference targets.
- ``vesta-regolith``: the regolith of the asteroid 4 Vesta, the SLIM paper's own Hapke fit
  (J. Imaging 6, 84, 2020, Table 5, "this study": ``B = 1.83, ω = 0.45, h = 0.53``), with
  isotropic particles (``phase_b = 0``; the paper fits no phase function). The paper gives no
  lunar parameters; a lunar preset needs a lunar fit from another source. (This preset was
  called ``lunar-regolith`` before, a misnomer for Vesta data.)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from types import MappingProxyType
from typing import Any

from sim_core.errors import InvalidInputError
from sim_core.materials.base import Material
from sim_core.materials.cook_torrance import CookTorrance
from sim_core.materials.hapke import Hapke
from sim_core.materials.lambertian import Lambertian
from sim_core.materials.seed_microfacet import SeedMicrofacet
from sim_core.materials.tabulated import Tabulated

__all__ = ["MATERIAL_KINDS", "PRESETS", "make_material", "material_preset"]

#: material kind -> class
MATERIAL_KINDS: Mapping[str, type[Material]] = MappingProxyType(
    {
        "seed-microfacet": SeedMicrofacet,
        "cook-torrance": CookTorrance,
        "lambertian": Lambertian,
        "hapke": Hapke,
        "tabulated": Tabulated,
    }
)

#: preset name -> (kind, parameters); read-only, ``material_preset`` copies the parameters
PRESETS: Mapping[str, tuple[str, Mapping[str, Any]]] = MappingProxyType(
    {
        "thermal-control-film": (
            "seed-microfacet",
            MappingProxyType(
                {"ks": 0.649, "kd": 0.081, "fresnel_exponent": 8.51, "sigma": 0.014, "f0": 0.775}
            ),
        ),
        "silicon-solar-cell": (
            "seed-microfacet",
            MappingProxyType(
                {"ks": 0.350, "kd": 0.053, "fresnel_exponent": 2.22, "sigma": 0.010, "f0": 0.021}
            ),
        ),
        "black-protective-shield": (
            "cook-torrance",
            MappingProxyType({"kd": 0.00, "ks": 0.79, "m": 0.15, "n2": 2.26}),
        ),
        "white-matte-tile": (
            "cook-torrance",
            MappingProxyType({"kd": 0.78, "ks": 0.20, "m": 0.08, "n2": 1.67}),
        ),
        "black-glossy-tile": (
            "cook-torrance",
            MappingProxyType({"kd": 0.07, "ks": 0.25, "m": 0.06, "n2": 1.46}),
        ),
        "black-flannel": ("lambertian", MappingProxyType({"albedo": 0.02})),
        "white-diffuse": ("lambertian", MappingProxyType({"albedo": 0.9})),
        "grey-diffuse": ("lambertian", MappingProxyType({"albedo": 0.5})),
        "vesta-regolith": (
            "hapke",
            MappingProxyType({"w": 0.45, "b0": 1.83, "h": 0.53, "phase_b": 0.0}),
        ),
    }
)


def make_material(kind: str, **params: Any) -> Material:
    """Build a material of the given ``kind`` from keyword parameters.

    Parameters
    ----------
    kind : {"seed-microfacet", "cook-torrance", "lambertian", "hapke", "tabulated"}
    **params
        The constructor parameters of that model; omitted ones take the model's defaults
        (``"tabulated"`` needs ``table``, a goniometer CSV path).

    Raises
    ------
    InvalidInputError
        For an unknown kind or parameter name (listing the allowed ones) or a parameter value
        outside its range.
    """
    cls = MATERIAL_KINDS.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise InvalidInputError(
            "kind", f"unknown material kind {kind!r}; allowed: {', '.join(MATERIAL_KINDS)}"
        )
    allowed = [f.name for f in fields(cls)]  # type: ignore[arg-type]
    unknown = sorted(set(params) - set(allowed))
    if unknown:
        raise InvalidInputError(
            unknown[0],
            f"unknown parameter(s) {', '.join(unknown)} for material kind {kind!r}; "
            f"allowed: {', '.join(allowed)}",
        )
    return cls(**params)


def material_preset(name: str) -> Material:
    """Build the preset ``name`` (see :data:`PRESETS`).

    Raises
    ------
    InvalidInputError
        For an unknown name, listing the allowed names.
    """
    entry = PRESETS.get(name) if isinstance(name, str) else None
    if entry is None:
        raise InvalidInputError(
            "preset", f"unknown material preset {name!r}; allowed: {', '.join(PRESETS)}"
        )
    kind, params = entry
    return make_material(kind, **dict(params))
