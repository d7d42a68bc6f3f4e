"""One error shape: every error the service answers is an RFC 9457 problem, declared in the
OpenAPI document for the operation and status that sent it, and the operation ids are readable.

The walk goes over every operation of the OpenAPI document and provokes the errors any request
can meet without setting up state: no token (401), an id that names nothing (404), a malformed
id, parameter or body (422), a method the path does not take (405, the ``default`` response).
Each body is validated (jsonschema, OpenAPI 3.1's JSON Schema dialect) against the schema the
document declares for that operation, status and content type.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from service.api.app import create_app
from service.api.problems import PROBLEM_JSON, PROBLEM_TYPES
from service.errors import ServiceError
from tests.service.api.conftest import AUTH, make_settings, problem, schema_validator

pytestmark = pytest.mark.timeout(120)
REPO = Path(__file__).parents[3]
#: ids that match their pattern but name nothing, by parameter name
NOBODY = {"campaign_id": "0" * 32, "job_id": "0" * 32, "frame_id": "0" * 32,
          "pose_id": "999999", "name": "report.json"}
#: the same parameters, malformed
MALFORMED = {"campaign_id": "not-an-id", "job_id": "not-an-id", "frame_id": "NOT-HEX",
             "pose_id": "0", "name": "no such name", "kind": "no-such-kind"}
#: HTTP methods no route takes
UNUSED_METHOD = "PATCH"


def _path_values(op: dict[str, Any], values: dict[str, str]) -> dict[str, str]:
    out = {}
    for p in op.get("parameters", []):
        if p["in"] != "path":
            continue
        enum = p["schema"].get("enum")
        if values is NOBODY and enum:
            out[p["name"]] = enum[0]  # a real name, so that the id decides
        else:
            assert p["name"] in values, f"no sample value for path parameter {p['name']!r}"
            out[p["name"]] = values[p["name"]]
    return out


def _url(path: str, values: dict[str, str]) -> str:
    return re.sub(r"\{(\w+)\}", lambda m: values[m.group(1)], path)


def _provocations(path: str, method: str, op: dict[str, Any]) -> list[tuple[str, dict, int]]:
    """(url, request kwargs, expected status) of the errors this operation must answer."""
    out: list[tuple[str, dict, int]] = []
    params = op.get("parameters", [])
    has_path = any(p["in"] == "path" for p in params)
    ok_url = _url(path, _path_values(op, NOBODY)) if has_path else path
    if op.get("security"):
        out.append((ok_url, {}, 401))
    if has_path:
        out.append((ok_url, {"headers": AUTH}, 404))
        out.append((_url(path, _path_values(op, MALFORMED)), {"headers": AUTH}, 422))
    for p in params:
        if p["in"] == "query":
            schema = p["schema"]
            bad = schema["minimum"] - 1 if "minimum" in schema else "no-such-value"
            out.append((ok_url, {"headers": AUTH, "params": {p["name"]: bad}}, 422))
    if "requestBody" in op:
        out.append((ok_url, {"headers": AUTH, "json": []}, 422))  # not an object
        out.append((ok_url, {"headers": {**AUTH, "Content-Type": "application/json"},
                             "content": b'{"cut short'}, 422))
    return out


@pytest.fixture(scope="module")
def api(tmp_path_factory):
    app = create_app(make_settings(tmp_path_factory.mktemp("problems")))
    with TestClient(app) as client:
        yield client, client.get("/api/v1/openapi.json").json()


def _check(doc: dict, path: str, method: str, res, expected: int) -> dict:
    """The response is the expected problem, declared for the operation: its status (or, for
    statuses any route may answer, ``default``), the content type and the schema."""
    where = f"{method.upper()} {res.request.url}"
    assert res.status_code == expected, f"{where}: {res.status_code} {res.text[:500]}"
    responses = doc["paths"][path][method]["responses"]
    key = str(expected) if str(expected) in responses else "default"
    if expected in (401, 404, 422):  # what a route knows it answers, it lists
        assert key == str(expected), f"{where}: {expected} is not declared"
    media_type = res.headers["content-type"]
    declared = responses[key]["content"]
    assert list(declared) == [PROBLEM_JSON] and media_type == PROBLEM_JSON, (where, media_type)
    body = res.json()
    pointer = declared[PROBLEM_JSON]["schema"]["$ref"]
    schema_validator(pointer, doc).validate(body)
    assert body["status"] == expected and body["detail"], (where, body)
    return body


def test_every_operation_answers_its_errors_as_the_problems_it_declares(api):
    client, doc = api
    operations = [(p, m) for p, item in doc["paths"].items() for m in item]
    assert len(operations) > 40
    provoked: dict[tuple[str, str], list[int]] = {}
    for path, method in operations:
        op = doc["paths"][path][method]
        for url, kwargs, expected in _provocations(path, method, op):
            res = client.request(method.upper(), url, **kwargs)
            body = _check(doc, path, method, res, expected)
            provoked.setdefault((path, method), []).append(expected)
            if expected == 422:
                assert body["errors"] and all(e["field"] and e["message"]
                                              for e in body["errors"]), body
        # a method the path does not take: the router's 405, the operation's default response
        res = client.request(UNUSED_METHOD, _url(path, _path_values(op, NOBODY)), headers=AUTH)
        _check(doc, path, method, res, 405)
        assert res.headers["allow"], res.headers
        provoked.setdefault((path, method), []).append(405)
    assert set(provoked) == set(operations)
    # every operation met at least one error of its own besides the 405
    assert [o for o in operations if len(provoked[o]) < 2] == [
        ("/api/v1/health", "get"), ("/api/v1/devices", "get"),
        ("/api/v1/devices/turntable/position", "get"), ("/api/v1/devices/solar", "get"),
        ("/api/v1/calibration", "get")]
    # ...and those answer what they declare too: no calibration is active yet (404)
    _check(doc, "/api/v1/calibration", "get", client.get("/api/v1/calibration"), 404)


def test_every_error_response_of_the_document_is_a_problem_and_no_fastapi_shape_is_left(api):
    _, doc = api
    for path, item in doc["paths"].items():
        for method, op in item.items():
            errors = {k: v for k, v in op["responses"].items() if k == "default" or k[0] in "45"}
            assert "default" in errors, (path, method)
            for status, response in errors.items():
                schema = "ValidationProblem" if status == "422" else "Problem"
                assert response["content"] == {PROBLEM_JSON: {"schema": {
                    "$ref": f"#/components/schemas/{schema}"}}}, (path, method, status)
            has_input = "requestBody" in op or op.get("parameters")
            assert ("422" in op["responses"]) == bool(has_input), (path, method)
    text = json.dumps(doc)
    assert "HTTPValidationError" not in text and '"ValidationError"' not in text


def test_a_validation_problem_names_each_field_as_a_path(api):
    client, _ = api
    res = client.post("/api/v1/campaigns", headers=AUTH, json={
        "name": "bad", "poses": [{"turntable_deg": 0}, {"turntable_deg": 0},
                                 {"turntable_deg": 0}, {"turntable_deg": 500}]})
    body = problem(res, 422)
    assert body["type"] == "urn:toftwin:problem:invalid-input" and body["title"] == "Invalid input"
    assert [e["field"] for e in body["errors"]] == ["poses[3].turntable_deg"]
    assert body["detail"] == f"poses[3].turntable_deg: {body['errors'][0]['message']}"
    assert "360 deg" in body["errors"][0]["message"]
    # an InvalidInputError raised below the API (the inline scene's camera) is the same shape
    scene = {"name": "s", "camera": {"preset": "pico_flexx", "fx_px": -1.0}, "objects": []}
    body = problem(client.post("/api/v1/simulate", headers=AUTH, json={"scene": scene}), 422)
    assert body["errors"][0]["field"].startswith("scene.camera"), body
    # a body that is not JSON: the field is the body, the message says where it broke
    res = client.post("/api/v1/poses", headers={**AUTH, "Content-Type": "application/json"},
                      content=b'{"turntable_deg": ')
    body = problem(res, 422)
    assert body["errors"][0]["field"] == "body" and "not valid JSON" in body["detail"]


def test_token_unknown_route_and_method_errors_are_problems_with_their_headers(api):
    client, _ = api
    body = problem(client.post("/api/v1/devices/stop"), 401)
    assert body["type"] == "urn:toftwin:problem:unauthorized" and "Bearer" in body["detail"]
    assert client.post("/api/v1/devices/stop").headers["www-authenticate"] == "Bearer"
    body = problem(client.get("/api/v1/no-such-thing"), 404)
    assert body["type"] == "urn:toftwin:problem:not-found" and "/api/v1" in body["detail"]
    body = problem(client.get("/static/no-such-file.js"), 404)
    assert body["type"] == "urn:toftwin:problem:not-found"
    res = client.delete("/api/v1/health")
    body = problem(res, 405)
    assert body["type"] == "urn:toftwin:problem:method-not-allowed"
    assert res.headers["allow"] == "GET" and "GET" in body["detail"]
    body = problem(client.get(f"/api/v1/campaigns/{'0' * 32}"), 404)
    assert body == {"type": "urn:toftwin:problem:not-found", "title": "Not found",
                    "status": 404, "detail": f"no campaign {'0' * 32}"}


def test_an_unexpected_error_is_a_500_problem_without_its_traceback_or_server_paths(tmp_path):
    data = tmp_path / "data-dir-of-the-server"
    app = create_app(make_settings(data))
    with TestClient(app, raise_server_exceptions=False) as client:
        res = client.post("/api/v1/devices/camera/capture", headers=AUTH)
        assert res.status_code == 201, res.text
        frame_id = res.json()["frame_id"]
        # the frame's row is damaged (a damaged file is a 410 of its own: test_damaged_files):
        # reading it fails where nothing expects
        with app.state.lab.engine.begin() as conn:
            conn.exec_driver_sql("UPDATE frames SET rig_json = '{\"cut short' WHERE id = ?",
                                 (frame_id,))
        res = client.get(f"/api/v1/frames/{frame_id}")
    body = problem(res, 500)
    assert body["type"] == "urn:toftwin:problem:internal-error"
    assert "log" in body["detail"]
    for leak in ("Traceback", "JSONDecodeError", "Expecting", "frame.json", str(tmp_path),
                 "site-packages", ".py"):
        assert leak not in res.text, leak


def test_operation_ids_are_unique_camel_case_verbs_and_nouns(api):
    _, doc = api
    ids = [op["operationId"] for item in doc["paths"].values() for op in item.values()]
    assert len(ids) == len(set(ids)), sorted(i for i in ids if ids.count(i) > 1)
    bad = [i for i in ids if not re.fullmatch(r"[a-z]+(?:[A-Z][a-z0-9]+)+", i)]
    assert not bad, bad
    by_route = {(m, p): op["operationId"] for p, item in doc["paths"].items()
                for m, op in item.items()}
    assert by_route[("get", "/api/v1/health")] == "getHealth"
    assert by_route[("post", "/api/v1/poses")] == "createPose"
    assert by_route[("get", "/api/v1/campaigns")] == "listCampaigns"
    assert by_route[("post", "/api/v1/campaigns/{campaign_id}/start")] == "startCampaign"


def test_the_service_documentation_lists_every_problem_type():
    text = (REPO / "docs" / "service.md").read_text()
    for kind in PROBLEM_TYPES.values():
        assert f"`{kind.name}`" in text and str(kind.status) in text, kind.name


def test_every_service_error_class_names_a_problem_type_of_its_own():
    def with_subclasses(cls: type[ServiceError]) -> list[type[ServiceError]]:
        return [cls, *(c for sub in cls.__subclasses__() for c in with_subclasses(sub))]

    classes = with_subclasses(ServiceError)
    assert len(classes) >= 7
    assert all(cls.problem in PROBLEM_TYPES for cls in classes)
    assert len({cls.problem for cls in classes}) == len(classes)
