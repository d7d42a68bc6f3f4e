"""Grey as stored and grey as shown.

Stored (grey.png, frame.npz's grey_8bit, the comparison metrics' grey): the frame's fixed grey
full scale, the same wherever it is data. Shown to people (``toftwin preview``, the report's and
the operator page's panels): the amplitude stretched to the 1st-99th percentile of its valid
pixels, measured and simulated of one pose on one range, with a colour bar stating it in DN. On
the satellite ground test the stored grey is black to the eye; the shown grey spans black to
white, and showing it changes no stored byte.
"""

import base64
import hashlib
import io

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from service.cli import app as toftwin_app
from service.export.panels import pose_panels
from service.export.report import inline_panels
from service.lab.comparison import compare
from service.store.frame_files import FrameStore, new_frame_id
from sim_core import frame_io
from sim_core.metrics import grey_8bit
from sim_core.pipeline import save_frame, simulate
from sim_core.preview import (
    BAR_HEIGHT_PX,
    colour_bar_ticks,
    grey_colours,
    grey_scale,
    side_by_side,
)
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from tests.sim_core.scenes import example


def _png(path):
    return np.array(Image.open(path))


def _data_uri(uri):
    return np.array(Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))))


def _digests(store, *frame_ids) -> dict[str, str]:
    return {f"{fid}/{p.name}": hashlib.sha256(p.read_bytes()).hexdigest()
            for fid in frame_ids for p in sorted(store.path(fid).iterdir())}


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    """The satellite ground test at 1 sun as the camera sees it (224 x 171): a measured frame
    (its raw frame stored as a capture) and a simulated one (another seed), in a frame store."""
    root = tmp_path_factory.mktemp("frames")
    store = FrameStore(root)
    scene = example("satellite_ground_test")
    measured = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=2, seed=1)))
    simulated = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=2, seed=2)))
    mid, m_image, m_fs = store.save_measured(measured.raw, scene.camera, {"rig": {}})
    out = save_frame(root.parent / "sim-out", simulated)
    sid = new_frame_id()
    store.save_files(sid, {p.name: p.read_bytes() for p in out.iterdir()})
    return store, mid, sid, m_image, m_fs, simulated


def test_stored_grey_keeps_the_frames_full_scale_wherever_it_is_data(stored):
    store, mid, sid, m_image, m_fs, simulated = stored
    m_png = _png(store.path(mid) / frame_io.GREY_PNG)
    s_png = _png(store.path(sid) / frame_io.GREY_PNG)
    mf, sf = frame_io.read_frame(store.path(mid)), frame_io.read_frame(store.path(sid))
    assert mf.grey_full_scale == m_fs == 2048.0 and sf.grey_full_scale == 2048.0
    np.testing.assert_array_equal(mf.grey_8bit(), m_png)
    np.testing.assert_array_equal(sf.grey_8bit(), s_png)
    np.testing.assert_array_equal(mf.arrays["grey_8bit"], m_png)
    # the comparison metrics (as the service's pose loop calls them)
    report = compare(m_image, simulated.image, None, (m_fs, simulated.grey_full_scale))
    assert report.grey_full_scale_measured == mf.grey_full_scale
    np.testing.assert_array_equal(grey_8bit(m_image.amplitude, report.grey_full_scale_measured),
                                  m_png)
    np.testing.assert_array_equal(
        grey_8bit(simulated.image.amplitude, report.grey_full_scale_simulated), s_png)
    # ... on which the satellite is black to the eye: a few levels of 255
    assert m_png[mf.image.valid].max() <= 10


def test_shown_grey_spans_black_to_white_on_one_range_for_both_frames(stored):
    store, mid, sid, *_ = stored
    mf, sf = frame_io.read_frame(store.path(mid)), frame_io.read_frame(store.path(sid))
    panels = {p.name: p for p in pose_panels(store, mid, sid)}
    gm, gs = panels["grey-measured"], panels["grey-simulated"]
    assert gm.scale == gs.scale  # one range: the two compare by eye
    both = np.concatenate([mf.image.amplitude[mf.image.valid],
                           sf.image.amplitude[sf.image.valid]])
    lo, hi = np.percentile(both, [1, 99])
    assert (gm.scale.lo, gm.scale.hi) == (lo, hi) and gm.scale.unit == "DN"
    # the colour bar states that range in DN at its ends, and says how it was chosen
    ticks = colour_bar_ticks(gm.scale)
    assert (ticks[0][1], ticks[-1][1]) == (f"{lo:.4g}", f"{hi:.4g}")
    assert gm.label == "grey [DN], 1st-99th pct of valid pixels"
    # the satellite now spans the colour range
    shown = gm.rgb[..., 0][mf.image.valid]
    assert shown.min() == 0 and shown.max() == 255
    assert np.percentile(shown, 50) > 20
    # the report inlines the same pictures
    inline = {p["name"]: p for p in inline_panels(pose_panels(store, mid, sid))}
    np.testing.assert_array_equal(_data_uri(inline["grey-measured"]["src"]), gm.rgb)
    # the grey difference is signed, in DN, on a symmetric scale
    gd = panels["grey-difference"]
    assert gd.scale.unit == "DN" and gd.scale.lo == -gd.scale.hi


def test_toftwin_preview_stretches_grey_adds_colour_bars_and_changes_no_stored_byte(
    stored, tmp_path
):
    store, mid, sid, *_ = stored
    before = _digests(store, mid, sid)
    frame = frame_io.read_frame(store.path(mid))
    picture = np.asarray(side_by_side(frame, scale=1))
    h, w = frame.image.range_m.shape
    assert picture.shape[0] == h + BAR_HEIGHT_PX  # the colour bars underneath
    grey = grey_scale((frame.image.amplitude, frame.image.valid))
    np.testing.assert_array_equal(picture[:h, :w], grey_colours(frame.image.amplitude, grey))
    assert picture[h:, :w].min() < 50 and picture[h:, :w].max() == 255  # a bar is drawn
    res = CliRunner().invoke(toftwin_app, ["preview", str(store.path(sid)), "--out",
                                           str(tmp_path / "p.png")])
    assert res.exit_code == 0, res.output
    inline_panels(pose_panels(store, mid, sid))
    assert _digests(store, mid, sid) == before
