"""The API's documentation and the operator page work without internet: nothing they load
comes from another host, and the docs render in a browser whose network is off.

The static check reads each page's HTML, every script and stylesheet it loads, and the files
those name: our own scripts and styles (the operator page's, the docs' init file) and every
stylesheet (Swagger UI's included) must name no other host. Swagger UI's own script is not read
for URLs: it holds namespace and specification URIs (``http://www.w3.org/2000/svg``, RFC links)
that are identifiers, never fetched; the browser test below records every request the docs make
with the network off instead.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from html.parser import HTMLParser
from urllib.parse import urljoin, urlsplit

import pytest

from service.api.routes.api_docs import SWAGGER_UI_URL
from tests.web.conftest import DOC_SIZE, Page

pytestmark = pytest.mark.timeout(120)
#: an absolute URL, or a protocol-relative one in a string or ``url(...)``
_URL = re.compile(r"""\bhttps?://[^\s"'`)<>]+|(?<=["'(`])//[\w.-]+""")
_CSS_URL = re.compile(r"""url\(\s*["']?([^"')]+)|@import\s+["']([^"']+)""")


class _Refs(HTMLParser):
    """What an HTML page refers to: every URL-valued attribute, its scripts and stylesheets,
    inline scripts and inline event handlers."""

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[str] = []
        self.scripts: list[str] = []
        self.stylesheets: list[str] = []
        self.inline_scripts: list[str] = []
        self.handlers: list[str] = []
        self._in_inline_script = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = {k: v or "" for k, v in attrs}
        for name, value in a.items():
            if name in ("src", "href", "action", "formaction", "poster", "data", "srcset"):
                self.urls.append(value)
            if name.startswith("on"):
                self.handlers.append(f"<{tag} {name}>")
            if name == "style":
                self.urls += [u or i for u, i in _CSS_URL.findall(value)]
        if tag == "script":
            if a.get("src"):
                self.scripts.append(a["src"])
            else:
                self._in_inline_script = True
        if tag == "link" and "stylesheet" in a.get("rel", "").split():
            self.stylesheets.append(a["href"])

    def handle_endtag(self, tag: str) -> None:
        if tag == "script":
            self._in_inline_script = False

    def handle_data(self, data: str) -> None:
        if self._in_inline_script and data.strip():
            self.inline_scripts.append(data.strip()[:80])


def _other_hosts(urls: list[str], base: str) -> list[str]:
    """The URLs (relative to ``base``) that point at another host."""
    host = urlsplit(base).netloc
    out = []
    for url in urls:
        parts = urlsplit(urljoin(base, url.strip()))
        if parts.scheme in ("data", "blob", "about"):
            continue
        if parts.scheme not in ("http", "https") or parts.netloc != host:
            out.append(url)
    return out


def _read(server, url: str):
    res = server.api.get(url)
    assert res.status_code == 200, (url, res.status_code, res.text[:300])
    return res


def _page_loads(server, path: str) -> dict[str, list[str]]:
    """What the page at ``path`` refers to, and what its scripts and stylesheets do."""
    base = server.url + path
    html = _read(server, path).text
    refs = _Refs()
    refs.feed(html)
    found = {"page": refs.urls, "inline scripts": refs.inline_scripts,
             "inline handlers": refs.handlers, "from files": []}
    for url in refs.scripts + refs.stylesheets:
        absolute = urljoin(base, url)
        assert urlsplit(absolute).netloc == urlsplit(server.url).netloc, url
        text = _read(server, absolute).text
        if url in refs.stylesheets:
            found["from files"] += [u or i for u, i in _CSS_URL.findall(text)]
        if not url.startswith(SWAGGER_UI_URL):  # our own files: any URL in them at all
            found["from files"] += _URL.findall(text)
    return found


@pytest.mark.parametrize("path", ["/", "/api/v1/docs"])
def test_the_pages_and_what_they_load_name_no_other_host(server, path):
    found = _page_loads(server, path)
    base = server.url + path
    assert found["page"], "the walk found nothing on the page"
    assert _other_hosts(found["page"], base) == []
    assert _other_hosts(found["from files"], base) == []
    assert not any("//cdn" in u for u in found["page"] + found["from files"])
    if path == "/api/v1/docs":  # ready for a Content-Security-Policy of script-src 'self'
        assert found["inline scripts"] == [] and found["inline handlers"] == []


def test_the_docs_load_swagger_ui_from_the_package_and_the_document_is_local(server):
    refs = _Refs()
    refs.feed(_read(server, "/api/v1/docs").text)
    assert f"{SWAGGER_UI_URL}/swagger-ui-bundle.js" in refs.scripts
    assert "/static/api-docs.js" in refs.scripts
    assert f"{SWAGGER_UI_URL}/swagger-ui.css" in refs.stylesheets
    init = _read(server, "/static/api-docs.js").text
    assert "validatorUrl: null" in init  # no badge fetched from a public validator
    # the document Swagger UI reads: no server elsewhere, no $ref outside itself
    doc = _read(server, "/api/v1/openapi.json").json()
    assert "servers" not in doc
    refs_out = re.findall(r'"\$ref":\s*"([^"]+)"', _read(server, "/api/v1/openapi.json").text)
    assert refs_out and all(r.startswith("#/") for r in refs_out)
    # /docs, where people look first, leads there
    res = server.api.get("/docs", follow_redirects=False)
    assert res.status_code in (301, 302, 307, 308) and res.headers["location"] == "/api/v1/docs"


@pytest.fixture(scope="module")
def offline_page(server) -> Iterator[Page]:
    """A headless Chromium with the network off (tests/web/conftest.py's ``OFFLINE``)."""
    page = Page(server, DOC_SIZE, offline=True)
    yield page
    page.close()


def test_the_api_docs_render_in_a_browser_with_the_network_off(server, offline_page):
    page = offline_page
    page.requested_urls()
    page.driver.get(f"{server.url}/docs")
    health = page.wait(lambda: page.find("#operations-service-getHealth"),
                       "Swagger UI to show the health operation", timeout_s=30.0)
    assert "/api/v1/health" in health.text and "getHealth" in health.text
    assert page.find("#operations-campaigns-createCampaign") is not None
    assert urlsplit(page.driver.current_url).path == "/api/v1/docs"
    page.shot("api-docs-offline")
    urls = page.requested_urls()
    assert any(u.endswith("/swagger-ui-bundle.js") for u in urls), urls
    assert any(u.endswith("/api/v1/openapi.json") for u in urls), urls
    assert _other_hosts(urls, server.url) == []
    page.assert_no_console_errors()


def test_the_operator_page_works_with_the_network_off_and_the_network_is_off(
    server, offline_page
):
    page = offline_page
    page.requested_urls()
    page.load("rig")
    urls = page.requested_urls()
    assert any(u.endswith("/static/page.js") for u in urls), urls
    assert _other_hosts(urls, server.url) == []
    page.assert_no_console_errors()
    # the network is off indeed: a request to another host does not get through (asked from
    # a blank page: the operator page's Content-Security-Policy refuses it before it leaves)
    page.driver.get("about:blank")
    probe = page.driver.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "fetch('https://example.com/', {mode: 'no-cors'})"
        ".then(() => done('reached'), (e) => done('blocked: ' + e));")
    assert probe.startswith("blocked"), probe
    assert [u for u in page.requested_urls() if "example.com" in u]  # it was asked for
    page.take_console()  # the probe's own failure
