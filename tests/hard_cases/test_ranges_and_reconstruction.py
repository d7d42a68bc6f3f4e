"""Ranges at the edges of the unambiguous interval, zero signal, and reconstruction of any
finite raw frame.

The single-frequency cases (1 mm, the ambiguity range of 60.24 MHz, 10 km, the empty scene)
are in test_sensor_extremes.py; here: the two-frequency mode at its extended ambiguity range
c / (2 * 20.08 MHz) = 7.46 m, zero signal through the whole chain, and property tests of the
reconstruction.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from sim_core.camera import F_60_24_MHZ, F_80_32_MHZ
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.pipeline import simulate
from sim_core.raw import RawFrame, ValidityThresholds, reconstruct_raw
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.tof import (
    ambiguity_range_m,
    common_frequency_hz,
    phase_from_phasor,
    reconstruct,
    unwrap_two_frequencies,
)
from tests.hard_cases.helpers import assert_frame_bounded, assert_stable, build, camera, lambert

F1, F2 = F_80_32_MHZ, F_60_24_MHZ
U_EXT = ambiguity_range_m(common_frequency_hz(F1, F2))  # 7.4650 m
TWO_PI = 2.0 * math.pi
DIRECT = RenderSettings(integrator="direct", spp=2, seed=4)


def _circle_error(a, b, u):
    d = np.abs(np.asarray(a) - np.asarray(b))
    return np.minimum(d, u - d)


def dual_wall(distance_m: float, power_w: float = 200.0, **camera_extra):
    wall = {"name": "wall", "mesh": {"kind": "rectangle", "size_m": [400.0, 400.0]},
            "material": lambert(0.8),
            "pose": {"position_m": [0.0, distance_m, 0.0], "rotation_deg": [90.0, 0.0, 0.0]}}
    cam = camera((0, 0, 0), (0, 1, 0), f_px=300.0, mode="dual", **camera_extra)
    return build(cam, [wall], power_w=power_w)


# -------------------------------------------------------------------------------------------
# Two frequencies at the extended ambiguity range
# -------------------------------------------------------------------------------------------
def test_extended_ambiguity_range_of_the_dual_mode_is_7_46_m():
    assert math.isclose(U_EXT, SPEED_OF_LIGHT_M_S / (2.0 * 20.08e6), rel_tol=1e-12)
    assert math.isclose(U_EXT, 4.0 * ambiguity_range_m(F1), rel_tol=1e-12)
    assert math.isclose(U_EXT, 3.0 * ambiguity_range_m(F2), rel_tol=1e-12)


@pytest.mark.parametrize("fraction", [-1e-4, 0.0, 1e-4])
def test_ideal_dual_frequency_frame_at_the_extended_range_wraps_without_nan(fraction):
    frame = simulate(dual_wall(U_EXT * (1.0 + fraction)),
                     RenderRequest(dataclasses.replace(DIRECT, jitter=False), ideal=True))
    assert_frame_bounded(frame)
    img, truth = frame.image, frame.light_field.truth_range_m
    assert img.valid.all()
    assert np.all((img.range_m >= 0.0) & (img.range_m < U_EXT))
    assert _circle_error(img.range_m, np.mod(truth, U_EXT), U_EXT).max() < 1e-5


# The pairs (n1, n2) of wrap counts must be compared on the circle of circumference U_EXT, not
# on a line: phases just below 2 pi at one frequency and just above 0 at the other (a target a
# hair's breadth from U_EXT, plus noise) once read 5.37 m or 2.09 m.


@pytest.mark.parametrize(
    ("phase1", "phase2"),
    [(TWO_PI - 1e-6, 1e-6), (1e-6, TWO_PI - 1e-6), (TWO_PI - 1e-3, 1e-3), (1e-3, TWO_PI - 1e-3)],
)
def test_phases_straddling_the_wrap_unwrap_next_to_zero(phase1, phase2):
    got = unwrap_two_frequencies(np.array([phase1]), F1, np.array([phase2]), F2)
    assert _circle_error(got, 0.0, U_EXT)[0] < 1e-3
    assert 0.0 <= got[0] < U_EXT


def test_noisy_dual_frequency_frame_at_the_extended_range_has_no_gross_errors():
    frame = simulate(dual_wall(U_EXT), RenderRequest(DIRECT))
    img, truth = frame.image, frame.light_field.truth_range_m
    assert img.valid.mean() > 0.95
    # Shot noise alone: about 1 cm per pixel here (4 cm at most); a wrong wrap is >= 0.6 m.
    err = _circle_error(img.range_m[img.valid], np.mod(truth[img.valid], U_EXT), U_EXT)
    assert err.max() < 0.1


@pytest.mark.parametrize("distance_m", [3.0, 5.0, 7.0])
def test_noisy_dual_frequency_frame_inside_the_extended_range_has_no_gross_errors(distance_m):
    frame = simulate(dual_wall(distance_m), RenderRequest(DIRECT))
    assert_frame_bounded(frame)
    img, truth = frame.image, frame.light_field.truth_range_m
    assert img.valid.all()
    assert np.max(np.abs(img.range_m - truth)) < 0.1


def test_dual_frequency_frame_is_stable_under_a_nanometre_wall_move():
    a = simulate(dual_wall(5.0), RenderRequest(DIRECT))
    b = simulate(dual_wall(5.0 + 1e-9), RenderRequest(DIRECT))
    # Same seed, same noise: the range moves by 1e-9 m plus float32 rounding (F32 * 5 m).
    assert_stable(a, b, range_tol_m=1e-5, radiance_rel=1e-5)


@settings(max_examples=150, deadline=None)
@given(
    r=st.floats(0.05, U_EXT - 0.05),
    n1=st.floats(-2e-3, 2e-3),
    n2=st.floats(-2e-3, 2e-3),
)
def test_unwrapping_tolerates_phase_noise_inside_the_extended_range(r, n1, n2):
    # Phase noise of 2 mrad (0.3 mm at 80 MHz) moves the unwrapped range by about as much.
    p1 = phase_from_phasor(np.exp(-1j * (4 * np.pi * F1 * r / SPEED_OF_LIGHT_M_S + n1)))
    p2 = phase_from_phasor(np.exp(-1j * (4 * np.pi * F2 * r / SPEED_OF_LIGHT_M_S + n2)))
    got = unwrap_two_frequencies(np.atleast_1d(p1), F1, np.atleast_1d(p2), F2)[0]
    assert 0.0 <= got < U_EXT
    assert _circle_error(got, r, U_EXT) < 1e-3


# -------------------------------------------------------------------------------------------
# Zero signal through the whole chain
# -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", ["single", "dual"])
@pytest.mark.parametrize("ideal", [False, True], ids=["sensor", "ideal"])
def test_dark_source_gives_a_finite_all_invalid_frame(mode, ideal):
    scene = dual_wall(2.0, power_w=0.0) if mode == "dual" else _single_wall(0.0)
    frame = simulate(scene, RenderRequest(DIRECT, ideal=ideal))
    assert_frame_bounded(frame)
    assert not frame.image.valid.any()
    assert np.all(frame.light_field.dc_active == 0.0)
    if ideal:  # no phasor at all: phase 0 by convention
        assert np.all(frame.image.phase_rad == 0.0)
    else:  # read noise and dark current only: far below the validity threshold
        assert not frame.raw.saturated.any() and not frame.raw.sbi_limit.any()
        assert frame.image.amplitude.max() < ValidityThresholds().min_amplitude_dn


@pytest.mark.parametrize("ideal", [False, True], ids=["sensor", "ideal"])
def test_empty_scene_in_dual_frequency_mode_is_all_invalid_and_finite(ideal):
    scene = build(camera((0, 0, 0), (0, 1, 0), mode="dual"), [])
    frame = simulate(scene, RenderRequest(DIRECT, ideal=ideal))
    assert_frame_bounded(frame)
    assert frame.image.phase_rad.shape[0] == 2
    assert not frame.image.valid.any() and not frame.light_field.hit.any()
    assert np.isnan(frame.light_field.truth_range_m).all()


def _single_wall(power_w):
    wall = {"name": "wall", "mesh": {"kind": "rectangle", "size_m": [40.0, 40.0]},
            "material": lambert(0.8),
            "pose": {"position_m": [0.0, 2.0, 0.0], "rotation_deg": [90.0, 0.0, 0.0]}}
    return build(camera((0, 0, 0), (0, 1, 0)), [wall], power_w=power_w)


@pytest.mark.parametrize("sensor", [{"sbi_enabled": False}, {}], ids=["no-sbi", "sbi"])
def test_a_source_that_saturates_every_pixel_gives_a_finite_all_invalid_frame(sensor):
    wall = {"name": "wall", "mesh": {"kind": "rectangle", "size_m": [4.0, 4.0]},
            "material": lambert(0.8),
            "pose": {"position_m": [0.0, 0.05, 0.0], "rotation_deg": [90.0, 0.0, 0.0]}}
    scene = build(camera((0, 0, 0), (0, 1, 0), sensor=sensor), [wall], power_w=1000.0)
    frame = simulate(scene, RenderRequest(DIRECT))
    assert_frame_bounded(frame)
    assert (frame.raw.saturated | frame.raw.sbi_limit).all()
    assert not frame.image.valid.any()


# -------------------------------------------------------------------------------------------
# Reconstruction of any finite raw frame
# -------------------------------------------------------------------------------------------
finite32 = st.floats(allow_nan=False, allow_infinity=False, width=32)
small32 = st.floats(-5000.0, 5000.0, allow_nan=False, width=32)


@st.composite
def raw_frames(draw, n_f: int) -> RawFrame:
    shape = (draw(st.integers(1, 4)), draw(st.integers(1, 5)))
    elements = st.one_of(small32, finite32, st.sampled_from([0.0, -0.0, 1e-45, 6.0, -6.0]))
    c = draw(hnp.arrays(np.float32, (n_f, 4, *shape), elements=elements))
    flags = hnp.arrays(np.bool_, shape)
    freqs = (F1, F2) if n_f == 2 else (F_60_24_MHZ,)
    return RawFrame(phase_images=c, intensity=np.zeros(shape, dtype=np.float32),
                    frequencies_hz=np.array(freqs), saturated=draw(flags),
                    sbi_limit=draw(flags), exposure_s=5e-4)


@settings(max_examples=120, deadline=None)
@given(raw=st.one_of(raw_frames(1), raw_frames(2)))
def test_any_finite_raw_frame_reconstructs_to_bounded_phases_and_a_consistent_mask(raw):
    z = np.full(raw.shape, 0.9)
    img = reconstruct_raw(raw, z)
    u = ambiguity_range_m(F_60_24_MHZ) if raw.frequencies_hz.size == 1 else U_EXT
    assert np.all(np.isfinite(img.phase_rad))
    assert np.all((img.phase_rad >= 0.0) & (img.phase_rad < TWO_PI))
    assert np.all(np.isfinite(img.amplitude)) and np.all(img.amplitude >= 0.0)
    expected_valid = (img.amplitude >= ValidityThresholds().min_amplitude_dn) & ~(
        raw.saturated | raw.sbi_limit)
    np.testing.assert_array_equal(img.valid, expected_valid)
    r = img.range_m[img.valid]
    assert np.all(np.isfinite(r)) and np.all((r >= 0.0) & (r <= u))
    np.testing.assert_allclose(img.depth_z_m[img.valid], 0.9 * r)
    assert np.all(np.isnan(img.range_m[~img.valid])) and np.all(np.isnan(img.depth_z_m[~img.valid]))


complex_parts = st.floats(-1e150, 1e150, allow_nan=False) | st.sampled_from(
    [0.0, -0.0, 5e-324, -5e-324, 1e-300])


@settings(max_examples=120, deadline=None)
@given(
    re=hnp.arrays(np.float64, (2, 3, 3), elements=complex_parts),
    im=hnp.arrays(np.float64, (2, 3, 3), elements=complex_parts),
    valid=hnp.arrays(np.bool_, (3, 3)),
    dual=st.booleans(),
)
def test_any_finite_phasor_gives_a_phase_in_zero_two_pi_and_finite_valid_ranges(
    re, im, valid, dual
):
    phasor = (re + 1j * im)[: 2 if dual else 1]
    freqs = np.array([F1, F2] if dual else [F_60_24_MHZ])
    img = reconstruct(phasor, np.ones((3, 3)), freqs, np.ones((3, 3)), valid)
    assert np.all((img.phase_rad >= 0.0) & (img.phase_rad < TWO_PI))
    assert np.all(np.isfinite(img.amplitude)) and np.all(img.amplitude >= 0.0)
    np.testing.assert_array_equal(img.valid, valid)
    u = U_EXT if dual else ambiguity_range_m(F_60_24_MHZ)
    r = img.range_m[valid]
    assert np.all(np.isfinite(r)) and np.all((r >= 0.0) & (r <= u))
    assert np.all(np.isnan(img.range_m[~valid]))


@settings(max_examples=100, deadline=None)
@given(phase=st.floats(0.0, TWO_PI, exclude_max=True), rel=st.floats(-1e-9, 1e-9))
def test_phase_is_stable_under_a_tiny_change_of_the_phasor(phase, rel):
    # Away from the wrap at 0 = 2 pi (where the phase jumps by 2 pi, a distance of 0 on the
    # circle), the phase of a unit phasor moves by no more than its perturbation.
    z = np.exp(-1j * phase)
    a = phase_from_phasor(np.array([z]))[0]
    b = phase_from_phasor(np.array([z * (1.0 + rel) * np.exp(1j * rel)]))[0]
    assert min(abs(a - b), TWO_PI - abs(a - b)) <= 2.0 * abs(rel) + 1e-14
