"""The local process pool: an input error raised in a worker reaches the service intact, and
the pool keeps working for the next job."""

from __future__ import annotations

import pytest

from service.compute.executors import LocalExecutor
from service.compute.jobs import make_job
from sim_core.errors import SceneError
from sim_core.render_request import request_from_spec
from sim_core.scene_spec import parse_scene_spec

pytestmark = pytest.mark.timeout(300)

TINY = {"pose": {"position_m": [0, 0, 0], "look_at_m": [0, 0, 1], "up": [0, -1, 0]},
        "width_px": 12, "height_px": 8}


def _job(material: str):
    spec = parse_scene_spec({
        "camera": TINY,
        "objects": [{"name": "plate", "mesh": {"kind": "rectangle", "size_m": [1.0, 1.0]},
                     "material": {"preset": material}, "pose": {"position_m": [0, 0, 1.0]}}],
    })
    return make_job(spec, ".", turntable_deg=None, solar_suns=None,
                    request=request_from_spec(spec.render, spp=1, seed=0, threads=1, ideal=True))


@pytest.mark.slow
def test_a_scene_error_in_a_worker_arrives_whole_and_the_pool_goes_on():
    executor = LocalExecutor(workers=1, threads=1)
    try:
        bad = executor.submit(_job("no-such-preset")).exception(timeout=240)
        assert isinstance(bad, SceneError), repr(bad)
        assert bad.field == "objects[0].material.preset"
        assert "unknown material preset 'no-such-preset'" in str(bad)
        good = executor.submit(_job("black-flannel")).result(timeout=240)
        assert good.image.valid.any()
    finally:
        executor.close()
