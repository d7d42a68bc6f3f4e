"""The USB wire format byte for byte (docs/devices.md, "Camera (USB)"), its checks and errors."""

from __future__ import annotations

import dataclasses
import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.camera.wire import (
    HEADER_SIZE,
    USE_CASES,
    CorruptFrameError,
    DeviceStatus,
    FrameError,
    TruncatedFrameError,
    decode_frame,
    decode_status,
    encode_frame,
    encode_raw_frame,
    encode_status,
    get_use_case,
    quantize_frame,
    raw_to_wire_values,
    wire_to_raw_frame,
)
from drivers.errors import DeviceInputError, ProtocolError
from sim_core.raw import RawFrame
from tests.drivers.helpers import MODE5, MODE9, H, W

pytestmark = pytest.mark.timeout(30)


def _images(uc, seed=0):
    rng = np.random.default_rng(seed)
    grey = rng.integers(0, 4096, (H, W), dtype=np.uint16)
    phases = rng.integers(0, 4096, (uc.n_frequencies, 4, H, W), dtype=np.uint16)
    return grey, phases


def _frame(uc=MODE5, seq=7, stamp=1_700_000_000_123_456, seed=0):
    grey, phases = _images(uc, seed)
    return encode_frame(grey, phases, use_case=uc, sequence=seq, timestamp_us=stamp)


def _rehash(data: bytes | bytearray) -> bytes:
    """Recompute both CRCs after editing a frame, so a deeper check is reached."""
    buf = bytearray(data)
    payload = bytes(buf[HEADER_SIZE:])
    buf[44:48] = struct.pack("<I", zlib.crc32(payload))
    buf[60:64] = struct.pack("<I", zlib.crc32(bytes(buf[:60])))
    return bytes(buf)


def _edit(data: bytes, offset: int, value: bytes) -> bytes:
    buf = bytearray(data)
    buf[offset : offset + len(value)] = value
    return _rehash(buf)


# -- layout ------------------------------------------------------------------------------
def test_header_layout_matches_the_documented_table():
    data = _frame(MODE5, seq=0x01020304, stamp=0x1122334455667788)
    payload = data[HEADER_SIZE:]
    expected = (
        b"TOFW"  # magic
        + bytes([2, 64])  # version, header size
        + b"\x01\x00"  # flags: grey image present
        + b"\x04\x03\x02\x01"  # sequence, little-endian
        + bytes([1, 1, 4, 12])  # use case code, n frequencies, n phases, bits per value
        + (224).to_bytes(2, "little")
        + (171).to_bytes(2, "little")
        + (500).to_bytes(4, "little")  # exposure in microseconds
        + bytes.fromhex("8877665544332211")  # timestamp in microseconds, little-endian
        + (60_240_000).to_bytes(4, "little")
        + (0).to_bytes(4, "little")  # no second frequency
        + (5 * 171 * 224 * 2).to_bytes(4, "little")  # payload length
        + zlib.crc32(payload).to_bytes(4, "little")
        + struct.pack("<f", float("nan"))  # illumination temperature: not reported
        + bytes(8)  # reserved
    )
    assert data[:60] == expected
    assert data[60:64] == zlib.crc32(expected).to_bytes(4, "little")
    assert len(data) == MODE5.frame_bytes == 64 + 383_040


def test_two_frequency_header_carries_both_frequencies_in_raw_frame_order():
    data = _frame(MODE9)
    assert data[12:14] == bytes([2, 2])
    assert data[20:24] == (2000).to_bytes(4, "little")
    assert data[32:40] == (80_320_000).to_bytes(4, "little") + (60_240_000).to_bytes(4, "little")
    assert len(data) == MODE9.frame_bytes == 64 + 9 * 171 * 224 * 2


def test_payload_is_grey_then_phases_frequency_major_little_endian_rows():
    grey = np.zeros((H, W), np.uint16)
    grey[0, 1] = 0x0ABC
    phases = np.zeros((2, 4, H, W), np.uint16)
    phases[1, 2, 3, 4] = 0x0123  # frequency 1, phase step 2, row 3, column 4
    data = encode_frame(grey, phases, use_case=MODE9, sequence=0, timestamp_us=0)
    image = H * W * 2
    assert data[64 + 2 : 64 + 4] == b"\xbc\x0a"  # grey pixel (row 0, column 1)
    offset = 64 + (1 + 1 * 4 + 2) * image + (3 * W + 4) * 2
    assert data[offset : offset + 2] == b"\x23\x01"
    assert sum(data[64:]) == 0xBC + 0x0A + 0x23 + 0x01


