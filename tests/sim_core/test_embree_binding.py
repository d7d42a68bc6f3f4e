"""Our Embree binding: the same answers and frames as embreex, packet widths checked, numba cache.

Where the binding cannot load, the tracer must fall back to embreex and say why: the tests
that need the binding then assert exactly that (:func:`_binding_or_fallback`) instead of
skipping.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from sim_core import embree_binding as eb
from sim_core.render import RenderSettings, render
from sim_core.tracing import BACKEND_ENV, PacketWidths, RayTracer
from tests.hard_cases.helpers import CENTRE, PATH, build, camera, lambert, rectangle
from tests.hard_cases.test_render_geometry import cluttered_scene, grazing_wall
from tests.sim_core.scenes import EXAMPLES, example, small_example

ROOT = Path(__file__).resolve().parents[2]
FIELDS = ("dc_active", "dc_ambient", "phasor", "dc_active_var", "dc_ambient_var", "phasor_cov",
          "truth_range_m", "truth_normal", "object_id", "hit")


def _binding_or_fallback() -> bool:
    """True where the binding loads; else asserts that tracers fall back to embreex, saying why."""
    if eb.AVAILABLE:
        return True
    tracer = RayTracer(np.zeros((0, 3, 3)), np.zeros(3), threads=1)
    assert tracer.backend == "embreex"
    assert tracer.fallback_reason and eb.UNAVAILABLE_REASON in tracer.fallback_reason
    with pytest.raises(eb.EmbreeBindingError, match="unavailable"):
        RayTracer(np.zeros((0, 3, 3)), np.zeros(3), threads=1, backend="binding")
    return False


def _random_rays(m: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Half from the render origin (camera rays), half from scattered points; unit float32."""
    rng = np.random.default_rng(seed)
    o = (rng.normal(size=(m, 3)) * 0.5).astype(np.float32)
    o[: m // 2] = 0.0
    d = rng.normal(size=(m, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return o, d.astype(np.float32)


@pytest.mark.parametrize("name", ["corner", "satellite_ground_test"])
def test_every_supported_width_answers_like_embreex_bit_for_bit(name):
    if not _binding_or_fallback():
        return
    scene = example(name)
    fallback = RayTracer(scene.triangles_m, scene.camera.position_m, threads=1,
                         backend="embreex")
    o, d = _random_rays(20_000)
    t_ref, p_ref = fallback.intersect32(o, d)
    assert 0.1 < (p_ref >= 0).mean() < 0.9  # hits and misses both tested
    rng = np.random.default_rng(1)
    tmax = np.where(p_ref >= 0, t_ref, 5.0) * rng.uniform(0.5, 1.5, o.shape[0])
    occ_ref = fallback.occluded_here(o, d, tmax.astype(np.float32))
    assert 0.05 < (occ_ref == 0).mean() < 0.95
    ours = eb.EmbreeScene((scene.triangles_m - scene.camera.position_m).astype(np.float32))
    for w in eb.supported_widths():
        tfar = np.empty(o.shape[0], np.float32)
        prim = np.empty(o.shape[0], np.int32)
        occ = np.empty(o.shape[0], np.int32)
        counters = np.zeros(2)
        eb.intersect(ours.handle, o, d, w, eb.packet_buffer(), tfar, prim, counters)
        eb.occluded(ours.handle, o, d, tmax.astype(np.float32), w, eb.packet_buffer(), occ,
                    counters)
        np.testing.assert_array_equal(prim, p_ref, err_msg=f"width {w}")
        np.testing.assert_array_equal(tfar.view(np.uint32), t_ref.view(np.uint32))
        np.testing.assert_array_equal(occ, occ_ref, err_msg=f"width {w}")
        assert counters[0] == 2 * o.shape[0] and counters[1] > 0.0
    ours.close()


def _assert_backends_agree(scene, settings: RenderSettings, threads=(1, 2)) -> None:
    """Frames of the binding (each thread count) and of embreex are bit-identical."""
    with RayTracer(scene.triangles_m, scene.camera.position_m, threads=2,
                   backend="embreex") as t:
        ref = render(scene, settings, t).light_field
    for n in threads:
        with RayTracer(scene.triangles_m, scene.camera.position_m, threads=n,
                       backend="binding") as t:
            assert t.kernel_scene is not None
            lf = render(scene, settings, t).light_field
        for f in FIELDS:
            np.testing.assert_array_equal(getattr(lf, f), getattr(ref, f),
                                          err_msg=f"{f}, {n} thread(s)")


@pytest.mark.parametrize("name", sorted(p.stem for p in EXAMPLES.glob("*.yaml")))
def test_example_frames_equal_the_embreex_fallback(name):
    if not _binding_or_fallback():
        return
    _assert_backends_agree(small_example(name, width=32),
                           RenderSettings(spp=4, max_bounces=3, seed=9))


@pytest.mark.parametrize(
    "make",
    [
        lambda: grazing_wall(),
        lambda: cluttered_scene(),
        lambda: cluttered_scene((1e6, -2e6, 3e5)),
        # coincident faces: which one a ray meets must not depend on the backend
        lambda: build(camera((0, 0, 0), (0, 1, 0)), [
            rectangle("dark", (10.0, 10.0), lambert(0.2), (0.0, 2.0, 0.0), (90.0, 0.0, 0.0)),
            rectangle("bright", (10.0, 10.0), lambert(0.8), (0.0, 2.0, 0.0), (90.0, 37.0, 0.0)),
        ]),
        # a sunlit ball: grazing shadow rays along its own facets
        lambda: build(camera((0, 0, 0), (0, 1, 0)), [
            {"name": "ball", "mesh": {"kind": "sphere", "radius_m": 0.5, "subdivisions": 3},
             "material": lambert(0.9), "pose": {"position_m": [0.0, 2.0, 0.0]}}],
            ambient={"sun": {"direction": [0.6, 0.3, -0.74]}}),
    ],
    ids=["grazing-wall", "cluttered", "cluttered-1e6-m", "coincident-faces", "sunlit-ball"],
)
@pytest.mark.parametrize("settings", [CENTRE, PATH], ids=["direct", "path"])
def test_hard_case_frames_equal_the_embreex_fallback(make, settings):
    if not _binding_or_fallback():
        return
    _assert_backends_agree(make(), settings, threads=(2,))


def test_an_unsupported_packet_width_is_refused_clearly():
    if not _binding_or_fallback():
        return
    ok = eb.supported_widths()
    assert 1 in ok and set(ok) <= set(eb.WIDTHS)
    assert eb.version() >= 40000
    scene = example("corner")
    for bad in [3, 32, *(w for w in eb.WIDTHS if w not in ok)]:
        with pytest.raises(eb.UnsupportedPacketWidthError, match="supported widths"):
            eb.check_width(bad)
        with pytest.raises(eb.UnsupportedPacketWidthError, match=f"packet width {bad}"):
            RayTracer(scene.triangles_m, scene.camera.position_m, threads=1,
                      widths=PacketWidths(shadow=bad))
    # the defaults are always supported ones
    with RayTracer(scene.triangles_m, scene.camera.position_m, threads=1) as t:
        assert all(w in ok for w in t.widths)
        assert t.widths[2] == eb.widest()


def test_the_backend_is_chosen_by_argument_or_environment(monkeypatch):
    scene = example("corner")
    args = (scene.triangles_m, scene.camera.position_m, 1)
    with pytest.raises(ValueError, match="backend must be one of"):
        RayTracer(*args, backend="optix")
    monkeypatch.setenv(BACKEND_ENV, "embreex")
    t = RayTracer(*args)
    assert (t.backend, t.kernel_scene, t.widths) == ("embreex", None, (1, 1, 1))
    assert t.fallback_reason == "embreex requested"
    monkeypatch.delenv(BACKEND_ENV)
    t = RayTracer(*args)
    assert t.backend == ("binding" if eb.AVAILABLE else "embreex")


def test_the_library_is_the_one_embreex_loaded():
    if not _binding_or_fallback():
        return
    path = eb.find_library()
    assert "libembree4" in Path(path).name
    if Path("/proc/self/maps").exists():
        assert path in eb._loaded_embree_paths()


def _twice_with_one_cache(code: str, cache_dir: Path) -> list[tuple[int, int, float]]:
    """Run ``code`` (printing cache hits, misses and seconds) in two fresh processes that share
    a new numba cache directory; their (hits, misses, seconds)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir), "PYTHONPATH": str(ROOT)}
    runs = []
    for _ in range(2):
        proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
        hits, misses, seconds = proc.stdout.split()
        runs.append((int(hits), int(misses), float(seconds)))
    return runs


_CACHE_PROBE = textwrap.dedent("""
    import time
    t0 = time.perf_counter()
    import numpy as np
    from sim_core import embree_binding as eb
    s = eb.EmbreeScene(np.array([[[-1, -1, 2], [1, -1, 2], [0, 1, 2]]], np.float32))
    o = np.zeros((5, 3), np.float32)
    d = np.tile(np.array([0, 0, 1], np.float32), (5, 1))
    t, p, occ = np.empty(5, np.float32), np.empty(5, np.int32), np.empty(5, np.int32)
    c = np.zeros(2)
    eb.intersect(s.handle, o, d, eb.widest(), eb.packet_buffer(), t, p, c)
    eb.occluded(s.handle, o, d, np.full(5, 9, np.float32), 1, eb.packet_buffer(), occ, c)
    assert (p == 0).all() and np.allclose(t, 2) and (occ == 0).all(), (p, t, occ)
    hits = sum(f.stats.cache_hits.total() for f in (eb.intersect, eb.occluded))
    misses = sum(f.stats.cache_misses.total() for f in (eb.intersect, eb.occluded))
    print(hits, misses, time.perf_counter() - t0)
""")


def test_a_second_process_loads_the_compiled_queries_from_numba_s_cache(tmp_path):
    if not _binding_or_fallback():
        return
    (h1, m1, s1), (h2, m2, s2) = _twice_with_one_cache(_CACHE_PROBE, tmp_path)
    assert h1 == 0 and m1 == 2  # compiled (the external functions do not prevent caching)
    assert h2 == 2 and m2 == 0  # loaded, no recompilation
    assert s2 < s1


@pytest.mark.slow
def test_a_second_process_renders_its_first_frame_without_compiling(tmp_path):
    """The whole renderer, binding path: the second process starts in well under the first."""
    if not _binding_or_fallback():
        return
    code = textwrap.dedent("""
        import time
        t0 = time.perf_counter()
        from sim_core.render import RenderSettings, render, kernels
        from tests.sim_core.scenes import small_example
        render(small_example("corner", width=16), RenderSettings(spp=1, max_bounces=3))
        st = kernels.trace_paths.stats
        print(st.cache_hits.total(), st.cache_misses.total(), time.perf_counter() - t0)
    """)
    runs = _twice_with_one_cache(code, tmp_path)
    (h1, m1, s1), (h2, m2, s2) = runs
    assert (h1, m1) == (0, 1) and (h2, m2) == (1, 0)
    assert s2 < 0.5 * s1, runs


def test_a_binding_that_cannot_load_falls_back_to_embreex_and_says_why(monkeypatch):
    """As on a machine where the library is not found: auto falls back, "binding" refuses."""
    monkeypatch.setattr(eb, "_LIB", None)
    monkeypatch.setattr(eb, "_DEVICE", None)
    monkeypatch.setattr(eb, "UNAVAILABLE_REASON", "EmbreeBindingError: no libembree4 found")
    monkeypatch.delenv(BACKEND_ENV, raising=False)
    scene = small_example("corner", width=16)
    with RayTracer(scene.triangles_m, scene.camera.position_m, threads=1) as t:
        assert t.backend == "embreex" and t.kernel_scene is None
        assert "no libembree4 found" in t.fallback_reason
        lf = render(scene, RenderSettings(spp=2, seed=1), t).light_field
    assert np.isfinite(lf.dc_active).all() and lf.dc_active.max() > 0.0
    with pytest.raises(eb.EmbreeBindingError, match="no libembree4 found"):
        RayTracer(scene.triangles_m, scene.camera.position_m, threads=1, backend="binding")
