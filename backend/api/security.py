"""Security headers on every response, the API docs served offline, the Bearer scheme.

- :class:`SecurityHeaders` (pure ASGI, so it also covers the ingest fast path):
  a Content-Security-Policy that allows what the dashboard loads — its own
  scripts (``/static``, ``/vendor/plotly.min.js``), inline styles (Plotly and
  Swagger UI write ``style`` attributes), ``data:``/``blob:`` images (the
  favicon, Plotly's PNG export) and, as frame and fetch target, the viser 3D
  twin on its own port of the host the page was asked by (``frontend/js/twin.js``;
  no other host; the port :func:`viser_public_port`: the one the scene listens on, or
  ``HELIOTWIN_VISER_PUBLIC_PORT``) — and nothing from elsewhere;
  ``frame-ancestors 'none'`` with ``X-Frame-Options: DENY``,
  ``X-Content-Type-Options: nosniff``, ``Referrer-Policy: no-referrer``. A
  response that sets its own CSP (the docs pages) keeps it.
- :func:`add_docs` — ``/docs`` (Swagger UI 5) with its JavaScript, CSS and icon
  from the ``fastapi-offline`` wheel mounted at ``/docs-static`` (FastAPI's
  documented self-hosting of the docs assets), so it renders with no network;
  the page's one inline script is allowed by its SHA-256 in that page's CSP.
  (No ``/redoc``: ReDoc fetches its logo from a CDN.)
- :func:`declare_bearer` — ``components.securitySchemes.bearerAuth`` (HTTP
  Bearer) in the OpenAPI document, so Swagger UI's "Authorize" and "Try it
  out" send a token; operations say whether they need it with
  ``openapi_extra={"security": …}``.
"""

from __future__ import annotations

import base64
import functools
import hashlib
import re
from pathlib import Path
from typing import Any

import fastapi_offline
from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.twin.viser_http import request_hostname

DOCS_ASSETS = Path(fastapi_offline.__file__).parent / "static"
DOCS_STATIC_URL = "/docs-static"


def content_security_policy(viser_port: int, script_hashes: tuple[str, ...] = (),
                            host: str | None = None) -> str:
    """The CSP of the service's pages (``script_hashes``: ``sha256-…`` of inline scripts).

    The viser 3D twin may be framed and fetched only on ``host`` (the host name the page
    was asked by, which is where ``frontend/js/twin.js`` looks for it) at ``viser_port``;
    without a host, not at all.
    """
    scripts = " ".join(["'self'", *(f"'{h}'" for h in script_hashes)])
    frames = "'none'" if host is None else f"http://{host}:{viser_port} https://{host}:{viser_port}"
    viser = "" if host is None else f" http://{host}:{viser_port} https://{host}:{viser_port}"
    sockets = "" if host is None else f" ws://{host}:{viser_port} wss://{host}:{viser_port}"
    return "; ".join([
        "default-src 'self'",
        f"script-src {scripts}",
        "style-src 'self' 'unsafe-inline'",
        "img-src 'self' data: blob:",
        "font-src 'self' data:",
        f"connect-src 'self'{viser}{sockets}",
        f"frame-src {frames}",
        "worker-src 'self' blob:",
        "object-src 'none'",
        "base-uri 'self'",
        "form-action 'self'",
        "frame-ancestors 'none'",
    ])


def viser_listen_port(app: Any) -> int:
    """The port the app's 3D scene listens on: the configured one, or the next free port
    the scene moved to when that was busy."""
    scene = getattr(app.state, "scene", None)
    return int(scene.port) if scene is not None else int(app.state.settings.server.viser_port)


def viser_public_port(app: Any) -> int:
    """The port a browser reaches the app's 3D scene on, at the dashboard's host name:
    ``HELIOTWIN_VISER_PUBLIC_PORT`` (a container's published port, a reverse proxy),
    else :func:`viser_listen_port`. ``GET /api/v1/meta`` says it, ``frontend/js/twin.js``
    frames it and the CSP allows it."""
    public = app.state.settings.server.viser_public_port
    return int(public) if public is not None else viser_listen_port(app)


class SecurityHeaders:
    """ASGI middleware adding the security headers to every HTTP response (the CSP names
    the request's own host for the viser port: :func:`content_security_policy`; the port
    :func:`viser_public_port` of the app, else ``viser_port``)."""

    def __init__(self, app: ASGIApp, viser_port: int) -> None:
        self.app = app
        self.viser_port = viser_port
        self.headers = [
            (b"x-frame-options", b"DENY"),
            (b"x-content-type-options", b"nosniff"),
            (b"referrer-policy", b"no-referrer"),
        ]

    @functools.lru_cache(maxsize=64)  # noqa: B019 - one middleware per app, a few host names
    def _csp(self, host: str | None, viser_port: int) -> bytes:
        return content_security_policy(viser_port, host=host).encode()

    def _viser_port(self, scope: Scope) -> int:
        app = scope.get("app")
        if app is None or getattr(app.state, "settings", None) is None:
            return self.viser_port
        return viser_public_port(app)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        host_header = next((v.decode("latin-1") for k, v in scope["headers"] if k == b"host"),
                           None)
        ours = [(b"content-security-policy",
                 self._csp(request_hostname(host_header), self._viser_port(scope))),
                *self.headers]

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {k.lower() for k, _ in headers}
                headers.extend(h for h in ours if h[0] not in present)
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)


def _with_own_csp(page: HTMLResponse, viser_port: int) -> HTMLResponse:
    """The page with a CSP that allows exactly its inline scripts (by hash)."""
    body = bytes(page.body).decode()
    hashes = tuple(
        "sha256-" + base64.b64encode(hashlib.sha256(s.encode()).digest()).decode()
        for s in re.findall(r"<script>(.*?)</script>", body, flags=re.S))
    return HTMLResponse(body, headers={
        "Content-Security-Policy": content_security_policy(viser_port, hashes)})


def add_docs(app: FastAPI, viser_port: int) -> None:
    """``/docs`` from local assets (create the app with ``docs_url=None``)."""
    app.mount(DOCS_STATIC_URL, StaticFiles(directory=DOCS_ASSETS), name="docs-static")
    title = f"{app.title} — API"

    @app.get("/docs", include_in_schema=False)
    async def swagger_ui() -> HTMLResponse:
        return _with_own_csp(get_swagger_ui_html(
            openapi_url=app.openapi_url or "/openapi.json", title=title,
            swagger_js_url=f"{DOCS_STATIC_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{DOCS_STATIC_URL}/swagger-ui.css",
            swagger_favicon_url=f"{DOCS_STATIC_URL}/favicon.png",
            swagger_ui_parameters={"persistAuthorization": True, "validatorUrl": None},
        ), viser_port)


def declare_bearer(schema: dict[str, Any]) -> dict[str, Any]:
    """Add the ``bearerAuth`` scheme (a site write token, or the admin token) to ``schema``.

    An operation that declares its own ``security`` keeps it (``[{}, {"bearerAuth": []}]``:
    a token is optional); one that can answer 401 and declares none needs a token.
    """
    schemes = schema.setdefault("components", {}).setdefault("securitySchemes", {})
    schemes["bearerAuth"] = {
        "type": "http", "scheme": "bearer",
        "description": "A site write token (`heliotwin token create --site ID`), or "
                       "HELIOTWIN_ADMIN_TOKEN for /api/v1/tokens.",
    }
    for item in schema.get("paths", {}).values():
        for op in item.values():
            if isinstance(op, dict) and "401" in op.get("responses", {}):
                op.setdefault("security", [{"bearerAuth": []}])
    return schema
