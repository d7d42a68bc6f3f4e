"""object.yaml through a scene: the scene's object_twin key, the combination, the hash."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from calibration.object_twin.pose import mount_model, transform_from_offset
from service.lab.scenes import resolve_scene
from sim_core.errors import InvalidInputError
from sim_core.geometry import transform_triangles
from sim_core.scene import build_scene
from sim_core.scene_spec import ObjectPose, load_scene_spec
from sim_core.twin_file import (
    CalibrationFile,
    IlluminationParameters,
    MountParameters,
    ObjectParameters,
    ObjectTwinFile,
    Provenance,
    load_object_twin,
    twin_hash,
    with_object_twin,
    write_calibration,
    write_object_twin,
)
from tests.sim_core.scenes import EXAMPLES

SCENE = EXAMPLES / "satellite_ground_test.yaml"
OBJECT = ObjectTwinFile(
    mount=MountParameters(pose_offset=ObjectPose(position_m=(0.004, 0.0, -0.002),
                                                 rotation_deg=(0.0, 0.5, 1.0))),
    objects={"body": ObjectParameters(reflectance_scale=0.9)},
    provenance=Provenance(rig="simulated", procedures={"object_fit": {"seconds": 1.0}}))


def test_a_scene_applies_its_object_file_with_its_calibration(tmp_path):
    write_object_twin(tmp_path / "fit" / "object.yaml", OBJECT)
    cal = CalibrationFile(illumination=IlluminationParameters(power_w=1.3))
    write_calibration(tmp_path / "calibration.yaml", cal)
    data = yaml.safe_load(SCENE.read_text())
    data.update(calibration="calibration.yaml", object_twin="fit/object.yaml")
    for o in data["objects"]:  # absolute: the scene file moves to tmp_path
        o["mesh"].pop("path", None)
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(data))
    spec = load_scene_spec(tmp_path / "scene.yaml")
    assert load_object_twin(tmp_path / "fit" / "object.yaml") == OBJECT
    scene = build_scene(spec, tmp_path, turntable_deg=0.0)
    nominal = build_scene(spec.model_copy(update={"calibration": None, "object_twin": None}),
                          tmp_path, turntable_deg=0.0)
    assert scene.light.power_w == pytest.approx(1.3)
    body = spec.objects[0].name
    assert body == "body"
    kd = [m.kd for m, n in zip(scene.materials, scene.object_names, strict=True) if n == body]
    kd0 = [m.kd for m, n in zip(nominal.materials, nominal.object_names, strict=True)
           if n == body]
    assert kd[0] == pytest.approx(0.9 * kd0[0])
    mounted = np.isin(scene.object_index, [i for i, o in enumerate(spec.objects)
                                           if o.on_turntable])
    model = mount_model(spec, tmp_path)
    expected = transform_triangles(model.triangles_m,
                                   transform_from_offset(OBJECT.mount.pose_offset,
                                                         model.axis_point_m))
    np.testing.assert_allclose(scene.triangles_m[mounted], expected, atol=1e-12)
    np.testing.assert_allclose(scene.triangles_m[~mounted], nominal.triangles_m[~mounted])
    assert scene.twin_hash == twin_hash(with_object_twin(cal, OBJECT))


def test_the_hash_covers_the_object_keys_not_the_provenance():
    cal = CalibrationFile()
    a = with_object_twin(cal, OBJECT)
    b = with_object_twin(cal, OBJECT.model_copy(update={"provenance": Provenance(rig="lab")}))
    c = with_object_twin(cal, OBJECT.model_copy(update={
        "objects": {"body": ObjectParameters(reflectance_scale=0.91)}}))
    assert twin_hash(a) == twin_hash(b) != twin_hash(c)
    assert twin_hash(a) != twin_hash(cal)
    assert with_object_twin(cal, None) is cal


def test_an_object_file_naming_no_object_of_the_scene_is_an_error():
    spec = load_scene_spec(SCENE)
    bad = ObjectTwinFile(objects={"antenna": ObjectParameters(reflectance_scale=0.9)})
    with pytest.raises(InvalidInputError) as exc:
        build_scene(spec, EXAMPLES, twin=with_object_twin(None, bad))
    assert exc.value.field == "twin.objects"


def test_an_inline_scene_may_not_name_an_object_file():
    data = yaml.safe_load(SCENE.read_text())
    data["object_twin"] = "object.yaml"
    with pytest.raises(InvalidInputError) as exc:
        resolve_scene(data, EXAMPLES, max_objects=100)
    assert exc.value.field == "scene.object_twin"
