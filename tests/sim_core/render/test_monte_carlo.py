"""Statistical behaviour of the path integrator: convergence, determinism, seeds."""

import numpy as np

from sim_core.render import RenderSettings, render

#: the ``corner`` and its converged ``reference`` (tests/sim_core/conftest.py)
CORNER_WIDTH_PX = 32
REFERENCE_SPP, REFERENCE_SEED = 4096, 12345


def test_monte_carlo_error_falls_as_one_over_sqrt_spp(corner, reference):
    pixels = np.s_[4:20, 8:24]  # a fixed pixel set on the three walls
    spps = np.array([4, 16, 64, 256])
    errs = []
    for spp in spps:
        # Average the squared error over several seeds so the slope is not one draw's luck.
        sq = [
            np.mean((render(corner, RenderSettings(spp=int(spp), seed=s)).light_field.dc_active
                     - reference.dc_active)[pixels] ** 2)
            for s in range(4)
        ]
        errs.append(np.sqrt(np.mean(sq)))
    slope = np.polyfit(np.log(spps), np.log(errs), 1)[0]
    assert -0.6 < slope < -0.4, (slope, errs)


def test_reported_standard_error_matches_the_spread_between_seeds(corner):
    a = render(corner, RenderSettings(spp=64, seed=1)).light_field
    b = render(corner, RenderSettings(spp=64, seed=2)).light_field
    se2 = (a.dc_active_var + b.dc_active_var) / 64
    ok = se2 > 0
    z2 = (a.dc_active - b.dc_active)[ok] ** 2 / se2[ok]
    # z is about standard normal per pixel: its mean square is 1 within sampling error.
    assert ok.sum() > 300
    assert 0.8 < z2.mean() < 1.25


def test_same_seed_is_bit_identical_whatever_the_thread_count(corner):
    one = render(corner, RenderSettings(spp=16, seed=7, threads=1)).light_field
    two = render(corner, RenderSettings(spp=16, seed=7, threads=2)).light_field
    for name in ("dc_active", "dc_ambient", "phasor", "dc_active_var", "truth_range_m"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name), err_msg=name)


def test_different_seeds_differ(corner):
    a = render(corner, RenderSettings(spp=4, seed=1)).light_field
    b = render(corner, RenderSettings(spp=4, seed=2)).light_field
    assert not np.array_equal(a.dc_active, b.dc_active)


def test_multipath_adds_light_and_shortens_no_path(corner, reference):
    direct = render(corner, RenderSettings(integrator="direct", spp=16, seed=3)).light_field
    # Indirect light only adds: every pixel is at least as bright as its direct part, and its
    # phasor magnitude is no larger than its DC (paths of different length interfere).
    assert np.all(reference.dc_active >= direct.dc_active * (1 - 0.05))
    assert np.all(np.abs(reference.phasor[0]) <= reference.dc_active * (1 + 1e-9))
    ratio = (reference.dc_active / direct.dc_active)[direct.dc_active > 0]
    assert ratio.mean() > 1.2  # a corner of albedo-0.5 walls: strong interreflection