@pytest.mark.parametrize("uc", [MODE5, MODE9], ids=lambda u: u.name)
def test_decode_returns_what_was_encoded(uc):
    grey, phases = _images(uc, seed=3)
    data = encode_frame(grey, phases, use_case=uc, sequence=41, timestamp_us=123)
    frame = decode_frame(data)
    assert frame.header.sequence == 41
    assert frame.header.timestamp_us == 123
    assert frame.header.use_case == uc
    assert np.array_equal(frame.grey, grey)
    assert np.array_equal(frame.phases, phases)


# -- conventions -------------------------------------------------------------------------
def test_raw_values_map_to_signed_correlation_c_equals_raw_minus_2048():
    grey = np.full((H, W), 1000, np.uint16)
    grey[5, 5] = 4095
    phases = np.full((1, 4, H, W), 2048, np.uint16)
    phases[0, 0, 0, 0] = 0
    phases[0, 3, 0, 1] = 4095
    phases[0, 1, 0, 2] = 2049
    raw = wire_to_raw_frame(
        decode_frame(encode_frame(grey, phases, use_case=MODE5, sequence=3, timestamp_us=2_500_000))
    )
    assert raw.phase_images.dtype == np.float32 and raw.intensity.dtype == np.float32
    assert raw.phase_images[0, 0, 0, 0] == -2048.0
    assert raw.phase_images[0, 3, 0, 1] == 2047.0
    assert raw.phase_images[0, 1, 0, 2] == 1.0
    assert raw.phase_images[0, 2, 10, 10] == 0.0
    assert raw.intensity[0, 0] == 1000.0
    # the ends of the ADC range mark saturation; SBI is not on the wire
    assert raw.saturated[0, 0] and raw.saturated[0, 1] and raw.saturated[5, 5]
    assert raw.saturated.sum() == 3 and not raw.sbi_limit.any()
    assert raw.frequencies_hz.tolist() == [60.24e6]
    assert raw.exposure_s == pytest.approx(500e-6)
    assert raw.timestamp_s == pytest.approx(2.5)
    assert raw.meta == {"use_case": "MODE_5_45FPS_500", "sequence": 3, "wire_version": 2}
    assert raw.illumination_temperature_c is None


def _raw(uc, phase_value, intensity_value):
    return RawFrame(
        phase_images=np.full((uc.n_frequencies, 4, H, W), phase_value, np.float32),
        intensity=np.full((H, W), intensity_value, np.float32),
        frequencies_hz=np.array(uc.frequencies_hz),
        saturated=np.zeros((H, W), bool),
        sbi_limit=np.zeros((H, W), bool),
        exposure_s=uc.exposure_s,
    )


@pytest.mark.parametrize(
    ("c", "raw"), [(0.5, 2048), (1.5, 2050), (-0.5, 2048), (3000.0, 4095), (-5000.0, 0)]
)
def test_quantisation_rounds_half_to_even_and_clips_to_12_bits(c, raw):
    grey, phases = raw_to_wire_values(_raw(MODE5, c, 5000.0))
    assert int(phases[0, 0, 0, 0]) == raw
    assert int(grey[0, 0]) == 4095


def test_quantize_frame_equals_the_decoded_wire_frame():
    rng = np.random.default_rng(5)
    base = _raw(MODE9, 0.0, 0.0)
    source = RawFrame(
        phase_images=(rng.normal(0, 900, base.phase_images.shape)).astype(np.float32),
        intensity=rng.uniform(-10, 4200, (H, W)).astype(np.float32),
        frequencies_hz=base.frequencies_hz,
        saturated=base.saturated,
        sbi_limit=base.sbi_limit,
        exposure_s=MODE9.exposure_s,
        timestamp_s=9.0,
        meta={"k": 1},
    )
    decoded = wire_to_raw_frame(
        decode_frame(encode_raw_frame(source, use_case=MODE9, sequence=1, timestamp_us=0))
    )
    expected = quantize_frame(source, MODE9)
    for name in ("phase_images", "intensity", "saturated", "sbi_limit", "frequencies_hz"):
        assert np.array_equal(getattr(decoded, name), getattr(expected, name)), name
    assert decoded.exposure_s == expected.exposure_s
    assert expected.timestamp_s == 9.0 and expected.meta == {"k": 1}


