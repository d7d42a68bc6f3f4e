"""The frame format (sim_core.frame_io): round trips of simulated and measured frame folders,
the grey full-scale rule, and the one-home helpers it relies on (range/depth, JSON)."""

import json
import math

import numpy as np
import pytest
from PIL import Image

from sim_core import frame_io
from sim_core.camera import depth_z_to_range, range_to_depth_z, z_over_range
from sim_core.json_safe import json_safe
from sim_core.pipeline import save_frame, simulate
from sim_core.raw import reconstruct_raw
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from tests.sim_core.scenes import small_example


def _strict_json(path):
    def reject(token):
        raise AssertionError(f"non-strict JSON token {token} in {path.name}")

    return json.loads(path.read_text(), parse_constant=reject)


@pytest.fixture(scope="module")
def sim_frame():
    scene = small_example("satellite_ground_test", width=24)
    return scene, simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=2, seed=5)))


def test_simulated_frame_round_trips(tmp_path, sim_frame):
    _, frame = sim_frame
    out = save_frame(tmp_path / "sim", frame, scene_name="sat")
    assert {p.name for p in out.iterdir()} == set(frame_io.FRAME_FILES)
    back = frame_io.read_frame(out)
    assert back.kind == "simulated"
    for name in ("range_m", "depth_z_m", "amplitude", "intensity", "phase_rad", "valid",
                 "frequencies_hz"):
        np.testing.assert_array_equal(getattr(back.image, name), getattr(frame.image, name))
    assert set(back.arrays) == set(frame_io.IMAGE_ARRAYS) | set(frame_io.LIGHT_FIELD_ARRAYS)
    np.testing.assert_array_equal(back.arrays["phasor"], frame.light_field.phasor)
    np.testing.assert_array_equal(back.raw.phase_images, frame.raw.phase_images)
    assert back.raw.meta == json_safe(frame.raw.meta)
    meta = _strict_json(out / frame_io.FRAME_JSON)
    assert meta == back.meta and meta["scene_name"] == "sat" and meta["ideal_sensor"] is False
    assert meta["arrays"] == frame_io.ARRAY_UNITS
    # a sensor frame's grey full scale is the ADC's, 2 ** (adc_bits - 1) DN
    assert back.grey_full_scale == meta["grey_preview_full_scale"] == 2.0 ** 11
    assert frame.grey_full_scale == back.grey_full_scale


def test_measured_frame_round_trips(tmp_path, sim_frame):
    scene, frame = sim_frame
    raw = frame.raw
    image, fs = frame_io.write_measured(tmp_path / "m", raw, scene.camera, {"rig": {"a": 1.0}})
    back = frame_io.read_frame(tmp_path / "m")
    assert back.kind == "measured" and back.grey_full_scale == fs == 2.0 ** 11
    for name in ("range_m", "depth_z_m", "amplitude", "valid"):
        np.testing.assert_array_equal(getattr(back.image, name), getattr(image, name))
        np.testing.assert_array_equal(getattr(back.image, name), getattr(frame.image, name))
    assert set(back.arrays) == set(frame_io.IMAGE_ARRAYS)
    assert frame_io.intrinsics_from_meta(back.meta, raw.shape) == scene.camera.intrinsics
    assert back.meta["kind"] == "measured" and back.meta["rig"] == {"a": 1.0}
    np.testing.assert_array_equal(back.raw.intensity, raw.intensity)
    assert _strict_json(tmp_path / "m" / frame_io.FRAME_JSON) == back.meta
    # a folder holding only raw.npz is a measured frame too (intrinsics: the preset's)
    (tmp_path / "r").mkdir()
    frame_io.write_raw(tmp_path / "r" / frame_io.RAW_NPZ, raw)
    only_raw = frame_io.read_frame(tmp_path / "r")
    assert only_raw.kind == "measured" and only_raw.grey_full_scale == 2.0 ** 11


def test_grey_full_scale_rule():
    amp = np.linspace(0.0, 1.0, 1001).reshape(7, 143)
    valid = np.ones(amp.shape, dtype=bool)
    assert frame_io.grey_full_scale(amp, valid, 12) == 2048.0
    assert frame_io.grey_full_scale(amp, valid, None) == pytest.approx(0.995)
    assert frame_io.grey_full_scale(amp, ~valid, None) == 0.0
    grey, fs = frame_io.grey_preview_8bit(amp, ~valid)
    assert fs == 0.0 and not grey.any()


