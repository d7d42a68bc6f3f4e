"""Renders from several threads at once are safe (numba's workqueue layer is not)."""

import threading

import numpy as np

from sim_core.render import RenderSettings, render
from tests.sim_core.scenes import small_example


def test_concurrent_renders_from_threads_finish_and_match_a_serial_render():
    scene = small_example("corner", width=24)
    settings = RenderSettings(spp=8, seed=4)
    serial = render(scene, settings).light_field.phasor
    results, errors = [None] * 3, []

    def work(i):
        try:
            results[i] = render(scene, settings).light_field.phasor
        except Exception as exc:  # surfaced below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not errors
    for r in results:
        np.testing.assert_array_equal(r, serial)
