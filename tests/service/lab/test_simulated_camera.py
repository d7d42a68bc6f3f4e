"""The simulated rig's camera streams frames rendered for the rig's state."""

import numpy as np
import pytest

from drivers.rig import Rig, RigState
from service.lab.simulated_camera import RenderedFrameSource, TwinDifferences, perturb_scene
from sim_core.camera import pixel_centre_grid, pixel_to_camera_direction
from sim_core.raw import reconstruct_raw
from sim_core.render import RenderSettings
from sim_core.scene_spec import load_scene_spec
from tests.sim_core.scenes import EXAMPLES, example

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def rig():
    path = EXAMPLES / "satellite_ground_test.yaml"
    source = RenderedFrameSource(load_scene_spec(path), path.parent,
                                 RenderSettings(integrator="direct", spp=2))
    r = Rig.simulated(frame_source=source, seed=3)
    yield r
    r.close()


def z_over_range(frame):
    from sim_core.camera import Intrinsics

    h, w = frame.intensity.shape
    intr = Intrinsics(w, h, 208.33, 208.33, (w - 1) / 2, (h - 1) / 2)
    u, v = pixel_centre_grid(intr)
    return pixel_to_camera_direction(intr, u, v)[:, 2].reshape(h, w)


def test_captured_frames_are_renders_of_the_satellite_at_about_one_metre(rig):
    rig.apply(RigState(turntable_angle_deg=30.0, solar_suns=1.0, shutter_open=True))
    frames = rig.capture(2)
    assert len(frames) == 2
    for f in frames:
        assert f.phase_images.shape == (1, 4, 171, 224) and f.phase_images.dtype == np.float32
        assert f.meta["rig"]["turntable_angle_deg"] == pytest.approx(30.0, abs=0.01)
    img = reconstruct_raw(frames[0], z_over_range(frames[0]))
    centre = img.range_m[75:95, 100:124]
    assert np.nanmedian(centre) == pytest.approx(0.95, abs=0.1)
    # Different frames carry different noise.
    assert not np.array_equal(frames[0].phase_images, frames[1].phase_images)


def test_turning_the_table_changes_the_image(rig):
    rig.apply(RigState(turntable_angle_deg=0.0, solar_suns=1.0, shutter_open=True))
    a = rig.capture(1)[0]
    rig.apply(RigState(turntable_angle_deg=60.0, solar_suns=1.0, shutter_open=True))
    b = rig.capture(1)[0]
    body = np.s_[60:110, 90:135]
    assert np.abs(a.intensity[body] - b.intensity[body]).mean() > 1.0


def test_perturbation_moves_objects_and_scales_reflectance():
    scene = example("satellite_ground_test")
    diff = TwinDifferences(pose_offset_m=(0.01, 0.0, 0.0), reflectance_scale=0.5)
    moved = perturb_scene(scene, diff)
    np.testing.assert_allclose(moved.triangles_m - scene.triangles_m, [[[0.01, 0.0, 0.0]] * 3]
                               * scene.n_triangles)
    assert moved.materials[0].kd == pytest.approx(0.5 * scene.materials[0].kd)
