"""The viser server's HTTP surface: same-origin WebSockets and security headers (issue 23,
item 10).

viser (1.1) serves its page and its WebSocket with ``websockets.asyncio.server.serve``
and offers no hook for either, so :func:`install` wraps that call inside viser's
``_infra`` module (nowhere else) before a ``ViserServer`` starts:

- a WebSocket handshake whose ``Origin`` names another host or port than its ``Host``
  is refused (403): a page elsewhere cannot drive the 3D twin through a visitor's
  browser (browsers always send ``Origin``; a client without one, not a browser, passes);
- every HTTP answer gets ``X-Content-Type-Options: nosniff``, ``Referrer-Policy:
  no-referrer`` and a CSP ``frame-ancestors`` that lets only pages of the same host
  frame it (the dashboard, on its own port) — not any site.
"""

from __future__ import annotations

import http
import inspect
import re
import threading
from collections.abc import Callable
from typing import Any
from urllib.parse import urlsplit

_HOSTNAME = re.compile(r"^(?:[A-Za-z0-9-]{1,63}(?:\.[A-Za-z0-9-]{1,63})*|\[[0-9A-Fa-f:.]{2,45}\])$")
_installed = threading.Lock()
_done = False


def request_hostname(host_header: str | None) -> str | None:
    """The host name of a ``Host`` header (``example.org:8000`` → ``example.org``), or None
    when it is absent or not a plain host name / IP literal (nothing else goes in a CSP)."""
    if not host_header:
        return None
    host = host_header.strip()
    if host.startswith("["):  # [IPv6]:port
        host = host[:host.find("]") + 1] if "]" in host else ""
    elif host.count(":") == 1:
        host = host.rsplit(":", 1)[0]
    return host if _HOSTNAME.match(host) else None


def origin_refusal(origin: str | None, host_header: str | None) -> str | None:
    """Why a WebSocket handshake is refused (``Origin`` not the ``Host`` it was sent to),
    or None to accept it."""
    if origin is None:
        return None
    netloc = urlsplit(origin.strip()).netloc.lower()
    if host_header and netloc == host_header.strip().lower():
        return None
    return f"cross-origin WebSocket refused: Origin {origin[:80]!r} is not this server"


def page_headers(host_header: str | None) -> dict[str, str]:
    """The security headers of the viser page and its files."""
    host = request_hostname(host_header)
    ancestors = "'self'" if host is None else f"'self' http://{host}:* https://{host}:*"
    return {"Content-Security-Policy": f"frame-ancestors {ancestors}",
            "X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer"}


class _With:
    """An object that answers ``overrides`` first, then ``target``'s attributes."""

    def __init__(self, target: Any, **overrides: Any) -> None:
        self._target, self._overrides = target, overrides

    def __getattr__(self, name: str) -> Any:
        if name in self._overrides:
            return self._overrides[name]
        return getattr(self._target, name)


def guarded_serve(serve: Callable[..., Any]) -> Callable[..., Any]:
    """``websockets.asyncio.server.serve`` with the Origin check and the page headers."""

    def wrapped(*args: Any, process_request: Any = None, **kwargs: Any) -> Any:
        async def check(connection: Any, request: Any) -> Any:
            if request.headers.get("Upgrade", "").lower() == "websocket":
                why = origin_refusal(request.headers.get("Origin"), request.headers.get("Host"))
                if why is not None:
                    return connection.respond(http.HTTPStatus.FORBIDDEN, why + "\n")
            if process_request is None:
                return None
            answer = process_request(connection, request)
            return await answer if inspect.isawaitable(answer) else answer

        def headers(connection: Any, request: Any, response: Any) -> Any:
            for name, value in page_headers(request.headers.get("Host")).items():
                if name not in response.headers:
                    response.headers[name] = value
            return response

        return serve(*args, process_request=check, process_response=headers, **kwargs)

    return wrapped


def install() -> None:
    """Guard every viser server started from now on in this process (idempotent)."""
    global _done
    with _installed:
        if _done:
            return
        from viser.infra import _infra

        ws = _infra.websockets
        server = _With(ws.asyncio.server, serve=guarded_serve(ws.asyncio.server.serve))
        _infra.websockets = _With(ws, asyncio=_With(ws.asyncio, server=server))  # type: ignore[assignment]
        _done = True
