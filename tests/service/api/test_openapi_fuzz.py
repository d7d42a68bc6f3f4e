"""Schemathesis against the OpenAPI document: no generated request makes the service fail (500).

Stateless and bounded: a few examples per operation (hypothesis' generation phase; the
coverage phase, which tries every boundary of every field, would run dozens of full poses),
derandomized, with the bearer token so
that requests get past authentication into validation and the routes (401 has its own test).
The app runs on the simulators with tiny renders; campaigns the fuzzer starts run in the
background and are stopped with the app.

The test drives schemathesis' Python API (a schema, its operations, each operation's hypothesis
strategy) rather than its pytest plugin: the plugin's lazy fixtures reach into pytest's private
node attributes, which pytest 9.2 removed. One test per operation, named after it, as before.
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from schemathesis.checks import not_a_server_error
from schemathesis.python.asgi import shutdown_lifespans

from service.api.app import API_PREFIX, create_app
from tests.service.api.conftest import AUTH, make_settings

pytestmark = pytest.mark.timeout(180)


def _operations() -> list[tuple[str, str]]:
    """(method, path) of every operation in the app's OpenAPI document (no app start needed)."""
    from pathlib import Path

    doc = create_app(make_settings(Path("unused"))).openapi()
    return [(method.upper(), path) for path, item in doc["paths"].items() for method in item]


@pytest.fixture(scope="module")
def api_schema(tmp_path_factory):
    """The app, started, as a schemathesis schema.

    Schemathesis starts the app's lifespan itself (once per app, kept until it is shut down);
    a ``TestClient`` around it would start a second service on the same data directory, which
    the data-directory lock refuses.
    """
    app = create_app(make_settings(tmp_path_factory.mktemp("fuzz"), stop_wait_s=2.0))
    config = schemathesis.Config.from_dict({"phases": {"coverage": {"enabled": False}}})
    try:
        yield schemathesis.openapi.from_asgi(f"{API_PREFIX}/openapi.json", app, config=config)
    finally:
        shutdown_lifespans()  # stops the app: the lab closes and unlocks its data directory


@pytest.mark.parametrize(("method", "path"), _operations(), ids=lambda v: v)
def test_no_generated_request_is_a_server_error(api_schema, method, path):
    operation = next(
        op for op in (result.ok() for result in api_schema.get_all_operations())
        if (op.method.upper(), op.path) == (method, path)
    )

    @given(case=operation.as_strategy())
    @settings(max_examples=6, deadline=None, derandomize=True, database=None,
              phases=[Phase.explicit, Phase.generate], suppress_health_check=list(HealthCheck))
    def check(case):
        case.call_and_validate(headers=AUTH, checks=[not_a_server_error])

    check()
