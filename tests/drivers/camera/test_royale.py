"""royale backend: clean import without roypy, and the pure RawData -> RawFrame conversion.

roypy is not installed here, so the conversion is tested on synthetic raw data laid out as royale
documents it (``royale/RawData.hpp``, ``sample_raw_data.py``; see docs/devices.md). The last
tests drive :class:`RoyaleCamera` through a small stand-in for the documented roypy calls, to
execute its glue code; it says nothing about real royale behaviour.
"""

from __future__ import annotations

import threading
import types

import numpy as np
import pytest

from drivers.camera import USE_CASES, CameraNotFoundError, CameraProtocol
from drivers.camera import royale as royale_backend
from drivers.camera.royale import (
    RawDataCopy,
    RoyaleCamera,
    RoyaleDataError,
    RoyaleNotInstalledError,
    copy_roypy_raw_data,
    royale_to_raw_frame,
    split_raw_buffer,
)
from drivers.camera.wire import quantize_frame, raw_to_wire_values
from drivers.errors import DeviceInputError, DeviceTimeoutError
from drivers.sim.usb_camera import CameraRequest, plane_source
from tests.drivers.helpers import MODE5, MODE9, H, W
from toftwin_camera_bridge import RawDataLayoutError

pytestmark = pytest.mark.timeout(20)


def _source(uc, index=0):
    return plane_source(1.2, noise_dn=6.0)(CameraRequest(uc, index, seed=4))


def _royale_layout(uc, *, grey_last=False, per_group=True, order=(0, 1, 2, 3), index=0):
    """A source frame as royale would deliver it: 12-bit words, groups, angles, flags."""
    grey, phases = raw_to_wire_values(_source(uc, index))
    freqs = [round(f) for f in uc.frequencies_hz]
    mod_frames, mod_angles, mod_freqs = [], [], []
    for k, f in enumerate(freqs):
        for step in order:
            mod_frames.append(phases[k, step])
            mod_angles.append(90 * step)
            mod_freqs.append(f)
    frames = [grey, *mod_frames] if not grey_last else [*mod_frames, grey]
    angles = [0, *mod_angles] if not grey_last else [*mod_angles, 0]
    illum = [0] + [1] * len(mod_frames) if not grey_last else [1] * len(mod_frames) + [0]
    groups = [1] + [4] * len(freqs) if not grey_last else [4] * len(freqs) + [1]
    names = ["gray"] + [f"mod{f // 10000}" for f in freqs]
    if grey_last:
        names = names[1:] + names[:1]
    per_frame = [freqs[-1], *mod_freqs] if not grey_last else [*mod_freqs, freqs[-1]]
    if per_group:
        group_freqs = [freqs[-1], *freqs] if not grey_last else [*freqs, freqs[-1]]
        mod, exp = group_freqs, [uc.exposure_us] * len(groups)
    else:
        mod, exp = per_frame, [uc.exposure_us] * len(frames)
    return RawDataCopy(
        width=W,
        height=H,
        raw_frames=np.stack(frames),
        modulation_frequencies_hz=tuple(mod),
        exposure_times_us=tuple(exp),
        raw_frame_count=tuple(groups),
        exposure_group_names=tuple(names),
        phase_angles_deg=tuple(angles),
        illumination_enabled=tuple(illum),
        timestamp_us=1_700_000_000_000_000,
        illumination_temperature_c=31.5,
    )


def _assert_equals_source(frame, uc, index=0):
    expected = quantize_frame(_source(uc, index), uc)
    assert np.array_equal(frame.phase_images, expected.phase_images)
    assert np.array_equal(frame.intensity, expected.intensity)
    assert np.array_equal(frame.saturated, expected.saturated)
    assert frame.frequencies_hz.tolist() == list(uc.frequencies_hz)


# -- without roypy -------------------------------------------------------------------------
def test_module_imports_without_roypy_and_says_royale_is_not_installed(monkeypatch):
    monkeypatch.setattr(royale_backend, "roypy", None)
    assert not royale_backend.royale_available()
    with pytest.raises(
        RoyaleNotInstalledError, match=r"^royale not installed: cannot import roypy"
    ):
        RoyaleCamera().connect()
    with pytest.raises(RoyaleNotInstalledError, match=r"not on PyPI.*PYTHONPATH"):
        royale_backend.require_roypy()