def test_ideal_frame_uses_the_percentile(tmp_path):
    scene = small_example("satellite_ground_test", width=16)
    frame = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=1), ideal=True))
    im = frame.image
    expected = float(np.percentile(im.amplitude[im.valid], 99.5))
    assert frame.grey_full_scale == pytest.approx(expected)
    back = frame_io.read_frame(save_frame(tmp_path, frame))
    assert back.raw is None and back.grey_full_scale == pytest.approx(expected)
    png = np.array(Image.open(tmp_path / frame_io.GREY_PNG))
    np.testing.assert_array_equal(png, back.grey_8bit())


def test_range_and_depth_convert_with_one_pair(sim_frame):
    scene, frame = sim_frame
    c = z_over_range(scene.camera.intrinsics)
    im = frame.image
    np.testing.assert_array_equal(im.depth_z_m, range_to_depth_z(im.range_m, c))
    np.testing.assert_allclose(depth_z_to_range(im.depth_z_m, c), im.range_m, rtol=1e-15)
    assert np.all((c > 0) & (c <= 1))
    # the renderer's ground truth uses the same conversion
    lf = frame.light_field
    np.testing.assert_allclose(lf.truth_depth_z_m, range_to_depth_z(lf.truth_range_m, c),
                               rtol=1e-12)


def test_json_safe_makes_strict_json():
    value = {1: (np.float32(1.5), np.int64(3), np.bool_(True), float("nan")),
             "a": np.array([math.inf, -math.inf]), "n": None, "s": "x"}
    out = json_safe(value)
    assert out == {"1": [1.5, 3, True, "nan"], "a": ["inf", "-inf"], "n": None, "s": "x"}
    json.dumps(out, allow_nan=False)
    assert json_safe([float("nan"), 2.0], non_finite=None) == [None, 2.0]


def test_reconstruction_of_the_written_raw_frame_is_the_stored_one(tmp_path, sim_frame):
    scene, frame = sim_frame
    frame_io.write_raw(tmp_path / "raw.npz", frame.raw)
    raw = frame_io.read_raw(tmp_path / "raw.npz")
    img = reconstruct_raw(raw, z_over_range(scene.camera.intrinsics))
    np.testing.assert_array_equal(img.range_m, frame.image.range_m)


def test_a_measured_frames_illumination_temperature_is_stored_and_read_back(tmp_path, sim_frame):
    import dataclasses

    scene, frame = sim_frame
    warm = dataclasses.replace(frame.raw, illumination_temperature_c=36.75)
    frame_io.write_measured(tmp_path / "m", warm, scene.camera, {})
    back = frame_io.read_frame(tmp_path / "m")
    assert back.meta[frame_io.TEMPERATURE_KEY] == 36.75
    assert back.raw.illumination_temperature_c == 36.75
    frame_io.write_measured(tmp_path / "n", frame.raw, scene.camera, {})  # reports none
    none = frame_io.read_frame(tmp_path / "n")
    assert frame_io.TEMPERATURE_KEY not in none.meta
    assert none.raw.illumination_temperature_c is None


def test_an_incompressible_member_is_stored_and_every_member_reads_back_bit_exact(tmp_path):
    """write_npz deflates what shrinks and stores what would not (a render's noise)."""
    import zipfile

    rng = np.random.default_rng(3)
    arrays = {
        "noise": rng.normal(size=(171, 224)),               # every mantissa random
        "zeros": np.zeros((171, 224)),
        "ids": np.repeat(np.arange(171, dtype=np.int32), 224).reshape(171, 224),
        "nan_rows": np.where(np.arange(171)[:, None] < 80, np.nan, rng.normal(size=(171, 224))),
        "small": rng.normal(size=10),                       # below the sample: deflated
        "text": np.array(json.dumps({"a": 1})),
        "empty": np.zeros((0, 3)),
    }
    path = tmp_path / "a.npz"
    frame_io.write_npz(path, arrays)
    methods = {i.filename: i.compress_type for i in zipfile.ZipFile(path).infolist()}
    assert methods["noise.npy"] == zipfile.ZIP_STORED
    for name in ("zeros", "ids", "small", "text", "empty"):
        assert methods[f"{name}.npy"] == zipfile.ZIP_DEFLATED, name
    with np.load(path) as back:
        assert set(back.files) == set(arrays)
        for name, a in arrays.items():
            assert back[name].dtype == a.dtype and back[name].shape == a.shape, name
            assert back[name].tobytes() == a.tobytes(), name
