"""Our scene as a Mitsuba 3 scene (sim_core.mitsuba_scene): the XML and its PLY meshes read back
with xml.etree and numpy, the ``load_dict`` form against the XML, and the refusals of what
Mitsuba cannot match. Rendering the export in Mitsuba: tests/service/cli/test_export_mitsuba.py.
"""

from __future__ import annotations

import math
import types
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from sim_core import mitsuba_scene as ms
from sim_core.camera import Camera, Intrinsics, look_at
from sim_core.errors import InvalidInputError
from sim_core.scene import build_scene
from sim_core.scene_spec import parse_scene_spec
from tests.sim_core.scenes import EXAMPLES, example

#: a stand-in for the ``mitsuba`` module: the one function the dictionary writer calls
FAKE_MI = types.SimpleNamespace(ScalarTransform4f=lambda rows: ("transform", np.array(rows)))


@pytest.fixture(scope="module")
def corner():
    return example("corner")


@pytest.fixture
def exported(corner, tmp_path):
    desc = ms.describe_scene(corner, spp=32, bounces=3)
    xml_path = ms.write_scene_xml(desc, tmp_path)
    return desc, xml_path, ET.parse(xml_path).getroot()


def _read_ply(path: Path) -> np.ndarray:
    """The ``(n, 3, 3)`` float32 triangles of one of our binary PLY files."""
    head, body = path.read_bytes().split(b"end_header\n", 1)
    lines = head.decode("ascii").splitlines()
    assert lines[:2] == ["ply", "format binary_little_endian 1.0"]
    n_vertex = int(next(ln for ln in lines if ln.startswith("element vertex")).split()[-1])
    n_face = int(next(ln for ln in lines if ln.startswith("element face")).split()[-1])
    assert n_vertex == 3 * n_face and len(body) == 12 * n_vertex + 13 * n_face
    faces = np.frombuffer(body[12 * n_vertex:], dtype=[("k", "u1"), ("i", "<i4", (3,))])
    assert (faces["k"] == 3).all()
    np.testing.assert_array_equal(faces["i"].ravel(), np.arange(n_vertex))
    return np.frombuffer(body[:12 * n_vertex], "<f4").reshape(n_face, 3, 3)


def _value(el: ET.Element):
    """A property element's value as the dictionary form holds it."""
    if el.tag == "float":
        return float(el.get("value"))
    if el.tag == "integer":
        return int(el.get("value"))
    if el.tag == "boolean":
        return {"true": True, "false": False}[el.get("value")]
    if el.tag == "string":
        return el.get("value")
    if el.tag == "point":
        return [float(el.get(k)) for k in "xyz"]
    if el.tag == "transform":
        (matrix,) = list(el)
        assert matrix.tag == "matrix"
        return ("transform", np.array([float(v) for v in matrix.get("value").split()])
                .reshape(4, 4))
    raise AssertionError(f"unexpected property element {el.tag}")


PLUGINS = {"sensor", "sampler", "film", "rfilter", "emitter", "shape", "bsdf", "integrator"}


def _xml_as_dict(el: ET.Element, folder: Path) -> dict:
    """An XML plugin element as a ``load_dict`` dictionary: nested plugins under their id,
    name or tag, files made absolute against the XML's folder."""
    out = {"type": el.get("type", "scene")}
    for child in el:
        if not isinstance(child.tag, str):  # a comment
            continue
        if child.tag in PLUGINS:
            key = child.get("id") or child.get("name") or child.tag
            assert key not in out, key
            out[key] = _xml_as_dict(child, folder)
        else:
            value = _value(child)
            out[child.get("name")] = (str(folder / value) if child.get("name") == "filename"
                                      else value)
    return out


def _assert_same(a, b, where="scene"):
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), (where, sorted(a), sorted(b))
        for k in a:
            _assert_same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, tuple):
        assert isinstance(b, tuple) and a[0] == b[0], where
        np.testing.assert_array_equal(a[1], b[1], err_msg=where)
    else:
        assert a == b and type(a) is type(b), (where, a, b)


