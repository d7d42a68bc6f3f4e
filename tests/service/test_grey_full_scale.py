"""A frame's grey image is the same wherever it is made: its grey.png, ``toftwin preview``, the
campaign report's panels and the comparison metrics (one grey full scale per frame)."""

import base64
import io

import numpy as np
import pytest
from PIL import Image

from service.export.panels import pose_panels
from service.export.report import inline_panels
from service.lab.comparison import compare
from service.store.frame_files import FrameStore, new_frame_id
from sim_core import frame_io
from sim_core.metrics import grey_8bit
from sim_core.pipeline import save_frame, simulate
from sim_core.preview import side_by_side
from sim_core.render import RenderSettings
from tests.sim_core.scenes import small_example


def _png(path):
    return np.array(Image.open(path))


def _data_uri(uri):
    return np.array(Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))))


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    root = tmp_path_factory.mktemp("frames")
    store = FrameStore(root)
    scene = small_example("satellite_ground_test", width=32)
    measured = simulate(scene, RenderSettings(integrator="direct", spp=2, seed=1))
    simulated = simulate(scene, RenderSettings(integrator="direct", spp=2, seed=2))
    mid, m_image, m_fs = store.save_measured(measured.raw, scene.camera, {"rig": {}})
    out = save_frame(root.parent / "sim-out", simulated)
    sid = new_frame_id()
    store.save_files(sid, {p.name: p.read_bytes() for p in out.iterdir()})
    return store, mid, sid, m_image, m_fs, simulated


def test_every_grey_image_of_a_frame_is_its_grey_png(stored):
    store, mid, sid, m_image, m_fs, simulated = stored
    m_png = _png(store.path(mid) / frame_io.GREY_PNG)
    s_png = _png(store.path(sid) / frame_io.GREY_PNG)
    mf, sf = frame_io.read_frame(store.path(mid)), frame_io.read_frame(store.path(sid))
    assert mf.grey_full_scale == m_fs and sf.grey_full_scale == simulated.grey_full_scale
    np.testing.assert_array_equal(mf.grey_8bit(), m_png)
    np.testing.assert_array_equal(sf.grey_8bit(), s_png)
    np.testing.assert_array_equal(mf.arrays["grey_8bit"], m_png)
    # the comparison metrics (as the service's pose loop calls them)
    report = compare(m_image, simulated.image, None, (m_fs, simulated.grey_full_scale))
    assert report.grey_full_scale_measured == mf.grey_full_scale
    assert report.grey_full_scale_simulated == sf.grey_full_scale
    np.testing.assert_array_equal(grey_8bit(m_image.amplitude, report.grey_full_scale_measured),
                                  m_png)
    np.testing.assert_array_equal(
        grey_8bit(simulated.image.amplitude, report.grey_full_scale_simulated), s_png)
    # the campaign report's panels
    panels = {p["name"]: p for p in inline_panels(pose_panels(store, mid, sid))}
    np.testing.assert_array_equal(_data_uri(panels["grey-measured"]["src"])[..., 0], m_png)
    np.testing.assert_array_equal(_data_uri(panels["grey-simulated"]["src"])[..., 0], s_png)
    # toftwin preview (grey on the left, magnified by 1)
    left = np.array(side_by_side(mf, scale=1))[:, : m_png.shape[1], 0]
    np.testing.assert_array_equal(left, m_png)
