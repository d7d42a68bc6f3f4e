"""The depth-error model: forward (twin) and inverse (correction) agree; edges are safe."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from sim_core.depth_errors import (
    DepthErrorModel,
    grid_pixel_offsets_m,
    pixel_offsets_to_grid,
    random_pixel_offsets_m,
    range_to_phase_rad,
)
from sim_core.errors import InvalidInputError
from sim_core.tof import phase_from_phasor
from sim_core.twin_file import DepthErrors, PixelOffsetPattern, WigglingTerm, parse_calibration

F = (60.24e6,)


def _model(offset=0.03, terms=((4, 0.015, 0.6),), sigma=0.004, shape=(20, 30), freqs=F):
    spec = DepthErrors(
        phase_offset_rad=[offset],
        wiggling=[WigglingTerm(harmonic=h, amplitude_rad=a, phase_rad=p) for h, a, p in terms],
        pixel_offset_m=PixelOffsetPattern(sigma=sigma, correlation_px=3, seed=1),
    )
    return DepthErrorModel.from_spec(spec, freqs, shape)


def test_applied_errors_follow_the_convention():
    """measured phase = true + offset + a sin(h phi + p) + 4 pi f o / c (issue 13, section 1)."""
    m = _model()
    phi = np.linspace(0.1, 6.0, 600).reshape(20, 30)
    z = 3.0 * np.exp(-1j * phi)[None]
    measured = phase_from_phasor(m.apply_to_phasor(z))[0]
    expect = phi + 0.03 + 0.015 * np.sin(4 * phi + 0.6) + range_to_phase_rad(
        m.pixel_offsets_m, F[0])
    diff = np.angle(np.exp(1j * (measured - expect)))
    assert np.max(np.abs(diff)) < 1e-12
    assert np.allclose(np.abs(m.apply_to_phasor(z)), 3.0)


@settings(max_examples=60, deadline=None)
@given(
    offset=st.floats(-3.0, 3.0),
    amps=st.lists(st.tuples(st.integers(1, 6), st.floats(0.0, 0.04), st.floats(-3, 3)),
                  max_size=3),
    phi=st.floats(0.0, 2 * np.pi, exclude_max=True),
)
def test_correction_inverts_the_errors(offset, amps, phi):
    # A wiggling whose sum of amplitude x harmonic reaches 0.5 folds the phase: the file
    # refuses it (test_wiggling_that_folds_the_phase_is_refused), so it is not a case to invert.
    assume(sum(a * h for h, a, _ in amps) < 0.5)
    m = _model(offset=offset, terms=tuple(amps), sigma=0.01, shape=(4, 5))
    z = np.full((1, 4, 5), np.exp(-1j * phi))
    measured = phase_from_phasor(m.apply_to_phasor(z))
    back = m.correct_phase(measured)
    diff = np.angle(np.exp(1j * (back - phi)))
    assert np.all(np.abs(diff) < 1e-9)
    assert np.all((back >= 0) & (back < 2 * np.pi))


def test_zero_phasor_and_nan_phase_are_safe():
    m = _model(shape=(2, 2))
    assert np.all(m.apply_to_phasor(np.zeros((1, 2, 2), complex)) == 0)
    out = m.correct_phase(np.full((1, 2, 2), np.nan))
    assert np.all(np.isnan(out))


def test_wiggling_that_folds_the_phase_is_refused():
    # Where the file is parsed (issue 25), not first when a simulation builds the model.
    bad = {"camera": {"depth": {"wiggling": [{"harmonic": 8, "amplitude_rad": 0.1}]}}}
    with pytest.raises(InvalidInputError, match=r"camera\.depth\.wiggling.*below 0\.5"):
        parse_calibration(bad)


def test_offsets_per_frequency_must_match_the_use_case():
    spec = DepthErrors(phase_offset_rad=[0.1, 0.2, 0.3])
    with pytest.raises(InvalidInputError, match=r"phase_offset_rad.*3 entries for 2"):
        DepthErrorModel.from_spec(spec, (80.32e6, 60.24e6), (4, 4))


def test_the_pattern_has_the_requested_spread_and_the_grid_reproduces_it():
    o = random_pixel_offsets_m(PixelOffsetPattern(sigma=0.004, correlation_px=12, seed=5),
                               (171, 224))
    assert o.std() == pytest.approx(0.004, rel=1e-9)
    back = grid_pixel_offsets_m(pixel_offsets_to_grid(o, 4), o.shape)
    assert np.sqrt(np.mean((back - o) ** 2)) < 0.1e-3  # well under a mm


def test_a_grid_too_small_for_the_image_is_refused():
    grid = pixel_offsets_to_grid(np.zeros((8, 8)), 4)
    with pytest.raises(InvalidInputError, match="does not cover"):
        grid_pixel_offsets_m(grid, (171, 224))
