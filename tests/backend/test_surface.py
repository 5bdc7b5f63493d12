"""The service's web surface (issue 23, item 10): the CSP lets the dashboard frame and
reach viser on its own host only, and viser refuses a WebSocket from another origin
and sends security headers with its page.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator

import httpx
import pytest
import viser
from live_service import LiveServer
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from backend.twin import viser_http


def _directive(csp: str, name: str) -> str:
    return next(d for d in csp.split("; ") if d.startswith(name + " "))


def test_the_csp_names_the_request_host_for_viser(client: httpx.Client,
                                                  live_server: LiveServer) -> None:
    port = live_server.process.settings.server.viser_port
    csp = client.get("/healthz", headers={"Host": "dash.example:8000"}).headers[
        "content-security-policy"]
    assert _directive(csp, "frame-src") == (
        f"frame-src http://dash.example:{port} https://dash.example:{port}")
    assert _directive(csp, "connect-src") == (
        f"connect-src 'self' http://dash.example:{port} https://dash.example:{port} "
        f"ws://dash.example:{port} wss://dash.example:{port}")
    assert "*" not in csp.replace("'self'", "")
    odd = client.get("/healthz", headers={"Host": "x;script-src *"}).headers[
        "content-security-policy"]  # a Host that is no host name: no viser source at all
    assert _directive(odd, "frame-src") == "frame-src 'none'"
    assert _directive(odd, "script-src") == "script-src 'self'"


@pytest.fixture(scope="module")
def viser_port() -> Iterator[int]:
    viser_http.install()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    try:
        yield server.get_port()
    finally:
        server.stop()


def test_viser_refuses_a_websocket_from_another_origin(viser_port: int) -> None:
    url = f"ws://127.0.0.1:{viser_port}"
    with pytest.raises(InvalidStatus) as err:
        connect(url, origin="http://evil.example", open_timeout=10).close()  # type: ignore[arg-type]
    assert err.value.response.status_code == 403
    connect(url, origin=f"http://127.0.0.1:{viser_port}", open_timeout=10).close()  # type: ignore[arg-type]
    connect(url, open_timeout=10).close()  # no Origin: not a browser


def test_the_viser_page_sends_security_headers(viser_port: int) -> None:
    r = httpx.get(f"http://127.0.0.1:{viser_port}/", timeout=10)
    assert r.status_code == 200
    assert r.headers["content-security-policy"] == (
        "frame-ancestors 'self' http://127.0.0.1:* https://127.0.0.1:*")
    assert r.headers["x-content-type-options"] == "nosniff"
    assert r.headers["referrer-policy"] == "no-referrer"
