"""Scene and calibration values are checked against physical ranges where they are parsed
(issue 25, items 2 and 3), so that nothing that passes validation makes a simulation raise.

Property tests: values drawn over and beyond the accepted ranges are either refused, by a
:class:`~sim_core.errors.InvalidInputError` naming the field and the range, or they build and
run the code path that failed (the optics and the render of a tiny frame, the depth errors, a
board's pattern) with every warning an error (an overflow is a failure too).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sim_core.boards import board_triangles, markers_needed
from sim_core.camera import z_over_range
from sim_core.depth_errors import DepthErrorModel
from sim_core.errors import InvalidInputError, SceneError
from sim_core.lens_ranges import focal_length_range_px
from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import parse_scene_spec
from sim_core.twin_file import parse_calibration

PLATE = {"name": "plate", "mesh": {"kind": "rectangle", "size_m": [2.0, 2.0]},
         "material": {"kind": "lambertian", "params": {"albedo": 0.5}},
         "pose": {"position_m": [0.0, 0.0, 1.0]}, "on_turntable": True}
POSE = {"position_m": [0, 0, 0], "look_at_m": [0, 0, 1], "up": [0, -1, 0]}
TURNTABLE = {"axis_point_m": [0.0, 0.0, 1.0], "axis_direction": [0.0, 1.0, 0.0]}
TINY = RenderSettings(integrator="direct", spp=1, max_bounces=1, threads=1)
PROPERTY = settings(max_examples=40, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])

#: any float a file may hold, from the tiny to the huge, both signs
anything = st.one_of(
    st.floats(-1e6, 1e6),
    st.builds(lambda m, e: m * 10.0**e, st.floats(-1.0, 1.0), st.integers(-300, 300)),
)


def _scene(camera: dict, **more) -> dict:
    return {"camera": {"pose": POSE, **camera}, "objects": [PLATE], "turntable": TURNTABLE,
            **more}


def _renders(spec, twin=None) -> None:
    """Build the scene and simulate a frame, warnings as errors; the frame is finite."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = build_scene(spec, ".", twin=twin)
        assert np.all(np.isfinite(z_over_range(scene.camera.intrinsics)))
        frame = simulate(scene, RenderRequest(TINY))
    valid = frame.image.valid
    assert np.all(np.isfinite(frame.image.range_m[valid]))


def _refused(err: InvalidInputError, prefix: str) -> None:
    assert err.field.startswith(prefix), err
    assert any(w in err.message for w in ("outside", "allowed", "less than", "greater than")), err


# -- the camera of a scene ------------------------------------------------------------------------
@PROPERTY
@given(width=st.integers(4, 24), height=st.integers(4, 24),
       fov=st.tuples(st.floats(1.0, 170.0), st.floats(1.0, 170.0)),
       centre=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)))
def test_intrinsics_inside_the_ranges_are_accepted_and_render(width, height, fov, centre):
    fx = 0.5 * width / math.tan(math.radians(fov[0] / 2.0))
    fy = 0.5 * height / math.tan(math.radians(fov[1] / 2.0))
    camera = {"width_px": width, "height_px": height, "fx_px": fx, "fy_px": fy,
              "cx_px": -0.5 + centre[0] * width, "cy_px": -0.5 + centre[1] * height}
    _renders(parse_scene_spec(_scene(camera)))


@PROPERTY
@given(width=st.integers(4, 24), height=st.integers(4, 24),
       values=st.fixed_dictionaries({}, optional={
           "fx_px": anything, "fy_px": anything, "cx_px": anything, "cy_px": anything}),
       distortion=st.fixed_dictionaries({}, optional={
           "k1": st.floats(-2.0, 2.0), "k2": st.floats(-2.0, 2.0), "p1": st.floats(-0.1, 0.1),
           "p2": st.floats(-0.1, 0.1), "k3": st.floats(-2.0, 2.0)}))
def test_any_intrinsics_are_refused_by_field_and_range_or_render(width, height, values,
                                                                 distortion):
    camera = {"width_px": width, "height_px": height, **values, "distortion": distortion}
    try:
        spec = parse_scene_spec(_scene(camera))
    except SceneError as err:
        _refused(err, "camera.")
        return
    _renders(spec)