# -- encoder input errors ------------------------------------------------------------------
def test_encode_refuses_non_finite_values_naming_the_field():
    frame = _raw(MODE5, 0.0, 10.0)
    frame.phase_images[0, 1, 2, 3] = np.nan
    with pytest.raises(DeviceInputError, match=r"^frame\.phase_images: 1 non-finite values"):
        encode_raw_frame(frame, use_case=MODE5, sequence=0, timestamp_us=0)


def test_encode_refuses_a_frame_of_another_use_case():
    with pytest.raises(DeviceInputError, match=r"frequencies_hz: \[60240000\.0\] Hz do not match"):
        encode_raw_frame(_raw(MODE5, 0, 0), use_case=MODE9, sequence=0, timestamp_us=0)


@pytest.mark.parametrize(
    ("grey", "phases", "match"),
    [
        (np.zeros((H, W), np.uint16), np.zeros((2, 4, H, W), np.uint16), "do not match use case"),
        (np.zeros((H, W), np.int32), np.zeros((1, 4, H, W), np.uint16), r"grey: dtype int32"),
        (np.zeros((H, W), np.uint16), np.full((1, 4, H, W), 4096, np.uint16), "exceeds the 12-bit"),
    ],
)
def test_encode_frame_checks_shape_dtype_and_range(grey, phases, match):
    with pytest.raises(DeviceInputError, match=match):
        encode_frame(grey, phases, use_case=MODE5, sequence=0, timestamp_us=0)


def test_encode_frame_checks_sequence_range():
    grey, phases = _images(MODE5)
    with pytest.raises(DeviceInputError, match=r"^sequence: got 4294967296"):
        encode_frame(grey, phases, use_case=MODE5, sequence=2**32, timestamp_us=0)


def test_unknown_use_case_lists_the_known_ones():
    with pytest.raises(DeviceInputError, match=r"^use_case: got 'MODE_X'; one of MODE_5_45FPS_500"):
        get_use_case("MODE_X")
    assert get_use_case(2) is MODE9


# -- decoder error forms ---------------------------------------------------------------------
def test_short_data_is_a_truncated_header():
    with pytest.raises(TruncatedFrameError, match="shorter than the 64-byte header") as info:
        decode_frame(_frame()[:63])
    assert info.value.reason == "short-header"


def test_wrong_magic():
    with pytest.raises(FrameError, match=r"starts with b'XOFW', expected b'TOFW'") as info:
        decode_frame(b"X" + _frame()[1:])
    assert info.value.reason == "magic"


def test_newer_version_is_named():
    with pytest.raises(FrameError, match=r"wire version 3; this decoder reads \[1, 2\]") as info:
        decode_frame(_edit(_frame(), 4, b"\x03"))
    assert info.value.reason == "version"


def test_header_crc_mismatch_is_corruption():
    data = bytearray(_frame(seq=9))
    data[20] ^= 0x01  # exposure field, CRC not updated
    with pytest.raises(CorruptFrameError, match="header CRC32") as info:
        decode_frame(bytes(data))
    assert info.value.reason == "header-crc"
    assert isinstance(info.value, ProtocolError)


@pytest.mark.parametrize(
    ("offset", "value", "match"),
    [
        (14, b"\x03", r"n_phases 3 \(expected 4\)"),
        (15, b"\x0a", r"bits_per_value 10"),
        (12, b"\x09", r"use case code 9"),
        (13, b"\x02", r"use case MODE_5_45FPS_500 with 2 frequencies"),
        (6, b"\x00\x00", r"flags 0x0000"),
    ],
)
def test_invalid_header_fields_are_named(offset, value, match):
    with pytest.raises(FrameError, match=match) as info:
        decode_frame(_edit(_frame(), offset, value))
    assert info.value.reason == "header"


def test_payload_length_field_must_match_the_image_size():
    with pytest.raises(FrameError, match="payload length field 100 bytes") as info:
        decode_frame(_edit(_frame(), 40, (100).to_bytes(4, "little")))
    assert info.value.reason == "length"


def test_truncated_payload_reports_what_arrived():
    data = _frame(seq=12)
    with pytest.raises(
        TruncatedFrameError, match=r"frame 12 truncated: 1000 of 383104 bytes"
    ) as info:
        decode_frame(data[:1000])
    assert (info.value.reason, info.value.sequence) == ("truncated", 12)


