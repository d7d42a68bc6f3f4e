"""Simulation jobs on a Dask cluster give the local executor's results, bit for bit.

A ``distributed.LocalCluster`` of one worker process on loopback stands in for the cluster;
the service reaches it only through ``--executor dask://HOST:PORT``.

Dask's ``distributed`` is the ``dask`` extra, not a dependency of the service. These tests are
marked ``dask``: the README's test command installs the extra and runs them; a venv without it
(CI's floors venv) deselects them with ``-m 'not slow and not root and not dask'``, and
tests/service/compute/test_dask_extra.py checks the service's refusal there.
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from tests.service.api.conftest import start_campaign, wait_campaign

pytestmark = [pytest.mark.dask, pytest.mark.timeout(150)]

POSES = [{"turntable_deg": -30, "repeats": 2}, {"turntable_deg": 20, "solar_suns": 0.9}]


@pytest.fixture(scope="module")
def dask_address():
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        yield cluster.scheduler_address.replace("tcp://", "dask://")


def run(client) -> tuple[list[dict], dict[str, np.ndarray]]:
    cid = start_campaign(client, POSES, seed=11)
    status = wait_campaign(client, cid, lambda s: s["state"] != "running", timeout_s=90)
    assert status["state"] == "completed", status
    rows = client.get(f"/api/v1/campaigns/{cid}/results").json()
    arrays = {}
    for r in rows:
        data = client.get(f"/api/v1/frames/{r['simulated_frame_id']}/arrays").content
        with np.load(io.BytesIO(data)) as z:
            arrays[(r["pose_index"], r["repeat"])] = {k: z[k] for k in z.files}
    return rows, arrays


def test_a_campaign_on_dask_equals_the_local_executor(make_client, tmp_path, dask_address):
    # both services first: the local pool's worker and the Dask worker load the renderer at
    # the same time (a service starts its workers' warm-up when it opens)
    local = make_client(tmp_path / "local", executor="local", workers=1)
    remote = make_client(tmp_path / "dask", executor=dask_address)
    assert local.get("/api/v1/health").json()["executor"] == "local"
    assert remote.get("/api/v1/health").json()["executor"] == "dask"
    rows_local, arrays_local = run(local)
    rows_dask, arrays_dask = run(remote)

    assert len(rows_local) == len(rows_dask) == 3
    for a, b in zip(rows_local, rows_dask, strict=True):
        assert (a["pose_index"], a["repeat"]) == (b["pose_index"], b["repeat"])
        assert a["metrics"] == b["metrics"]
    for key, frame in arrays_local.items():
        for name in ("range_m", "amplitude", "phasor", "object_id", "valid"):
            np.testing.assert_array_equal(frame[name], arrays_dask[key][name], err_msg=name)
    meta = remote.get(f"/api/v1/frames/{rows_dask[0]['simulated_frame_id']}").json()["metadata"]
    assert meta["worker"] != local.get(
        f"/api/v1/frames/{rows_local[0]['simulated_frame_id']}").json()["metadata"]["worker"]
