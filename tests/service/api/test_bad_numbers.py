"""Numbers JSON cannot carry, and types lax validation would coerce, are 422s that change nothing.

Every request body of the OpenAPI document is walked: each numeric field (at any depth: a
campaign's ``poses[0].turntable_deg``, a mask's ``near_m``) gets ``NaN``, ``Infinity``,
``-Infinity`` and ``1e309`` in turn, written into the raw JSON text as a client that does not
check would send them, and each must be a 422 whose body is strict JSON naming the field; then
``true`` where a number belongs and a number where a switch belongs.
"""

from __future__ import annotations

import json
import math
from typing import Any

from tests.service.api.conftest import AUTH, problem

#: a valid body for every operation that takes one (a new operation must be added here)
BASE_BODIES: dict[tuple[str, str], dict[str, Any]] = {
    ("POST", "/api/v1/devices/turntable/move"): {"angle_deg": 10.0},
    ("POST", "/api/v1/devices/solar/lamp"): {"on": False},
    ("POST", "/api/v1/devices/solar/level"): {"suns": 1.0},
    ("POST", "/api/v1/devices/solar/shutter"): {"open": False},
    ("POST", "/api/v1/simulate"): {"turntable_deg": 0.0, "solar_suns": 1.0, "seed": 0, "spp": 1},
    ("POST", "/api/v1/poses"): {"turntable_deg": 0.0, "solar_suns": 1.0, "seed": 0, "spp": 1,
                                "mask": {"kind": "depth_window", "near_m": 0.1, "far_m": 5.0}},
    ("POST", "/api/v1/campaigns"): {
        "name": "n", "seed": 0, "spp": 1,
        "poses": [{"turntable_deg": 0.0, "solar_suns": 1.0, "repeats": 1}],
        "mask": {"kind": "region", "rows": [0, 10], "cols": [0, 10]},
    },
    ("PUT", "/api/v1/calibration"): {
        "camera": {"fx_px": 210.0, "cy_px": 85.0, "distortion": {"k1": -0.1},
                   "depth": {"phase_offset_rad": [0.01],
                             "wiggling": [{"harmonic": 4, "amplitude_rad": 0.01}]},
                   "sensor": {"adc_gain_e_per_dn": 9.0}},
        "illumination": {"power_w": 1.2},
        "turntable": {"axis_point_m": [0.0, 0.0, 0.0], "zero_offset_deg": 0.5},
        "solar_simulator": {"irradiance_scale": 1.0},
    },
    ("POST", "/api/v1/calibrations"): {
        "fixtures": ["tilt+30@200mm", "tilt-30@200mm"], "frames_per_view": 1, "noise_frames": 2,
        "sweep": {"from_deg": -30.0, "to_deg": 30.0, "step_deg": 15.0},
        "solar_levels_suns": [1.0], "solar_frames": 1, "solar_reference_suns": 1.0,
        "activate": False,
    },
}
BAD_NUMBERS = ("NaN", "Infinity", "-Infinity", "1e309")
SENTINEL = "__BAD_NUMBER__"


def _resolve(schema: dict, doc: dict) -> dict:
    while "$ref" in schema:
        schema = doc["components"]["schemas"][schema["$ref"].rsplit("/", 1)[-1]]
    return schema


def _kinds(schema: dict, doc: dict) -> set[str]:
    schema = _resolve(schema, doc)
    kinds = {schema["type"]} if "type" in schema else set()
    for key in ("anyOf", "oneOf", "allOf"):
        for sub in schema.get(key, []):
            kinds |= _kinds(sub, doc)
    return kinds


def _object_schema(schema: dict, doc: dict) -> dict | None:
    schema = _resolve(schema, doc)
    if "properties" in schema:
        return schema
    for sub in schema.get("anyOf", []):
        found = _object_schema(sub, doc)
        if found is not None:
            return found
    return None


def _fields(value: Any, schema: dict, doc: dict, path: tuple = ()) -> list[tuple[tuple, set]]:
    """(path, JSON types) of every scalar the body holds, with what its schema allows."""
    if isinstance(value, dict):
        obj = _object_schema(schema, doc) or {"properties": {}}
        return [f for k, v in value.items()
                for f in _fields(v, obj["properties"].get(k, {}), doc, (*path, k))]
    if isinstance(value, list):
        s = _resolve(schema, doc)
        items = s.get("items") or next((a.get("items") for a in s.get("anyOf", [])
                                        if "items" in a), None)
        prefix = s.get("prefixItems") or next((a.get("prefixItems") for a in s.get("anyOf", [])
                                               if "prefixItems" in a), None)
        return [f for i, v in enumerate(value)
                for f in _fields(v, (prefix[i] if prefix else items) or {}, doc, (*path, i))]
    return [(path, _kinds(schema, doc))]