def test_trailing_bytes_are_refused():
    with pytest.raises(FrameError, match="2 bytes after the 383104-byte frame"):
        decode_frame(_frame() + b"\x00\x00")


def test_payload_crc_mismatch_is_corruption():
    data = bytearray(_frame(seq=4))
    data[HEADER_SIZE + 1000] ^= 0x10
    with pytest.raises(CorruptFrameError, match=r"frame 4: payload CRC32") as info:
        decode_frame(bytes(data))
    assert info.value.reason == "payload-crc"


def test_words_above_12_bits_are_refused_even_with_valid_crcs():
    data = _edit(_frame(), HEADER_SIZE + 10, b"\xff\xff")
    with pytest.raises(FrameError, match=r"1 words exceed the 12-bit range 0\.\.4095") as info:
        decode_frame(data)
    assert info.value.reason == "values"


@settings(max_examples=40, deadline=None)
@given(position=st.integers(0, MODE5.frame_bytes - 1), flip=st.integers(1, 255))
def test_any_changed_byte_is_detected(position, flip):
    data = bytearray(_FRAME)
    data[position] ^= flip
    with pytest.raises(FrameError):
        decode_frame(bytes(data))


_FRAME = _frame()


@settings(max_examples=25, deadline=None)
@given(
    seq=st.integers(0, 2**32 - 1),
    stamp=st.integers(0, 2**64 - 1),
    name=st.sampled_from(sorted(USE_CASES)),
)
def test_header_fields_round_trip(seq, stamp, name):
    uc = USE_CASES[name]
    grey = np.zeros((H, W), np.uint16)
    phases = np.zeros((uc.n_frequencies, 4, H, W), np.uint16)
    header = decode_frame(
        encode_frame(grey, phases, use_case=uc, sequence=seq, timestamp_us=stamp)
    ).header
    assert (header.sequence, header.timestamp_us, header.use_case) == (seq, stamp, uc)


# -- GET_STATUS ----------------------------------------------------------------------------
def test_status_layout():
    status = DeviceStatus(1, 2, True, 3, 224, 171, 0x01020304, 0x0100)
    data = encode_status(status)
    assert data == bytes([1, 2, 1, 3, 224, 0, 171, 0, 4, 3, 2, 1, 0, 1, 0, 0])
    assert decode_status(data) == status
    assert status.firmware == "1.00"
    assert status.last_error_text == "busy: not allowed while streaming"


def test_status_of_wrong_length_or_form_is_a_protocol_error():
    with pytest.raises(ProtocolError, match="15 bytes, expected 16"):
        decode_status(bytes(15))
    with pytest.raises(ProtocolError, match="streaming byte is 2"):
        decode_status(bytes([1, 0, 2]) + bytes(13))


# -- the illumination temperature (wire version 2) ----------------------------------------
def test_a_frames_illumination_temperature_travels_in_the_header():
    grey, phases = _images(MODE5, seed=1)
    data = encode_frame(grey, phases, use_case=MODE5, sequence=2, timestamp_us=9,
                        illumination_temperature_c=37.25)
    assert data[48:52] == struct.pack("<f", 37.25)
    raw = wire_to_raw_frame(decode_frame(data))
    assert raw.illumination_temperature_c == 37.25
    assert raw.meta["wire_version"] == 2


def test_a_version_1_frame_still_decodes_without_a_temperature():
    """Frames recorded before version 2: version byte 1, reserved zeros where the
    temperature now is; they decode, and report no temperature (not 0 degC)."""
    data = _edit(_frame(MODE5), 4, bytes([1]))
    data = _edit(data, 48, bytes(4))
    raw = wire_to_raw_frame(decode_frame(data))
    assert raw.meta["wire_version"] == 1 and raw.illumination_temperature_c is None


@settings(max_examples=40, deadline=None)
@given(t=st.one_of(st.none(), st.floats(-40.0, 125.0)))
def test_quantize_frame_reports_the_temperature_the_wire_delivers(t):
    raw = dataclasses.replace(_raw(MODE5, 10.0, 500.0), illumination_temperature_c=t)
    data = encode_raw_frame(raw, use_case=MODE5, sequence=0, timestamp_us=0)
    wired = wire_to_raw_frame(decode_frame(data))
    assert quantize_frame(raw, MODE5).illumination_temperature_c == (
        wired.illumination_temperature_c)
    if t is not None:
        assert wired.illumination_temperature_c == pytest.approx(t, rel=1e-6, abs=1e-5)
