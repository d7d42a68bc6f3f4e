"""The chunked renderer: results independent of how the work is split, and honest accounting."""

import numpy as np
import pytest

from sim_core.render import ProgressiveRenderer, RenderSettings, render
from sim_core.render.integrator import STAGES
from sim_core.tracing import RayTracer
from tests.sim_core.scenes import small_example

FIELDS = ("dc_active", "dc_ambient", "phasor", "dc_active_var", "dc_ambient_var", "phasor_cov")


@pytest.fixture(scope="module")
def satellite():
    # ambient light (solar simulator) and microfacet materials: every kernel path runs
    return small_example("satellite_ground_test", width=40)


def _assert_same(a, b):
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_samples_split_over_requests_give_the_same_sums(satellite):
    settings = RenderSettings(spp=7, seed=3)
    whole = ProgressiveRenderer(satellite, settings)
    whole.add_samples(7)
    parts = ProgressiveRenderer(satellite, settings)
    for n in (1, 2, 4):
        parts.add_samples(n)
    _assert_same(whole.light_field(), parts.light_field())
    whole.close()
    parts.close()


def test_a_pixel_gets_the_same_samples_whichever_pixels_come_with_it(satellite):
    settings = RenderSettings(spp=5, seed=11)
    full = ProgressiveRenderer(satellite, settings)
    full.add_samples(5)
    npix = full.npix
    rng = np.random.default_rng(0)
    order = rng.permutation(npix)
    split = ProgressiveRenderer(satellite, settings)
    split.add_samples(5, order[: npix // 3])  # a scattered subset first, the rest after
    split.add_samples(5, order[npix // 3:])
    _assert_same(full.light_field(), split.light_field())
    full.close()
    split.close()


def test_thread_count_does_not_change_a_scene_with_ambient_light(satellite):
    one = render(satellite, RenderSettings(spp=6, seed=5, threads=1)).light_field
    two = render(satellite, RenderSettings(spp=6, seed=5, threads=2)).light_field
    _assert_same(one, two)
    assert one.dc_ambient.max() > 0.0  # the solar simulator's beam is in the picture


@pytest.mark.parametrize(
    ("pixels", "match"),
    [
        ([0, 5, 5], "only once"),
        ([-1], r"\[0, "),
        ([10**9], r"\[0, "),
        ([True, False, True], "flatnonzero"),
        ([1.5, 2.0], "integer"),
    ],
)
def test_bad_pixel_requests_name_the_problem_and_add_nothing(satellite, pixels, match):
    r = ProgressiveRenderer(satellite, RenderSettings(spp=1))
    with pytest.raises(ValueError, match="pixels"):
        r.add_samples(1, np.array(pixels))
    with pytest.raises(ValueError, match=match):
        r.add_samples(1, np.array(pixels))
    assert r.samples.sum() == 0
    r.close()


@pytest.mark.parametrize("backend", ["binding", "embreex"])
def test_time_accounting_adds_up(satellite, backend):
    """The relations between the clocks hold at any load: they are checked exactly (clock by
    clock, interval by interval), never as a ratio of two wall clocks that the scheduler can
    stretch one at a time."""
    with RayTracer(satellite.triangles_m, satellite.camera.position_m, threads=2,
                   backend=backend) as tracer:
        renderer = ProgressiveRenderer(satellite, RenderSettings(spp=8, seed=1), tracer)
        truth_s = tracer.stats.seconds  # the ground-truth pass: the tracer's first queries
        renderer.add_samples(8)
        res = renderer.result()
        renderer.close()
    capacity = res.seconds * res.threads
    assert (res.threads, tracer.backend) == (2, backend)
    assert set(res.stage_thread_seconds) == set(STAGES)
    assert all(v > 0.0 for v in res.stage_thread_seconds.values())
    # The ground-truth pass is timed inside its own stretch of the render.
    assert 0.0 < truth_s <= res.timings_s["ground_truth"] * res.threads
    # The tracer's clock holds the ground-truth pass and every query of the path tracing, the
    # stages' Embree lap the path tracing's queries: on the binding the compiled kernel's clock
    # is charged to both, so they agree to rounding; on embreex the lap runs around the
    # tracer's timed call (and adds the Python call), so it holds it.
    stage_embree = res.stage_thread_seconds["embree"]
    tracing_embree = res.embree_thread_seconds - truth_s
    if backend == "binding":
        assert stage_embree == pytest.approx(tracing_embree, rel=1e-9)
    else:
        assert stage_embree >= tracing_embree * (1 - 1e-9) > 0.0
    # The stages are disjoint laps of tasks that run one after another on each thread, inside
    # the render's wall time; Embree's share of the capacity is part of it.
    assert sum(res.stage_thread_seconds.values()) <= capacity
    assert 0.0 < res.embree_share < 1.0
    assert res.rays_traced > satellite.camera.intrinsics.width_px * 8


def test_progress_reaches_the_total(satellite):
    seen = []
    render(satellite, RenderSettings(spp=9, seed=2), progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (9, 9)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)


def test_a_non_integer_sample_count_is_refused(satellite):
    r = ProgressiveRenderer(satellite, RenderSettings(spp=1))
    with pytest.raises(ValueError, match=r"^n: .*integer"):
        r.add_samples(2.5)
    assert r.samples.sum() == 0
    r.close()


@pytest.mark.parametrize("threads", [1, 2])
def test_progress_comes_block_by_block_and_an_exception_from_it_stops_the_render(
    satellite, threads
):
    with RayTracer(satellite.triangles_m, satellite.camera.position_m, threads=threads) as tr:
        r = ProgressiveRenderer(satellite, RenderSettings(spp=4), tr)
        seen = []
        r.add_samples(4, progress=lambda d, t: seen.append(d))
        assert len(seen) > 2 and seen[-1] == 4  # reported as blocks finish, not once at the end

        class StopError(Exception):
            pass

        def stop(done, total):
            raise StopError

        before = int(r.samples.sum())
        # 64 samples: many blocks, most of them not started at the first report
        with pytest.raises(StopError):
            r.add_samples(64, progress=stop)
        added = int(r.samples.sum()) - before
        assert 0 < added < 64 * r.npix  # stopped early; what was added stays counted
        assert set(np.unique(r.samples)) <= {4, 68}  # every pixel has whole requests only