# -- conversion ----------------------------------------------------------------------------
@pytest.mark.parametrize("uc", [MODE5, MODE9], ids=lambda u: u.name)
@pytest.mark.parametrize("grey_last", [False, True], ids=["grey-first", "grey-last"])
@pytest.mark.parametrize("per_group", [True, False], ids=["per-group", "per-frame"])
def test_royale_raw_data_converts_to_the_quantised_source_frame(uc, grey_last, per_group):
    data = _royale_layout(uc, grey_last=grey_last, per_group=per_group)
    frame = royale_to_raw_frame(data, use_case=uc)
    _assert_equals_source(frame, uc)
    assert frame.phase_images.dtype == np.float32 and frame.phase_images.shape == (
        uc.n_frequencies,
        4,
        H,
        W,
    )
    assert frame.exposure_s == pytest.approx(uc.exposure_s)
    assert frame.timestamp_s == pytest.approx(1.7e9)
    assert frame.meta["timestamp_source"] == "royale"
    assert frame.meta["grey_index"] == (4 * uc.n_frequencies if grey_last else 0)
    assert frame.meta["grey_index_source"] == "exposure group of one raw frame"
    assert frame.meta["illumination_temperature_c"] == 31.5


def test_phase_frames_are_ordered_by_phase_angle():
    data = _royale_layout(MODE9, order=(2, 0, 3, 1))
    _assert_equals_source(royale_to_raw_frame(data, use_case=MODE9), MODE9)


def test_convention_is_c_equals_raw_minus_2048():
    frames = np.full((5, H, W), 2048, np.uint16)
    frames[0] = 777  # grey
    frames[1, 0, 0] = 0
    frames[3, 0, 1] = 4095
    data = RawDataCopy(W, H, frames, (60_240_000,) * 5, (500,) * 5)
    frame = royale_to_raw_frame(data)
    assert frame.phase_images[0, 0, 0, 0] == -2048 and frame.phase_images[0, 2, 0, 1] == 2047
    assert frame.phase_images[0, 1, 5, 5] == 0 and frame.intensity[9, 9] == 777
    assert frame.saturated[0, 0] and frame.saturated[0, 1] and frame.saturated.sum() == 2
    assert frame.meta["grey_index_source"].startswith("assumed first")


def test_grey_frame_found_from_the_illumination_flag_without_groups():
    data = _royale_layout(MODE5, grey_last=True)
    data = RawDataCopy(
        W,
        H,
        data.raw_frames,
        (60_240_000,) * 5,
        (500,) * 5,
        illumination_enabled=data.illumination_enabled,
        timestamp_us=None,
    )
    frame = royale_to_raw_frame(data, use_case=MODE5, timestamp_s=12.5)
    _assert_equals_source(frame, MODE5)
    assert (
        frame.meta["grey_index"] == 4 and frame.meta["grey_index_source"] == "illumination disabled"
    )
    assert (frame.timestamp_s, frame.meta["timestamp_source"]) == (12.5, "host")


def test_left_aligned_12_bit_words_need_value_shift():
    data = _royale_layout(MODE5)
    shifted = RawDataCopy(
        W,
        H,
        data.raw_frames << 4,
        data.modulation_frequencies_hz,
        data.exposure_times_us,
        data.raw_frame_count,
    )
    with pytest.raises(RoyaleDataError, match=r"exceed 12 bits .* pass value_shift=4"):
        royale_to_raw_frame(shifted)
    _assert_equals_source(royale_to_raw_frame(shifted, value_shift=4), MODE5)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"raw_frames": np.zeros((6, H, W), np.uint16)}, "6 raw frames; a use case gives 1 grey"),
        ({"raw_frames": np.zeros((5, H, W + 1), np.uint16)}, r"expected \(n, 171, 224\)"),
        ({"modulation_frequencies_hz": (1, 2, 3)}, "3 modulation frequencies for 5 raw frames"),
        ({"phase_angles_deg": (0, 0, 90, 90, 270)}, r"phase angles \[0, 90, 90, 270\]"),
    ],
)
def test_raw_data_that_no_use_case_gives_is_refused(change, match):
    data = _royale_layout(MODE5)
    fields = {**data.__dict__, **change}
    if "raw_frames" in change and change["raw_frames"].shape[0] != 5:
        fields["raw_frame_count"] = ()
        fields["modulation_frequencies_hz"] = (60_240_000,) * change["raw_frames"].shape[0]
    with pytest.raises(RoyaleDataError, match=match):
        royale_to_raw_frame(RawDataCopy(**fields))


