"""The security headers of every response: the one place of the service's browser policy.

Every response (HTML pages, their fragments, the reports, JSON, files, problems, event
streams) carries :func:`security_headers`:

- ``Content-Security-Policy`` (:data:`CSP`): scripts only from this service's own files (no
  inline script, no ``eval``), every fetch, image, font and style from this service only (no
  inline style), nothing framed, no ``<base>``, no plugin, forms submit only here. On a JSON
  or image response it costs nothing and covers a document opened on its own (an SVG plot is
  a document that could hold a script).
- ``X-Content-Type-Options: nosniff``: a browser takes each response as its declared type.
- ``frame-ancestors 'none'`` and, for browsers without it, ``X-Frame-Options: DENY``: no page
  frames ours (no click-jacking of the emergency stop or the token field).
- ``Referrer-Policy: no-referrer``: a link followed from a page names no address of the lab.

Self-contained documents (the campaign report, a calibration job's files, an SVG plot; a route
says so with the dependency :func:`self_contained_document`) get :data:`DOCUMENT_CSP`, which
also allows inline styles: each is one file that works on its own when saved (its own
``<style>``, inline matplotlib SVG plots whose every shape has a ``style`` attribute). A style
cannot run script, and with images, fonts and fetches limited to ``'self'`` an injected style
cannot send anything to another host. The operator page and the API docs (where the token is
typed) take no inline style at all.

Swagger UI (the API docs) needs no ``'unsafe-eval'``: its bundle's ``Function("return this")``
calls are fallbacks for engines without ``globalThis``, never reached in a browser
(tests/web/test_security_headers.py uses the docs and finds no CSP violation).

:class:`SecurityHeaders` is the ASGI middleware that adds them; the 500 problem (answered
outside the app's middleware, :mod:`service.api.problems`) adds them itself.
"""

from __future__ import annotations

from fastapi import Request
from starlette.datastructures import MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

#: the Content-Security-Policy of every response, directive by directive
CSP_DIRECTIVES: dict[str, str] = {
    "default-src": "'none'",
    "script-src": "'self'",
    "style-src": "'self'",
    "img-src": "'self' data:",  # data: Swagger UI's icons, the pages' empty favicon
    "font-src": "'self'",
    "connect-src": "'self'",  # the API, its event streams
    "form-action": "'self'",
    "base-uri": "'none'",
    "object-src": "'none'",
    "frame-ancestors": "'none'",
}
#: the policy of a self-contained document: the same, inline styles allowed
DOCUMENT_CSP_DIRECTIVES: dict[str, str] = CSP_DIRECTIVES | {"style-src": "'self' 'unsafe-inline'"}


def _policy(directives: dict[str, str]) -> str:
    return "; ".join(f"{name} {value}" for name, value in directives.items())


CSP = _policy(CSP_DIRECTIVES)
DOCUMENT_CSP = _policy(DOCUMENT_CSP_DIRECTIVES)
_STATE_KEY = "content_security_policy"


def self_contained_document(request: Request) -> None:
    """Dependency of a route whose answer is a self-contained document (its own styles
    inline): its response gets :data:`DOCUMENT_CSP`."""
    setattr(request.state, _STATE_KEY, DOCUMENT_CSP)


def security_headers(csp: str = CSP) -> dict[str, str]:
    """The headers every response carries (a fresh dict); ``csp`` the policy."""
    return {
        "Content-Security-Policy": csp,
        "X-Content-Type-Options": "nosniff",
        "X-Frame-Options": "DENY",
        "Referrer-Policy": "no-referrer",
    }


class SecurityHeaders:
    """ASGI middleware: every HTTP response gets :func:`security_headers` (replacing any of
    the same name, so that no route can weaken them by accident): :data:`CSP`, or
    :data:`DOCUMENT_CSP` where the route depends on :func:`self_contained_document`."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                csp = scope.get("state", {}).get(_STATE_KEY, CSP)
                for name, value in security_headers(csp).items():
                    headers[name] = value
            await send(message)

        await self.app(scope, receive, send_with_headers)
