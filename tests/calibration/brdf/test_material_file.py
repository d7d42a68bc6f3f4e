"""A fit's material file: written atomically, referenced by a scene as ``material: {file}``."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from calibration.brdf import fit_brdf
from calibration.brdf.material_file import write_material_file
from sim_core.errors import SceneError
from sim_core.materials import make_material
from sim_core.materials.material_file import read_material_file
from sim_core.scene import build_material, build_scene, inline_material_files
from sim_core.scene_spec import MaterialSpec, parse_scene_spec
from tests.calibration.brdf.synthetic import measure


@pytest.fixture(scope="module")
def fit():
    syn = measure(make_material("lambertian", albedo=0.4), 2, noise=0.03)
    return fit_brdf(syn.table, "lambertian", seed=2)


def _scene(material: dict) -> dict:
    return {
        "camera": {"preset": "pmd-camboard-pico-flexx",
                   "pose": {"position_m": [0, 0, 0], "look_at_m": [0, 0, 1], "up": [0, 1, 0]}},
        "objects": [{"name": "target", "mesh": {"kind": "rectangle", "size_m": [0.3, 0.3]},
                     "pose": {"position_m": [0, 0, 1.0]}, "material": material}],
    }


def test_written_file_holds_the_spec_and_the_report(tmp_path, fit):
    path = write_material_file(tmp_path / "sub" / "fit.yaml", fit)
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert {"kind": data["kind"], "params": data["params"]} == fit.material_spec()
    assert data["fit"]["e_fit"] == pytest.approx(fit.e_fit)
    assert sum(s["outlier"] for s in data["fit"]["samples"]) == fit.n_outliers
    assert [p.name for p in path.parent.iterdir()] == ["fit.yaml"]  # no temporary left over
    assert read_material_file(path) == (fit.kind, fit.params)


def test_scene_references_the_file_relative_to_its_folder(tmp_path, fit):
    write_material_file(tmp_path / "materials" / "fit.yaml", fit)
    spec = parse_scene_spec(_scene({"file": "materials/fit.yaml"}))
    scene = build_scene(spec, tmp_path)
    mat = scene.materials[0]
    assert mat == make_material("lambertian", albedo=fit.params["albedo"])
    # params adjust a file's values like a preset's
    adjusted = build_material(MaterialSpec(file="materials/fit.yaml", params={"albedo": 0.1}),
                              "m", tmp_path)
    assert adjusted.albedo == 0.1
    # a worker without the scene's folder gets the material inlined
    inlined = inline_material_files(spec, tmp_path)
    assert inlined.objects[0].material.kind == "lambertian"
    assert inlined.objects[0].material.file is None
    assert build_scene(inlined, tmp_path / "elsewhere").materials[0] == mat


def test_errors_name_the_field(tmp_path):
    spec = parse_scene_spec(_scene({"file": "missing.yaml"}))
    with pytest.raises(SceneError) as err:
        build_scene(spec, tmp_path)
    assert err.value.field == "objects[0].material.file"
    assert "does not exist" in str(err.value)
    (tmp_path / "bad.yaml").write_text("kind: lambertian\nparams: {albedo: 1.5}\n")
    with pytest.raises(SceneError) as err:
        build_scene(parse_scene_spec(_scene({"file": "bad.yaml"})), tmp_path)
    assert err.value.field == "objects[0].material.file" and "albedo" in str(err.value)
    (tmp_path / "typo.yaml").write_text("kind: lambertian\nparam: {albedo: 0.5}\n")
    with pytest.raises(SceneError, match="unknown key"):
        build_scene(parse_scene_spec(_scene({"file": "typo.yaml"})), tmp_path)
    with pytest.raises(SceneError) as err:
        inline_material_files(spec, tmp_path)
    assert err.value.field == "objects[0].material.file"


@pytest.mark.parametrize("material", [
    {"file": "a.yaml", "preset": "white-diffuse"},
    {"file": "a.yaml", "kind": "lambertian"},
    {"params": {"albedo": 0.5}},
])
def test_exactly_one_of_preset_kind_file(material):
    with pytest.raises((ValidationError, SceneError), match="exactly one"):
        parse_scene_spec(_scene(material))


def test_material_file_values_reach_the_renderer(tmp_path, fit):
    write_material_file(tmp_path / "fit.yaml", fit)
    scene = build_scene(parse_scene_spec(_scene({"file": "fit.yaml"})), tmp_path)
    wi = np.array([[0.0, 0.0, 1.0]])
    assert scene.materials[0].eval_local(wi, wi)[0] == pytest.approx(fit.params["albedo"] / np.pi)