def test_mixed_frequencies_inside_a_phase_set_are_refused():
    data = _royale_layout(MODE9, per_group=False)
    freqs = list(data.modulation_frequencies_hz)
    freqs[2] = 60_240_000  # second phase frame of the 80.32 MHz set
    bad = RawDataCopy(**{**data.__dict__, "modulation_frequencies_hz": tuple(freqs)})
    with pytest.raises(
        RoyaleDataError, match=r"raw frame 2 at 60240000 Hz inside a four-phase set"
    ):
        royale_to_raw_frame(bad)


def test_frequencies_must_match_the_use_case():
    with pytest.raises(RoyaleDataError, match=r"do not match use case MODE_9_5FPS_2000"):
        royale_to_raw_frame(_royale_layout(MODE5), use_case=MODE9)


def test_value_shift_is_checked():
    with pytest.raises(DeviceInputError, match=r"^value_shift: got 5"):
        royale_to_raw_frame(_royale_layout(MODE5), value_shift=5)


# -- copying out of roypy objects ----------------------------------------------------------
def test_flat_buffer_skips_one_pseudo_data_row_per_frame():
    frames = np.arange(2 * 4 * 3, dtype=np.uint16).reshape(2, 4, 3)  # 2 frames, pseudo + 3 rows
    out = split_raw_buffer(frames.ravel(), 2, 3, 3)
    assert np.array_equal(out, frames[:, 1:, :])
    with pytest.raises(RawDataLayoutError, match="has 23 words; 2 raw frames of 3 x 3"):
        split_raw_buffer(frames.ravel()[:-1], 2, 3, 3)


def _roypy_like(data: RawDataCopy, *, with_get_raw_phase=True):
    """A record with royale's RawData attribute names (as the roypy sample reads them)."""
    n = data.raw_frames.shape[0]
    flat = np.concatenate(
        [np.concatenate([np.full((1, W), 999, np.uint16), f]) for f in data.raw_frames]
    ).ravel()
    record = types.SimpleNamespace(
        width=W,
        height=H,
        rawData=list(flat),
        rawFrameCount=list(data.raw_frame_count),
        modulationFrequencies=list(data.modulation_frequencies_hz),
        exposureTimes=list(data.exposure_times_us),
        exposureGroupNames=list(data.exposure_group_names),
        phaseAngles=list(data.phase_angles_deg),
        illuminationEnabled=list(data.illumination_enabled),
        illuminationTemperature=31.5,
        streamId=0,
        timeStamp=types.SimpleNamespace(count=lambda: 1_700_000_000_000_000),
    )
    if with_get_raw_phase:
        record.getRawPhase = lambda i: list(data.raw_frames[i].ravel()) if i < n else []
    return record


@pytest.mark.parametrize("with_get_raw_phase", [True, False], ids=["getRawPhase", "rawData"])
def test_copy_of_a_roypy_raw_data_converts_like_the_original(with_get_raw_phase):
    data = _royale_layout(MODE9)
    copy = copy_roypy_raw_data(_roypy_like(data, with_get_raw_phase=with_get_raw_phase))
    assert np.array_equal(copy.raw_frames, data.raw_frames)
    assert copy.timestamp_us == data.timestamp_us
    assert copy.raw_frame_count == (1, 4, 4) and copy.exposure_group_names[0] == "gray"
    _assert_equals_source(royale_to_raw_frame(copy, use_case=MODE9), MODE9)


# -- RoyaleCamera glue, through a stand-in for the documented roypy calls ---------------------
class _StandInCamera:
    def __init__(self, layout):
        self.layout = layout
        self.listener = None
        self.use_case = None
        self._stop = threading.Event()
        self._thread = None

    def initialize(self):
        return 0

    def registerRawDataListener(self, listener):
        self.listener = listener
        return 0

    def getUseCases(self):
        return ["MODE_9_5FPS_2000", "MODE_5_45FPS_500"]

    def setUseCase(self, name):
        self.use_case = name
        return 0

    def startCapture(self):
        self._stop.clear()
        uc = USE_CASES[self.use_case]

        def run():
            index = 0
            while not self._stop.wait(0.005):
                if self.layout:
                    self.listener.onNewData(_roypy_like(_royale_layout(uc, index=index)))
                    index += 1

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()
        return 0

    def stopCapture(self):
        self._stop.set()
        self._thread.join(1.0)
        return 0

    def getId(self):
        return "0005-1111-2222-3333"

    def getCameraName(self):
        return "PICOFLEXX"

    def getCameraInfo(self):
        return [("BRIDGE_TYPE", "Enclustra")]