# -------------------------------------------------------------------------------------------
def test_the_xml_is_well_formed_and_holds_sensor_light_and_integrator(corner, exported):
    _, xml_path, root = exported
    assert xml_path.name == "scene.xml"
    assert xml_path.read_text().startswith("<?xml")
    assert root.tag == "scene" and root.get("version") == "3.0.0"

    (sensor,) = root.findall("sensor")
    assert sensor.get("type") == "perspective"
    intr = corner.camera.intrinsics
    fov = float(sensor.find("float[@name='fov']").get("value"))
    assert fov == pytest.approx(2.0 * math.degrees(math.atan(intr.width_px / (2 * intr.fx_px))),
                                rel=1e-15)
    assert 50.0 < fov < 60.0  # the pico flexx preset: about 56 deg across
    assert sensor.find("string[@name='fov_axis']").get("value") == "x"
    for axis, c, n in (("x", intr.cx_px, intr.width_px), ("y", intr.cy_px, intr.height_px)):
        offset = float(sensor.find(f"float[@name='principal_point_offset_{axis}']").get("value"))
        assert offset == pytest.approx(0.5 - (c + 0.5) / n, abs=1e-15)
    matrix = sensor.find("transform[@name='to_world']/matrix")
    to_world = np.array([float(v) for v in matrix.get("value").split()]).reshape(4, 4)
    # the exact float64 of ours with x and y negated (Mitsuba's x left, y up)
    np.testing.assert_array_equal(to_world,
                                  corner.camera.world_from_camera @ np.diag([-1, -1, 1, 1.0]))
    np.testing.assert_allclose(to_world[:3, 3], [1.5, 1.5, 1.5])
    np.testing.assert_allclose(to_world[:3, 2], -np.ones(3) / math.sqrt(3), atol=1e-15)
    assert sensor.find("sampler").get("type") == "independent"
    assert sensor.find("sampler/integer[@name='sample_count']").get("value") == "32"
    film = sensor.find("film")
    assert film.get("type") == "hdrfilm" and film.find("rfilter").get("type") == "box"
    assert int(film.find("integer[@name='width']").get("value")) == intr.width_px == 224
    assert int(film.find("integer[@name='height']").get("value")) == intr.height_px == 171

    (light,) = root.findall("emitter")
    assert light.get("type") == "point"
    intensity = float(light.find("float[@name='intensity']").get("value"))
    assert intensity == pytest.approx(corner.light.power_w / (4 * math.pi), rel=1e-15)
    assert intensity == pytest.approx(20.0 / (4 * math.pi), rel=1e-15)
    position = [float(light.find("point[@name='position']").get(k)) for k in "xyz"]
    np.testing.assert_array_equal(position, corner.light.position_m)

    (integrator,) = root.findall("integrator")
    assert integrator.get("type") == "path"
    assert integrator.find("integer[@name='max_depth']").get("value") == "4"  # 3 bounces + 1
    assert integrator.find("integer[@name='rr_depth']").get("value") == "4"  # from bounce 5


def test_the_meshes_lie_beside_the_xml_with_the_scenes_triangles(corner, exported):
    desc, xml_path, root = exported
    shapes = root.findall("shape")
    assert len(shapes) == len(corner.materials) == 3
    total = 0
    for m_idx, shape in enumerate(shapes):
        assert shape.get("type") == "ply" and shape.get("id") == f"material_{m_idx}"
        filename = shape.find("string[@name='filename']").get("value")
        assert filename == f"meshes/material_{m_idx}.ply"  # relative to the XML
        tris = _read_ply(xml_path.parent / filename)
        mine = corner.triangles_m[corner.material_index == m_idx]
        assert tris.shape == mine.shape == (2, 3, 3)
        np.testing.assert_array_equal(tris, mine.astype(np.float32))
        total += tris.shape[0]
        assert shape.find("boolean[@name='face_normals']").get("value") == "true"
        outer = shape.find("bsdf")
        assert outer.get("type") == "twosided"
        assert outer.find("bsdf").get("type") == "diffuse"
        assert float(outer.find("bsdf/float[@name='reflectance']").get("value")) == 0.5
    assert total == corner.n_triangles == desc.n_triangles
    assert sorted(p.name for p in (xml_path.parent / "meshes").iterdir()) == [
        "material_0.ply", "material_1.ply", "material_2.ply"]


def test_the_dictionary_says_what_the_xml_says(corner, exported, tmp_path):
    desc, xml_path, root = exported
    folder = tmp_path / "dict"
    folder.mkdir()
    d = ms.scene_dict(FAKE_MI, desc, folder)
    _assert_same(d, _xml_as_dict(root, folder))
    assert d["sensor"]["to_world"][0] == "transform"  # made by mi.ScalarTransform4f
    for name in ("material_0", "material_1", "material_2"):  # the dictionary's meshes exist
        assert Path(d[name]["filename"]).is_file()
        assert Path(d[name]["filename"]).read_bytes() == (
            xml_path.parent / "meshes" / f"{name}.ply").read_bytes()


def test_the_integrator_matches_our_bounces_and_russian_roulette():
    assert ms.integrator_dict(ms.MitsubaIntegrator.matching(1)) == {
        "type": "path", "max_depth": 2, "rr_depth": 4}
    assert ms.MitsubaIntegrator.matching(5, 2) == ms.MitsubaIntegrator(6, 1)
    assert ms.MitsubaIntegrator.matching(3, 1).rr_depth == 1  # Mitsuba's rr_depth is >= 1