@pytest.mark.parametrize(("field", "value", "size"), [
    ("fx_px", 1e-300, 224), ("fx_px", 1e300, 224), ("fx_px", 9.7, 224), ("fy_px", 7.4, 171),
    ("fy_px", 2e9, 171),
])
def test_a_focal_length_outside_its_range_is_refused(field, value, size):
    lo, hi = focal_length_range_px(size)
    with pytest.raises(SceneError) as err:
        parse_scene_spec(_scene({field: value}))
    assert err.value.field == f"camera.{field}"
    assert f"[{lo:.4g}, {hi:.4g}] px" in err.value.message
    assert "at most 170 deg, a pixel at least 1e-09 rad" in err.value.message


def test_distortion_that_folds_the_image_is_refused_and_a_real_lens_is_not():
    real = {"k1": -0.11, "k2": 0.04, "p1": 0.0005, "p2": -0.0004, "k3": 0.0}
    assert parse_scene_spec(_scene({"distortion": real})).camera.distortion.k1 == -0.11
    with pytest.raises(SceneError) as err:
        parse_scene_spec(_scene({"distortion": {"k1": -1.0}}))  # folds at r = 0.58 < 0.68
    assert err.value.field == "camera.distortion", err.value
    assert "fold" in err.value.message or "cannot be inverted" in err.value.message
    with pytest.raises(SceneError) as err:
        parse_scene_spec(_scene({"distortion": {"k1": 1e300}}))
    assert err.value.field == "camera.distortion.k1"


# -- directions -----------------------------------------------------------------------------------
@PROPERTY
@given(axis=st.tuples(anything, anything, anything), up=st.tuples(anything, anything, anything),
       sun=st.tuples(anything, anything, anything))
def test_directions_are_refused_by_length_or_render(axis, up, sun):
    data = _scene({}, ambient={"sun": {"direction": list(sun)}})
    data["turntable"] = {**TURNTABLE, "axis_direction": list(axis)}
    data["camera"]["pose"] = {**POSE, "up": list(up)}
    try:
        spec = parse_scene_spec(data)
    except SceneError as err:
        assert err.field in ("turntable.axis_direction", "camera.pose.up",
                             "ambient.sun.direction"), err
        assert "length" in err.message, err
        return
    try:
        _renders(spec)
    except InvalidInputError as err:  # an up vector along the view: refused when posed
        assert err.field == "camera.pose.up" and "parallel" in err.message, err


def test_a_turntable_axis_must_be_a_unit_vector():
    with pytest.raises(SceneError, match=r"turntable\.axis_direction: .*1e\+308.*1 \+- 0\.01"):
        parse_scene_spec(_scene({}, turntable={"axis_direction": [1e308, 0.0, 0.0]}))
    spec = parse_scene_spec(_scene({}, turntable={"axis_direction": [0.0, 1.005, 0.0]}))
    assert spec.turntable.axis_direction == (0.0, 1.005, 0.0)  # normalised when used


# -- boards ---------------------------------------------------------------------------------------
DICTIONARIES = ["DICT_4X4_50", "DICT_4X4_100", "DICT_5X5_50", "DICT_6X6_250", "DICT_7X7_1000",
                "DICT_ARUCO_ORIGINAL", "DICT_APRILTAG_36H11"]


@PROPERTY
@given(sx=st.integers(3, 40), sy=st.integers(3, 40), square_m=st.floats(0.001, 0.5),
       marker=st.floats(0.05, 0.99), dictionary=st.sampled_from(DICTIONARIES))
def test_a_board_is_refused_by_its_sizes_or_builds(sx, sy, square_m, marker, dictionary):
    mesh = {"kind": "charuco_board", "squares_x": sx, "squares_y": sy, "square_m": square_m,
            "marker_m": marker * square_m, "dictionary": dictionary}
    data = {"camera": {"pose": POSE}, "objects": [{"name": "b", "mesh": mesh}]}
    try:
        spec = parse_scene_spec(data)
    except SceneError as err:
        assert err.field == "objects[0].mesh", err
        assert "allowed" in err.message or "holds" in err.message, err
        return
    tris, white = board_triangles(spec.objects[0].mesh)
    assert len(tris) > 0 and set(np.unique(white)) <= {0, 1}


def test_a_board_with_more_squares_than_its_dictionary_has_markers_is_refused():
    mesh = {"kind": "charuco_board", "squares_x": 40, "squares_y": 40, "square_m": 0.1,
            "marker_m": 0.06}
    with pytest.raises(SceneError) as err:
        parse_scene_spec({"camera": {"pose": POSE}, "objects": [{"name": "b", "mesh": mesh}]})
    assert err.value.field == "objects[0].mesh"
    assert f"needs {markers_needed(40, 40)} markers; DICT_4X4_50 holds 50" in err.value.message