def _stand_in_roypy(camera, ids=("0005-1111-2222-3333",)):
    class IRawDataListener:
        def __init__(self):
            pass

    class CameraManager:
        def __init__(self, code=None):
            self.code = code

        def getConnectedCameraList(self):
            return list(ids)

        def createCamera(self, camera_id):
            return camera

    return types.SimpleNamespace(IRawDataListener=IRawDataListener, CameraManager=CameraManager)


def test_royale_camera_glue_captures_converted_frames(monkeypatch):
    cam = _StandInCamera(layout=True)
    monkeypatch.setattr(royale_backend, "roypy", _stand_in_roypy(cam))
    with RoyaleCamera(use_case="MODE_9_5FPS_2000", frame_timeout_s=1.0) as royale:
        assert isinstance(royale, CameraProtocol) and cam.use_case == "MODE_9_5FPS_2000"
        frames = royale.capture(2)
        ident = royale.identity()
    assert all(f.phase_images.shape == (2, 4, H, W) for f in frames)
    _assert_equals_source(frames[0], MODE9, index=0)
    assert (ident.serial, ident.model, ident.backend) == (
        "0005-1111-2222-3333",
        "PICOFLEXX",
        "royale",
    )
    assert ident.extra == {"BRIDGE_TYPE": "Enclustra"}


def test_royale_camera_glue_errors(monkeypatch):
    cam = _StandInCamera(layout=False)  # streams nothing
    monkeypatch.setattr(royale_backend, "roypy", _stand_in_roypy(cam))
    with (
        RoyaleCamera(frame_timeout_s=0.1) as royale,
        pytest.raises(DeviceTimeoutError, match=r"no raw frame within 0\.1 s"),
    ):
        royale.capture(1)
    monkeypatch.setattr(royale_backend, "roypy", _stand_in_roypy(cam, ids=()))
    with pytest.raises(CameraNotFoundError, match="royale sees no camera"):
        RoyaleCamera().connect()


def test_the_illumination_temperature_is_copied_from_raw_data_when_present():
    data = _royale_layout(MODE5)
    warm = RawDataCopy(**{**data.__dict__, "illumination_temperature_c": 38.5})
    assert royale_to_raw_frame(warm, use_case=MODE5).illumination_temperature_c == 38.5
    cold = RawDataCopy(**{**data.__dict__, "illumination_temperature_c": None})
    assert royale_to_raw_frame(cold, use_case=MODE5).illumination_temperature_c is None


def test_a_frame_of_the_previous_use_case_after_a_switch_is_dropped_and_counted(monkeypatch):
    """A source's capture thread may hand over a frame it took before a use-case switch after
    the switch was acknowledged: such a frame is stale, not an error; a copy that is no raw
    frame still is."""
    cam = _StandInCamera(layout=False)  # streams nothing: the test hands over every frame
    monkeypatch.setattr(royale_backend, "roypy", _stand_in_roypy(cam))
    with RoyaleCamera(use_case="MODE_5_45FPS_500", frame_timeout_s=0.3) as royale:
        royale.start()
        royale.configure("MODE_9_5FPS_2000")
        royale._on_frame(_royale_layout(MODE5))  # late, from before the switch
        royale._on_frame(_royale_layout(MODE9))
        frames = royale.capture(1)
        assert frames[0].phase_images.shape[0] == 2 and royale.stale == 1
        bad = _royale_layout(MODE5)
        royale._on_frame(RawDataCopy(**{**bad.__dict__, "raw_frames": bad.raw_frames[:4]}))
        with pytest.raises(RoyaleDataError, match="4 raw frames"):
            royale.capture(1)
        royale._on_frame(_royale_layout(MODE5))  # only stale frames: a timeout naming them
        with pytest.raises(DeviceTimeoutError, match=r"0 of 1 frames; 2 of another use case "
                           r"dropped \(the last: frequencies \[60240000\.0\] Hz do not match "
                           r"use case MODE_9_5FPS_2000"):
            royale.capture(1)
        royale.stop()
