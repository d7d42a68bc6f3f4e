"""A capture with the calibrated stray light taken out (issue 27): the board's phases as
without it, so the depth fit is not pulled towards the surroundings."""

from __future__ import annotations

import numpy as np

from calibration.captures import average_frames, without_stray_light
from sim_core.optics import StrayLight
from sim_core.raw import RawFrame

STRAY = StrayLight(0.03, 60.0)
SHAPE = (40, 56)


def _frame(phasor: np.ndarray, offset_dn: np.ndarray) -> RawFrame:
    """A one-frequency frame whose ``(C0 - C2) - 1j (C3 - C1)`` is ``phasor``, each pair
    centred on ``offset_dn``."""
    x, y = phasor.real, -phasor.imag
    c = np.stack([offset_dn + x / 2, offset_dn - y / 2, offset_dn - x / 2, offset_dn + y / 2])
    return RawFrame(phase_images=c[None], intensity=2.0 * offset_dn,
                    frequencies_hz=np.array([60.24e6]), saturated=np.zeros(SHAPE, bool),
                    sbi_limit=np.zeros(SHAPE, bool), exposure_s=1e-3)


def test_the_stray_light_is_taken_out_of_a_captures_phases_and_amplitude():
    # a bright near patch (phase 1.0) in front of a dark far wall (phase 2.5)
    amplitude = np.full(SHAPE, 20.0)
    phase = np.full(SHAPE, 2.5)
    amplitude[10:30, 15:40], phase[10:30, 15:40] = 900.0, 1.0
    true = 2.0 * amplitude * np.exp(-1j * phase)
    offset = 300.0 + amplitude
    cap = average_frames([_frame(STRAY.apply(true), STRAY.apply(offset))])
    wall = (slice(0, 6), slice(0, 10))
    # the wall's phase is pulled towards the patch's as measured ...
    assert np.all(np.abs(cap.phase_rad[0][wall] - 2.5) > 0.1)
    clean = without_stray_light(cap, STRAY)
    # ... and is its own again with the stray light taken out, the amplitude too
    np.testing.assert_allclose(clean.phase_rad[0], phase, atol=1e-9)
    np.testing.assert_allclose(clean.amplitude, amplitude, rtol=1e-9)
    # each pair's sum (the tap offsets) and everything else stay as measured
    c, c0 = clean.phase_images[0], cap.phase_images[0]
    np.testing.assert_allclose(c[0] + c[2], c0[0] + c0[2], rtol=1e-12)
    np.testing.assert_allclose(c[1] + c[3], c0[1] + c0[3], rtol=1e-12)
    assert clean.intensity is cap.intensity and clean.valid is cap.valid
    assert clean.n_frames == cap.n_frames
