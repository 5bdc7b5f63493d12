"""``/docs`` with no network, and the security headers the dashboard works under.

Every request the browser makes outside 127.0.0.1/localhost is aborted (and
recorded): Swagger UI must still render the whole API from the service's own
assets, declare the Bearer scheme and send the token from "Authorize" with
"Try it out". The dashboard's overview (Plotly) and the viser iframe work under
the CSP; the ``page`` fixture fails on any console error, a CSP violation included.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


def _offline(page) -> list[str]:  # type: ignore[no-untyped-def]
    """Abort every request that leaves this machine; the list of what was aborted."""
    aborted: list[str] = []

    def handle(route) -> None:  # type: ignore[no-untyped-def]
        host = urlsplit(route.request.url).hostname
        if route.request.url.startswith(("data:", "blob:")) or host in ("127.0.0.1",
                                                                       "localhost"):
            route.continue_()
        else:
            aborted.append(route.request.url)
            route.abort()

    page.route("**/*", handle)
    return aborted


def test_docs_render_offline_and_send_the_token(page, server, heliotwin_cli) -> None:
    aborted = _offline(page)
    page.goto(server.url + "/docs")
    page.wait_for_selector(".swagger-ui .info .title", timeout=30_000)
    assert "heliotwin" in page.inner_text(".swagger-ui .info .title")
    page.wait_for_selector(".opblock")
    assert page.locator(".opblock").count() >= 20  # every operation, not an error box
    assert page.locator(".swagger-ui .errors-wrapper").count() == 0
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "docs-offline.png"))

    made = heliotwin_cli("token", "create", "--site", "tehuantepec", env=server.env)
    assert made.returncode == 0, made.stderr
    token = made.stdout.split()[-1]
    page.click("button.authorize")
    page.fill(".auth-container input", token)
    page.click(".auth-btn-wrapper button.authorize")
    page.click("button.btn-done")

    # "Try it out" on POST /api/v1/simulations with its example body (one day)
    op = page.locator("#operations-simulations-create_simulation_api_v1_simulations_post")
    op.locator(".opblock-summary").click()
    op.locator("button.try-out__btn").click()
    with page.expect_request(lambda r: urlsplit(r.url).path == "/api/v1/simulations") as req:
        op.locator("button.execute").click()
    assert req.value.headers.get("authorization") == f"Bearer {token}"
    op.locator(".live-responses-table .response-col_status").first.wait_for(timeout=60_000)
    status = op.locator(".live-responses-table tbody .response-col_status").first.inner_text()
    assert status.strip() == "200", op.locator(".live-responses-table").inner_text()
    assert "tracker_energy_wh" in op.locator(".live-responses-table").inner_text()

    page.screenshot(path=str(ARTIFACTS / "docs-try-it-out.png"))
    assert aborted == [], f"/docs asked the network for {aborted}"


def test_security_headers_and_the_dashboard_under_them(page, server) -> None:
    for path in ("/", "/healthz", "/api/v1/sites", "/docs", "/nope"):
        r = httpx.get(server.url + path, timeout=30)
        csp = r.headers.get("content-security-policy", "")
        assert "frame-ancestors 'none'" in csp and "object-src 'none'" in csp, path
        assert "script-src 'self'" in csp and "unsafe-eval" not in csp, path
        assert r.headers.get("x-frame-options") == "DENY", path
        assert r.headers.get("x-content-type-options") == "nosniff", path
        assert r.headers.get("referrer-policy") == "no-referrer", path
    r = httpx.post(server.url + "/api/v1/sites/tehuantepec/measurements", json={}, timeout=30)
    assert r.status_code == 401 and r.headers.get("x-frame-options") == "DENY"  # fast path

    aborted = _offline(page)
    page.goto(server.url + "/#overview")
    page.wait_for_selector("body[data-overview-loaded]")
    page.wait_for_selector("#chart-power .main-svg")  # Plotly drew under the CSP
    page.goto(server.url + "/#twin")
    frame = page.wait_for_selector("#twin-frame[src]").content_frame()
    frame.wait_for_selector("canvas", timeout=30_000)  # the viser iframe is allowed
    assert aborted == []
