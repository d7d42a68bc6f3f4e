"""Fixtures for the API tests: the app on the device simulators, tiny renders, a bearer token.

Renders are kept tiny (1 sample per pixel, direct light for the simulated camera) so that a
pose takes a fraction of a second on two cores; the thread executor keeps app start-up fast
(the process pool and Dask have tests of their own); two of its workers make campaigns run
two poses in flight, as a service with two local workers does.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from service.api.app import create_app
from service.settings import Settings

TOKEN = "test-token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
TINY = {"sim_spp": 1, "camera_spp": 1, "camera_integrator": "direct", "workers": 2}


def make_settings(data_dir: Path, **overrides: Any) -> Settings:
    """Settings of a simulated service with tiny renders in ``data_dir``."""
    values = {"token": TOKEN, "data_dir": data_dir, "simulated": True, "executor": "thread",
              **TINY, **overrides}
    return Settings(**values)


@pytest.fixture
def make_client(tmp_path: Path) -> Iterator[Callable[..., TestClient]]:
    """Factory: a started app (TestClient) for settings overrides; all closed at the end."""
    opened: list[TestClient] = []

    def make(data_dir: Path | None = None, **overrides: Any) -> TestClient:
        client = TestClient(create_app(make_settings(data_dir or tmp_path, **overrides)))
        client.__enter__()
        opened.append(client)
        return client

    yield make
    for client in reversed(opened):
        client.__exit__(None, None, None)


@pytest.fixture
def client(make_client) -> TestClient:
    """The app on the simulators with tiny renders."""
    return make_client()


def wait_campaign(
    client: TestClient, cid: str, until: Callable[[dict], bool], timeout_s: float = 60.0,
    poll_s: float = 0.02,
) -> dict:
    """Poll ``GET /campaigns/{cid}`` until ``until(status)``; fail after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        status = client.get(f"/api/v1/campaigns/{cid}").json()
        if until(status):
            return status
        if time.monotonic() > deadline:
            raise AssertionError(f"campaign {cid} did not get there in {timeout_s} s: {status}")
        time.sleep(poll_s)


def start_campaign(client: TestClient, poses: list[dict], **fields: Any) -> str:
    """Create and start a campaign; returns its id."""
    res = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": "test", "poses": poses, **fields})
    assert res.status_code == 201, res.text
    cid = res.json()["id"]
    res = client.post(f"/api/v1/campaigns/{cid}/start", headers=AUTH)
    assert res.status_code == 200, res.text
    return cid