def _with(body: Any, path: tuple, value: Any) -> Any:
    body = json.loads(json.dumps(body))
    target = body
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return body


def _cases(doc: dict) -> list[tuple[str, str, tuple, str]]:
    cases = []
    for path, item in doc["paths"].items():
        for method, op in item.items():
            if "requestBody" not in op:
                continue
            key = (method.upper(), path)
            assert key in BASE_BODIES, f"{key} takes a body: add a valid one to BASE_BODIES"
            body = BASE_BODIES[key]
            schema = op["requestBody"]["content"]["application/json"]["schema"]
            for field, kinds in _fields(body, schema, doc):
                if kinds & {"number", "integer"}:
                    cases += [(method.upper(), path, field, text) for text in BAD_NUMBERS]
                    cases.append((method.upper(), path, field, "true"))
                if "boolean" in kinds:
                    cases.append((method.upper(), path, field, "1"))
    return cases


def _not_json(constant: str) -> None:
    raise AssertionError(f"the 422 body holds {constant}, which is not JSON")


def _field_name(path: tuple) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else ("." if out else "") + str(part)
    return out


def test_every_numeric_field_of_every_body_refuses_what_json_cannot_carry(client):
    doc = client.get("/api/v1/openapi.json").json()
    angle_before = client.get("/api/v1/devices/turntable/position").json()["angle_deg"]
    cases = _cases(doc)
    assert len(cases) > 40, "the walk found too few fields"
    for method, path, field, text in cases:
        raw = json.dumps(_with(BASE_BODIES[(method, path)], field, SENTINEL))
        raw = raw.replace(json.dumps(SENTINEL), text)
        res = client.request(method, path, headers={**AUTH, "Content-Type": "application/json"},
                             content=raw)
        where = f"{method} {path} {_field_name(field)} = {text}"
        assert res.status_code == 422, f"{where}: {res.status_code} {res.text[:300]}"
        json.loads(res.text, parse_constant=_not_json)
        body = problem(res, 422)
        assert _field_name(field) in body["detail"], f"{where}: {body['detail']}"
    # nothing moved: the stage is where it was
    assert math.isclose(client.get("/api/v1/devices/turntable/position").json()["angle_deg"],
                        angle_before, abs_tol=1e-9)
    assert client.get("/api/v1/campaigns").json() == []
    assert client.get("/api/v1/calibrations").json() == []
    assert client.get("/api/v1/calibration").status_code == 404


def test_a_lone_surrogate_is_a_422_not_a_failure_to_encode_it(client):
    res = client.post("/api/v1/campaigns", headers={**AUTH, "Content-Type": "application/json"},
                      content=b'{"name": "\\ud800", "poses": [{"turntable_deg": "\\udfff"}]}')
    assert "poses[0].turntable_deg" in problem(res, 422)["detail"]


def test_every_numeric_query_and_path_parameter_refuses_what_is_not_a_number(client):
    doc = client.get("/api/v1/openapi.json").json()
    cid = client.post("/api/v1/campaigns", headers=AUTH,
                      json={"name": "q", "poses": [{"turntable_deg": 0.0}]}).json()["id"]
    checked = 0
    for path, item in doc["paths"].items():
        for method, op in item.items():
            params = op.get("parameters", [])
            numeric = [p for p in params if _kinds(p["schema"], doc) & {"number", "integer"}]
            for param in numeric:
                for text in (*BAD_NUMBERS, "true"):
                    url = path.replace("{campaign_id}", cid).replace("{frame_id}", "0" * 32)
                    query = {}
                    if param["in"] == "path":
                        url = url.replace("{" + param["name"] + "}", text)
                    else:
                        query[param["name"]] = text
                    res = client.request(method.upper(), url, params=query, headers=AUTH)
                    where = f"{method.upper()} {path} {param['name']} = {text}"
                    assert res.status_code == 422, f"{where}: {res.status_code} {res.text[:200]}"
                    json.loads(res.text, parse_constant=_not_json)
                    checked += 1
    assert checked >= 25, checked
