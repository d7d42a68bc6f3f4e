"""Fixtures for the API tests: the app on the device simulators, tiny renders, a bearer token.

Renders are kept tiny (1 sample per pixel, direct light for the simulated camera) so that a
pose takes a fraction of a second on two cores; the thread executor keeps app start-up fast
(the process pool and Dask have tests of their own); two of its workers make campaigns run
two poses in flight, as a service with two local workers does.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient
from jsonschema import Draft202012Validator
from referencing import Registry, Resource
from referencing.jsonschema import DRAFT202012

from service.api.app import create_app
from service.api.problems import PROBLEM_JSON
from service.settings import Settings

TOKEN = "test-token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
TINY = {"sim_spp": 1, "camera_spp": 1, "camera_integrator": "direct", "workers": 2}


def make_settings(data_dir: Path, **overrides: Any) -> Settings:
    """Settings of a simulated service with tiny renders in ``data_dir``."""
    values = {"token": TOKEN, "data_dir": data_dir, "simulated": True, "executor": "thread",
              **TINY, **overrides}
    return Settings(**values)


@functools.cache
def openapi_document() -> dict[str, Any]:
    """The app's OpenAPI document (the app is made, not started)."""
    return create_app(make_settings(Path("unused"))).openapi()


#: the base URI the OpenAPI document is registered under for its ``$ref``s
OPENAPI_URI = "urn:toftwin:openapi"


def schema_validator(pointer: str, doc: dict[str, Any] | None = None) -> Draft202012Validator:
    """A JSON Schema (2020-12, OpenAPI 3.1's dialect) validator for the schema at ``pointer``
    of the OpenAPI document (``#/components/schemas/Problem``), its ``$ref``s resolved in it."""
    doc = doc if doc is not None else openapi_document()
    registry = Registry().with_resource(
        OPENAPI_URI, Resource.from_contents(doc, default_specification=DRAFT202012))
    return Draft202012Validator({"$ref": OPENAPI_URI + pointer}, registry=registry)


def problem(res: httpx.Response, status: int) -> dict[str, Any]:
    """The body of the error response ``res``, checked: its ``status``, the content type
    ``application/problem+json`` and the OpenAPI document's schema of a problem (422: the
    validation problem), whose ``status`` is the response's."""
    assert res.status_code == status, (res.status_code, res.text[:2000])
    assert res.headers["content-type"] == PROBLEM_JSON, res.headers
    body = res.json()
    schema = "ValidationProblem" if status == 422 else "Problem"
    schema_validator(f"#/components/schemas/{schema}").validate(body)
    assert body["status"] == status, body
    return body


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
