"""Schemathesis against the OpenAPI document: no generated request makes the service fail (500).

Stateless and bounded: a few examples per operation (hypothesis' generation phase; the
coverage phase, which tries every boundary of every field, would run dozens of full poses),
derandomized, with the bearer token so
that requests get past authentication into validation and the routes (401 has its own test).
The app runs on the simulators with tiny renders; campaigns the fuzzer starts run in the
background and are stopped with the app.
"""

from __future__ import annotations

import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, Phase, settings
from schemathesis.checks import not_a_server_error

from service.app import create_app
from tests.service.api.conftest import AUTH, make_settings

pytestmark = pytest.mark.timeout(180)


@pytest.fixture(scope="module")
def api_schema(tmp_path_factory):
    """The app, started, as a schemathesis schema."""
    app = create_app(make_settings(tmp_path_factory.mktemp("fuzz"), stop_wait_s=2.0))
    config = schemathesis.Config.from_dict({"phases": {"coverage": {"enabled": False}}})
    with TestClient(app):
        yield schemathesis.openapi.from_asgi("/api/v1/openapi.json", app, config=config)


schema = schemathesis.pytest.from_fixture("api_schema")


@schema.parametrize()
@settings(max_examples=6, deadline=None, derandomize=True, database=None,
          phases=[Phase.explicit, Phase.generate], suppress_health_check=list(HealthCheck))
def test_no_generated_request_is_a_server_error(case):
    case.call_and_validate(headers=AUTH, checks=[not_a_server_error])