# -- the depth errors of a calibration ------------------------------------------------------------
wiggling_term = st.fixed_dictionaries(
    {"harmonic": st.integers(1, 16), "amplitude_rad": st.floats(0.0, 0.5)},
    optional={"phase_rad": st.floats(-10.0, 10.0), "frequency_index": st.integers(0, 1)})


@PROPERTY
@given(terms=st.lists(wiggling_term, max_size=4), step=st.integers(1, 64),
       extra=st.tuples(st.integers(-2, 2), st.integers(-2, 2)), grid=st.booleans())
def test_depth_errors_are_refused_by_field_and_range_or_apply_and_invert(terms, step, extra,
                                                                          grid):
    depth: dict = {"wiggling": terms}
    if grid:
        rows = max(1, -(-170 // step) + 1 + extra[0])
        cols = max(1, -(-223 // step) + 1 + extra[1])
        depth["pixel_offset_m"] = {"grid_step_px": step, "offsets_mm": [[1.0] * cols] * rows}
    try:
        cal = parse_calibration({"camera": {"depth": depth}})
    except InvalidInputError as err:
        assert err.field in ("calibration.camera.depth.wiggling",
                             "calibration.camera.depth"), err  # (its pixel_offset_m)
        assert "allowed: below 0.5" in err.message or "does not cover" in err.message, err
        return
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = DepthErrorModel.from_spec(cal.camera.depth, (80.32e6, 60.24e6), (171, 224))
        phi = np.linspace(0.0, 6.2, 171 * 224).reshape(171, 224)
        measured = np.angle(model.apply_to_phasor(np.exp(-1j * np.stack([phi, phi]))))
        back = model.correct_phase(np.mod(-measured, 2 * np.pi))
    assert np.all(np.isfinite(back))


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(fx=st.floats(150.0, 300.0), cx=st.floats(-0.5, 223.5),
       k=st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), st.floats(-0.01, 0.01),
                   st.floats(-0.01, 0.01), st.floats(-0.3, 0.3)),
       axis=st.tuples(st.floats(-0.1, 0.1), st.floats(0.99, 1.0), st.floats(-0.1, 0.1)))
def test_a_calibration_that_parses_renders_on_the_preset(fx, cx, k, axis):
    data = {"camera": {"fx_px": fx, "cx_px": cx,
                       "distortion": dict(zip(("k1", "k2", "p1", "p2", "k3"), k, strict=True))},
            "turntable": {"axis_direction": list(axis)}}
    try:
        cal = parse_calibration(data)
    except InvalidInputError as err:
        _refused(err, "calibration.")
        return
    _renders(parse_scene_spec(_scene({})), twin=cal)


@PROPERTY
@given(position=st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(0.5, 3.0)),
       size=st.tuples(st.floats(0.01, 5.0), st.floats(0.01, 5.0)),
       rotation=st.tuples(st.floats(-720.0, 720.0), st.floats(-720.0, 720.0),
                          st.floats(-720.0, 720.0)),
       wild=st.sampled_from([None, ("position", 0), ("position", 2), ("size", 0), ("size", 1),
                             ("rotation", 1)]),
       wild_value=anything)
def test_positions_sizes_and_rotations_are_refused_by_field_and_range_or_render(
        position, size, rotation, wild, wild_value):
    """A plate a lab would use with one value drawn from anything at all: refused naming the
    field and its range (1e308 m boxes were accepted, gave NaN vertices and failed an object
    fit), or it renders."""
    values = {"position": list(position), "size": list(size), "rotation": list(rotation)}
    if wild is not None:
        values[wild[0]][wild[1]] = wild_value
    plate = {**PLATE, "mesh": {"kind": "rectangle", "size_m": values["size"]},
             "on_turntable": False,
             "pose": {"position_m": values["position"], "rotation_deg": values["rotation"]}}
    try:
        spec = parse_scene_spec({"camera": {"pose": POSE, "width_px": 8, "height_px": 6,
                                            "fx_px": 8.0, "fy_px": 8.0},
                                 "objects": [plate]})
    except SceneError as err:
        fields = ("objects[0].mesh.size_m", "objects[0].pose.position_m",
                  "objects[0].pose.rotation_deg")
        assert any(f in str(err) for f in fields), err
        assert "than or equal to" in str(err), err
        return
    _renders(spec)
