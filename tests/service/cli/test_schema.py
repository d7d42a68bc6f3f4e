"""``toftwin schema scene``: the committed schema is current and the bundled examples pass it."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from service.cli import app
from service.cli.schema import SCENE_SCHEMA_FILE, SCHEMAS, scene_schema, schema_text

ROOT = Path(__file__).resolve().parents[3]
COMMITTED = ROOT / SCENE_SCHEMA_FILE
EXAMPLES = sorted((ROOT / "examples").glob("*.yaml"))
REGENERATE = f"toftwin schema scene --out {SCENE_SCHEMA_FILE}"
runner = CliRunner()


def test_schema_scene_prints_the_schema():
    res = runner.invoke(app, ["schema", "scene"])
    assert res.exit_code == 0, res.output
    printed = json.loads(res.stdout)
    assert printed == scene_schema()
    jsonschema.Draft202012Validator.check_schema(printed)


def test_schema_scene_writes_the_file(tmp_path):
    out = tmp_path / "sub" / "scene.schema.json"
    res = runner.invoke(app, ["schema", "scene", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert out.read_text(encoding="utf-8") == schema_text(scene_schema())


def test_the_committed_schema_is_current():
    assert COMMITTED.is_file(), f"{SCENE_SCHEMA_FILE} is missing; make it with `{REGENERATE}`"
    committed = COMMITTED.read_text(encoding="utf-8")
    assert committed == schema_text(scene_schema()), (
        f"{SCENE_SCHEMA_FILE} differs from the scene models (sim_core/scene_spec.py); "
        f"regenerate it with `{REGENERATE}` and commit it")


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(json.loads(COMMITTED.read_text(encoding="utf-8")))


def test_there_are_examples():
    assert len(EXAMPLES) >= 3


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_every_example_validates_against_the_schema(validator, path):
    scene = yaml.safe_load(path.read_text(encoding="utf-8"))
    errors = [f"{'.'.join(map(str, e.absolute_path))}: {e.message}"
              for e in validator.iter_errors(scene)]
    assert not errors, f"{path.name}: {errors}"


def test_the_schema_rejects_what_the_loader_rejects(validator):
    scene = yaml.safe_load(EXAMPLES[0].read_text(encoding="utf-8"))
    assert validator.is_valid(scene)
    assert not validator.is_valid({**scene, "colour": "red"})  # unknown field
    assert not validator.is_valid({**scene, "render": {"spp": 0}})  # below the range
    assert not validator.is_valid({k: v for k, v in scene.items() if k != "camera"})


# -- the other files' schemas (issue 29): calibration, reality, object twin -------------------
@pytest.mark.parametrize("name", sorted(set(SCHEMAS) - {"scene"}))
def test_every_committed_schema_is_current_and_printed(name):
    from service.cli.schema import schema_of

    path = ROOT / SCHEMAS[name]
    assert path.is_file(), f"{SCHEMAS[name]} is missing: `toftwin schema {name} --out {path}`"
    assert path.read_text(encoding="utf-8") == schema_text(schema_of(name)), (
        f"{SCHEMAS[name]} differs from its models; regenerate it with `toftwin schema {name} "
        f"--out {SCHEMAS[name]}` and commit it")
    res = runner.invoke(app, ["schema", name])
    assert res.exit_code == 0 and json.loads(res.stdout) == schema_of(name)
    jsonschema.Draft202012Validator.check_schema(json.loads(res.stdout))


def _validator(name: str) -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(
        json.loads((ROOT / SCHEMAS[name]).read_text(encoding="utf-8")))


def _errors(validator, data) -> list[str]:
    return [f"{'.'.join(map(str, e.absolute_path))}: {e.message}"
            for e in validator.iter_errors(data)]


def test_files_our_commands_write_pass_their_schemas(tmp_path):
    """A calibration as ``write_calibration`` writes it, a random reality with issue 27's
    effects as the tests' lab is given it, an object twin as ``write_object_twin`` (the object
    fit's writer) writes it, and a hand-written drift of one number: each passes its schema,
    and the model that reads the file takes it."""
    from sim_core.twin_file import (
        ObjectTwinFile,
        load_object_twin,
        load_reality,
        parse_calibration,
        parse_reality,
        write_calibration,
        write_object_twin,
    )
    from tests.calibration.realities import random_reality, with_world_effects
    from tests.service.api.test_calibration import CALIBRATION

    path = write_calibration(tmp_path / "calibration.yaml", parse_calibration(CALIBRATION))
    assert not _errors(_validator("calibration"), yaml.safe_load(path.read_text()))

    reality = with_world_effects(random_reality(151, object_twin_names=["body"]), 151)
    (tmp_path / "reality.yaml").write_text(yaml.safe_dump(reality.model_dump(mode="json")))
    data = yaml.safe_load((tmp_path / "reality.yaml").read_text())
    assert not _errors(_validator("reality"), data)
    assert load_reality(tmp_path / "reality.yaml") == reality

    obj = ObjectTwinFile.model_validate({
        "mount": {"pose_offset": {"position_m": [0.001, -0.002, 0.0],
                                  "rotation_deg": [0.1, 0.0, -0.2]}},
        "objects": {"body": {"reflectance_scale": 0.95}},
        "provenance": {"rig": "simulated"}})
    path = write_object_twin(tmp_path / "object.yaml", obj)
    assert not _errors(_validator("object"), yaml.safe_load(path.read_text()))
    assert load_object_twin(path) == obj

    # what a user writes by hand in the forms the loaders take: the drift as one number
    by_hand = {"camera": {"temperature": {"illumination_start_c": 25.0,
                                          "illumination_end_c": 45.0, "time_constant_s": 600.0,
                                          "depth_drift_mm_per_c": 0.3}}}
    for name, parse in (("calibration", parse_calibration), ("reality", parse_reality)):
        assert not _errors(_validator(name), by_hand), name
        assert parse(by_hand).camera.temperature.depth_drift_mm_per_c == [0.3]


@pytest.mark.parametrize(("name", "data"), [
    ("calibration", {"camera": {"fx": 210.0}}),  # an unknown key
    ("calibration", {"turntable": {"settling": {"amplitude_deg": -1.0, "frequency_hz": 2.0,
                                                "damping_ratio": 0.1}}}),  # below its range
    ("reality", {"camera": {"stray_light": {"fraction": 2.0, "kernel_radius_px": 30.0}}}),
    ("object", {"objects": {"body": {"reflectance_scale": "bright"}}}),
    ("calibration", {"camera": {"temperature": {
        "illumination_start_c": 25.0, "illumination_end_c": 45.0, "time_constant_s": 600.0,
        "depth_drift_mm_per_c": [0.1, 0.2, 0.3, 0.4, 0.5]}}}),  # more frequencies than any
])
def test_the_schemas_reject_what_the_loaders_reject(name, data):
    from sim_core.errors import InvalidInputError
    from sim_core.twin_file import parse_calibration, parse_object_twin, parse_reality

    assert _errors(_validator(name), data)
    parse = {"calibration": parse_calibration, "reality": parse_reality,
             "object": parse_object_twin}[name]
    with pytest.raises(InvalidInputError):
        parse(data)


# -- the material file and frame.json (issue 29) -----------------------------------------------
def test_a_fitted_material_file_passes_its_schema_and_reads(tmp_path):
    """A material file as ``toftwin calibrate brdf`` writes it passes the schema, and the
    loader and the model take it alike."""
    from calibration.brdf import fit_brdf
    from calibration.brdf.material_file import write_material_file
    from sim_core.materials import make_material
    from sim_core.materials.material_file import MaterialFile, read_material_file
    from tests.calibration.brdf.synthetic import measure

    fit = fit_brdf(measure(make_material("lambertian", albedo=0.4), 2, noise=0.03).table,
                   "lambertian", seed=2)
    path = write_material_file(tmp_path / "fit.yaml", fit)
    data = yaml.safe_load(path.read_text())
    assert not _errors(_validator("material"), data)
    model = MaterialFile.model_validate(data)
    assert read_material_file(path) == (model.kind, model.params)


_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=5),
                    st.booleans(), st.none(), st.lists(st.integers(), max_size=2))


@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.dictionaries(
    st.sampled_from(["kind", "params", "fit", "kd", "preset"]),
    st.one_of(st.sampled_from(["lambertian", "cook-torrance", "hapke", "marble"]),
              st.dictionaries(st.sampled_from(["albedo", "kd", "m", "fresnel_angle"]), _VALUES,
                              max_size=3), _VALUES), max_size=4))
def test_the_material_schema_takes_what_the_loader_takes(tmp_path_factory, data):
    """On random documents: what the schema accepts the loader reads; what the loader reads
    with a known material kind the schema accepts (the loader leaves the kind to the scene)."""
    from sim_core.errors import InvalidInputError
    from sim_core.materials import MATERIAL_KINDS
    from sim_core.materials.material_file import read_material_file

    path = tmp_path_factory.mktemp("material") / "m.json"
    try:
        path.write_text(json.dumps(data, allow_nan=False))
    except ValueError:  # NaN or inf: no JSON document at all
        return
    try:
        read_material_file(path)
        loads = True
    except InvalidInputError:
        loads = False
    valid = not _errors(_validator("material"), data)
    if valid:
        assert loads, data
    if loads and data.get("kind") in MATERIAL_KINDS:
        assert valid, (data, _errors(_validator("material"), data))


def test_frame_json_of_each_kind_passes_its_schema_and_states_the_camera(tmp_path):
    """A simulated frame's and a measured frame's frame.json pass the schema; the model's
    intrinsics are the ones the frame reader uses, and a simulated frame carries its pose."""
    from sim_core import frame_io
    from sim_core.frame_meta import FrameJson
    from sim_core.pipeline import save_frame, simulate
    from sim_core.render import RenderSettings
    from sim_core.render_request import RenderRequest
    from tests.sim_core.scenes import small_example

    scene = small_example("corner", width=16)
    frame = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=1)))
    sim = save_frame(tmp_path / "sim", frame, scene_name="corner")
    frame_io.write_measured(tmp_path / "meas", frame.raw, scene.camera,
                            {"frame_id": "b" * 32, "rig": {"turntable_deg": 5.0}})
    for folder in (sim, tmp_path / "meas"):
        data = json.loads((folder / frame_io.FRAME_JSON).read_text())
        assert not _errors(_validator("frame"), data), folder
        model = FrameJson.model_validate(data)
        intr = frame_io.intrinsics_from_meta(data, tuple(data["shape"]))
        assert model.intrinsics is not None
        assert model.intrinsics.model_dump() == frame_io.intrinsics_dict(intr)
        assert intr == scene.camera.intrinsics
    assert FrameJson.model_validate(json.loads((sim / "frame.json").read_text())) \
        .world_from_camera == scene.camera.world_from_camera.tolist()
    broken = {**data, "shape": [171], "world_from_camera": [[1.0, 0.0]]}
    assert len(_errors(_validator("frame"), broken)) == 2