def test_ply_writer(tmp_path):
    tris = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 1], [1, 0, 1], [0, 1, 1]]], float)
    path = ms.write_ply(tmp_path / "m.ply", tris)
    head, body = path.read_bytes().split(b"end_header\n")
    assert b"element vertex 6" in head and b"element face 2" in head
    assert len(body) == 6 * 12 + 2 * 13
    np.testing.assert_array_equal(_read_ply(path), tris)
    assert [p.name for p in tmp_path.iterdir()] == ["m.ply"]  # no temporary file left


# -- what Mitsuba cannot match is refused, naming the field and what is allowed --------------
def _corner_with(**changes):
    data = yaml.safe_load((EXAMPLES / "corner.yaml").read_text())
    for key, value in changes.items():
        section, name = key.split("__")
        if section == "objects":
            data["objects"][0][name] = value
        else:
            data.setdefault(section, {})[name] = value
    return build_scene(parse_scene_spec(data), base_dir=EXAMPLES)


@pytest.mark.parametrize(("intr", "field", "says"), [
    (Intrinsics(224, 171, 200.0, 210.0, 111.5, 85.0), "camera.fy_px", "allowed: fy_px = fx_px"),
    (Intrinsics(224, 171, 200.0, 200.0, 111.5, 85.0, (0.1, 0, 0, 0, 0)), "camera.distortion",
     "allowed: all five coefficients 0"),
], ids=["fx-fy", "distortion"])
def test_a_camera_mitsuba_cannot_match_is_refused(corner, intr, field, says):
    cam = Camera(intr, look_at([1.5, 1.5, 1.5], [0, 0, 0], [0, 0, 1]))
    bad = type(corner)(**{**corner.__dict__, "camera": cam})
    with pytest.raises(InvalidInputError) as err:
        ms.describe_scene(bad)
    assert err.value.field == field and says in str(err.value)


@pytest.mark.parametrize(("changes", "field", "says"), [
    ({"objects__material": "black-glossy-tile"}, "objects[0].material",
     "allowed: lambertian"),
    ({"illumination__angular_profile": [[0.0, 1.0], [60.0, 0.5], [90.0, 0.0]]},
     "illumination.angular_profile", "allowed: none (an isotropic source)"),
    ({"ambient__solar_simulator": {"direction": [-1.0, -1.0, -1.0]}},
     "ambient.solar_simulator", "allowed: no ambient source"),
    ({"ambient__sun": {"direction": [0.0, 0.0, -1.0]}}, "ambient.sun",
     "allowed: no ambient source"),
], ids=["material", "profile", "solar-simulator", "sun"])
def test_a_scene_mitsuba_cannot_match_is_refused(changes, field, says):
    with pytest.raises(InvalidInputError) as err:
        ms.describe_scene(_corner_with(**changes))
    assert err.value.field == field, str(err.value)
    assert says in str(err.value)


def test_a_solar_simulator_with_its_shutter_closed_is_no_ambient_light():
    spec = {"direction": [-1.0, -1.0, -1.0]}
    data = yaml.safe_load((EXAMPLES / "corner.yaml").read_text())
    data["ambient"] = {"solar_simulator": spec}
    scene = build_scene(parse_scene_spec(data), base_dir=EXAMPLES, solar_suns=0.0)
    assert ms.describe_scene(scene).light.intensity_w_sr == pytest.approx(20.0 / (4 * math.pi))


def test_a_boards_cells_are_two_meshes_and_named_by_their_cell():
    data = yaml.safe_load((EXAMPLES / "corner.yaml").read_text())
    board = {"name": "board", "mesh": {"kind": "checkerboard", "squares_x": 4, "squares_y": 3,
                                       "square_m": 0.1},
             "pose": {"position_m": [0.5, 0.5, 0.01], "rotation_deg": [0.0, 0.0, 0.0]}}
    data["objects"].append(board)
    desc = ms.describe_scene(build_scene(parse_scene_spec(data), base_dir=EXAMPLES))
    assert [(m.source, m.reflectance) for m in desc.meshes[3:]] == [
        ("objects[3].mesh.black", 0.04), ("objects[3].mesh.white", 0.85)]
    board["mesh"]["white"] = "black-glossy-tile"
    with pytest.raises(InvalidInputError) as err:
        ms.describe_scene(build_scene(parse_scene_spec(data), base_dir=EXAMPLES))
    assert err.value.field == "objects[3].mesh.white"
