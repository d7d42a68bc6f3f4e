"""Tests of the preset registry and the material factory."""

from __future__ import annotations

import pytest

from sim_core.errors import InvalidInputError
from sim_core.materials import (
    MATERIAL_KINDS,
    PRESETS,
    CookTorrance,
    Hapke,
    Lambertian,
    Material,
    SeedMicrofacet,
    make_material,
    material_preset,
)

EXPECTED_PRESETS = {
    "thermal-control-film": SeedMicrofacet,
    "silicon-solar-cell": SeedMicrofacet,
    "black-protective-shield": CookTorrance,
    "white-matte-tile": CookTorrance,
    "black-glossy-tile": CookTorrance,
    "black-flannel": Lambertian,
    "white-diffuse": Lambertian,
    "grey-diffuse": Lambertian,
    "vesta-regolith": Hapke,
}


def test_every_named_preset_exists_and_builds_its_kind() -> None:
    assert set(PRESETS) == set(EXPECTED_PRESETS)
    for name, cls in EXPECTED_PRESETS.items():
        kind, params = PRESETS[name]
        material = material_preset(name)
        assert isinstance(material, cls)
        assert MATERIAL_KINDS[kind] is cls
        assert material.name == kind
        assert material == make_material(kind, **params)
        assert 0.0 <= material.albedo_bound <= 1.0


@pytest.mark.parametrize(
    ("kind", "params", "cls"),
    [
        ("seed-microfacet", {"ks": 0.2, "sigma": 0.5}, SeedMicrofacet),
        ("cook-torrance", {"m": 0.3, "fresnel_angle": "half"}, CookTorrance),
        ("lambertian", {"albedo": 0.1}, Lambertian),
        ("hapke", {"w": 0.2}, Hapke),
        ("hapke", {}, Hapke),
    ],
)
def test_make_material_builds_each_kind_with_defaults_for_missing_parameters(
    kind: str, params: dict[str, object], cls: type[Material]
) -> None:
    material = make_material(kind, **params)
    assert isinstance(material, cls)
    for key, value in params.items():
        assert getattr(material, key) == value


def test_unknown_kind_is_rejected_listing_the_allowed_kinds() -> None:
    with pytest.raises(InvalidInputError) as excinfo:
        make_material("phong", shininess=10)
    assert excinfo.value.field == "kind"
    message = str(excinfo.value)
    assert "'phong'" in message
    for kind in ("seed-microfacet", "cook-torrance", "lambertian", "hapke"):
        assert kind in message


def test_unknown_parameter_is_rejected_listing_the_allowed_parameters() -> None:
    with pytest.raises(InvalidInputError) as excinfo:
        make_material("cook-torrance", roughness=0.3)
    assert excinfo.value.field == "roughness"
    assert "kd, ks, m, n2, fresnel_angle" in str(excinfo.value)


def test_invalid_parameter_value_is_reported_by_the_factory_too() -> None:
    with pytest.raises(InvalidInputError, match=r"albedo = 2 is outside \[0, 1\]"):
        make_material("lambertian", albedo=2)


def test_unknown_preset_is_rejected_listing_the_allowed_names() -> None:
    with pytest.raises(InvalidInputError) as excinfo:
        material_preset("gold")
    assert excinfo.value.field == "preset"
    message = str(excinfo.value)
    assert "'gold'" in message
    for name in EXPECTED_PRESETS:
        assert name in message


def test_preset_registry_is_read_only() -> None:
    with pytest.raises(TypeError):
        PRESETS["new"] = ("lambertian", {"albedo": 0.1})  # type: ignore[index]
    with pytest.raises(TypeError):
        PRESETS["grey-diffuse"][1]["albedo"] = 0.9  # type: ignore[index]


def test_materials_are_immutable() -> None:
    material = material_preset("grey-diffuse")
    with pytest.raises(AttributeError):
        material.albedo = 0.9  # type: ignore[misc]
