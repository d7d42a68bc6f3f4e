"""Security headers (issue 25, item 7): every response of every route, HTML or not, error or
not, carries the Content-Security-Policy, ``nosniff``, no framing and no referrer.

The routes are walked from the app itself (every GET route, its path parameters filled with a
finished campaign, pose, frame and calibration job), so that a route added later is covered
without a test naming it; the HTML ones (``text/html``) are collected and must include every
page the service has. The policy allows scripts from the service only (no inline script, no
eval) and nothing from another host; the operator page and the API docs allow no inline style
either. A browser loads them under this policy in tests/web/test_security_headers.py.
"""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from service.api.app import create_app
from tests.service.api.conftest import AUTH, make_settings, problem
from tests.service.api.finished_lab import finished_lab, get_urls

pytestmark = pytest.mark.timeout(120)

#: every route that answers HTML (by route name): the operator page, its fragments, the
#: campaign report, the API docs and a calibration job's report.html
HTML_ROUTES = {"page", "pose_fragment", "campaigns_fragment", "explained_fragment",
               "calibration_fragment", "get_campaign_report", "api_docs",
               "get_calibration_job_file", "calibration_verdicts_fragment"}
#: where the token is typed: no inline style either
STRICT_STYLE = {"page", "api_docs"}
#: the sources a directive may name: this service, nothing, or inline images (``data:``)
SOURCES = {"'self'", "'none'", "data:", "'unsafe-inline'"}


def csp_directives(res) -> dict[str, list[str]]:
    """The response's Content-Security-Policy as {directive: [sources]}."""
    policy = res.headers.get("content-security-policy")
    assert policy, f"no Content-Security-Policy: {dict(res.headers)}"
    out = {}
    for part in policy.split(";"):
        name, *sources = part.split()
        out[name] = sources
    return out


def assert_security_headers(res, where: str) -> dict[str, list[str]]:
    """The headers every response must carry; returns its policy."""
    h = res.headers
    assert h.get("x-content-type-options") == "nosniff", (where, dict(h))
    assert h.get("x-frame-options") == "DENY", (where, dict(h))
    assert h.get("referrer-policy") == "no-referrer", (where, dict(h))
    csp = csp_directives(res)
    assert csp.get("frame-ancestors") == ["'none'"], (where, csp)
    assert csp.get("default-src") == ["'none'"], (where, csp)
    assert csp.get("script-src") == ["'self'"], (where, csp)  # no inline script, no eval
    assert csp.get("base-uri") == ["'none'"] and csp.get("object-src") == ["'none'"], csp
    for directive, sources in csp.items():
        assert set(sources) <= SOURCES, (where, directive, sources)  # no other host
        if directive != "style-src":
            assert "'unsafe-inline'" not in sources, (where, directive)
    return csp


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    with TestClient(create_app(make_settings(tmp_path_factory.mktemp("headers")))) as client:
        yield client, finished_lab(client)


def test_every_get_route_carries_the_headers_and_every_html_page_is_covered(lab):
    client, finished = lab
    urls = get_urls(client.app, finished)
    assert len(urls) >= 30, urls  # the walk found the app's routes
    html = set()
    for name, url in urls.items():
        res = client.get(url, follow_redirects=False)
        assert res.status_code in (200, 307), (name, url, res.status_code, res.text[:300])
        csp = assert_security_headers(res, f"{name} {url}")
        if res.headers.get("content-type", "").startswith("text/html"):
            html.add(name)
            if name in STRICT_STYLE:
                assert csp["style-src"] == ["'self'"], (name, csp)
    assert html == HTML_ROUTES, html ^ HTML_ROUTES


@pytest.mark.parametrize("path", ["/static/page.js", "/static/page.css", "/static/figures.css",
                                  "/static/swagger-ui/swagger-ui-bundle.js",
                                  "/api/v1/openapi.json"])
def test_static_files_carry_them(lab, path):
    client, _ = lab
    res = client.get(path)
    assert res.status_code == 200
    assert_security_headers(res, path)


def test_errors_carry_them(lab):
    client, finished = lab
    checks = [
        (client.get("/nothing-here"), 404),
        (client.delete("/api/v1/health"), 405),
        (client.post("/api/v1/devices/turntable/move", json={"angle_deg": 1}), 401),
        (client.post("/api/v1/devices/turntable/move", headers=AUTH,
                     json={"angle_deg": "x"}), 422),
        (client.post("/api/v1/simulate", headers={**AUTH, "Content-Type": "application/json"},
                     content=b"[" * (4 << 20)), 413),
        (client.get(f"/api/v1/calibrations/{finished.job_id}/files/nothing.png"), 404),
    ]
    for res, status in checks:
        problem(res, status)
        assert_security_headers(res, f"{res.request.method} {res.request.url} {status}")


def test_an_unexpected_error_carries_them(tmp_path):
    # The 500 is answered outside the app's middleware (Starlette's server-error handler):
    # a route of this test raises, as a bug would.
    app = create_app(make_settings(tmp_path))

    @app.get("/boom")
    def boom() -> None:
        raise RuntimeError("a bug")

    with TestClient(app, raise_server_exceptions=False) as client:
        res = client.get("/boom")
    problem(res, 500)
    assert_security_headers(res, "500")
