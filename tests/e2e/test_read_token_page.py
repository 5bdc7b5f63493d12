"""The dashboard of a service that requires a token to read (HELIOTWIN_READ_REQUIRE_TOKEN).

A ``heliotwin serve --no-demo`` of this module's own with the setting on: the page first
shows the header's token field with the server's 401 message and reads nothing else;
after a token is entered the Overview loads; a token the service refuses shows the field
again with its message.
"""

from __future__ import annotations

import datetime as dt
import sys
from collections.abc import Iterator
from pathlib import Path
from zoneinfo import ZoneInfo

import pytest

from tests.e2e.conftest import ARTIFACTS, open_page

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backend"))
from live_service import ServerProcess, new_database  # noqa: E402

SITE = "tehuantepec"
TODAY = dt.datetime.now(ZoneInfo("America/Mexico_City")).date()


@pytest.fixture(scope="module")
def closed_server(browser, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    tmp = tmp_path_factory.mktemp("read-token")
    proc = ServerProcess(new_database("sqlite", tmp).url, tmp / "server.log", extra_env={
        "HELIOTWIN_READ_REQUIRE_TOKEN": "true", "HELIOTWIN_ADMIN_TOKEN": "admin-read-e2e"})
    proc.start()
    try:
        yield proc
    finally:
        proc.stop()


@pytest.fixture()
def pg(browser, closed_server: ServerProcess, request: pytest.FixtureRequest) -> Iterator[object]:
    # the refused reads are 401s the browser logs as failed resources
    with open_page(browser, request, timeout_ms=60_000,
                   ignore=lambda text: "401" in text) as page:
        yield page


def test_the_page_asks_for_a_token_then_loads(pg, closed_server: ServerProcess) -> None:
    ARTIFACTS.mkdir(exist_ok=True)
    pg.goto(f"{closed_server.base_url}/#overview?site={SITE}&day={TODAY.isoformat()}")
    pg.wait_for_selector("#read-token-form", state="visible")
    message = pg.inner_text("#read-token-msg")
    assert "HELIOTWIN_READ_REQUIRE_TOKEN" in message
    assert pg.locator("#site-select option").count() == 0  # nothing read without a token
    assert pg.get_attribute("body", "data-overview-loaded") is None
    pg.screenshot(path=str(ARTIFACTS / "e2e-read-token-asked.png"))

    pg.fill("#read-token", closed_server.token(SITE))  # a logger's ingest token reads too
    pg.click("#read-token-use")
    pg.wait_for_selector(f'body[data-overview-loaded="{SITE}/{TODAY.isoformat()}"]')
    assert pg.locator("#read-token-form").is_hidden()
    assert pg.locator("#read-token-forget").is_visible()
    assert pg.input_value("#site-select") == SITE
    assert pg.evaluate("sessionStorage.getItem('heliotwin.token')")  # this tab's only
    assert pg.locator("#banner").is_hidden(), pg.inner_text("#banner")
    pg.screenshot(path=str(ARTIFACTS / "e2e-read-token-loaded.png"))


def test_a_refused_token_shows_the_field_again(pg, closed_server: ServerProcess) -> None:
    pg.goto(f"{closed_server.base_url}/")
    pg.evaluate("sessionStorage.setItem('heliotwin.token', 'not-a-token')")
    pg.reload()
    pg.wait_for_selector("#read-token-form", state="visible")
    assert "unknown write token" in pg.inner_text("#read-token-msg")
    # said to be the token given, with what to paste instead (a bare "unknown write token")
    assert "The token you gave was refused" in pg.inner_text("#read-token-msg")
    assert "heliotwin token create --site ID" in pg.inner_text("#read-token-msg")
    pg.click("#read-token-forget")
    pg.wait_for_selector("#read-token-form", state="visible")
    assert pg.evaluate("sessionStorage.getItem('heliotwin.token')") is None
    assert "HELIOTWIN_READ_REQUIRE_TOKEN" in pg.inner_text("#read-token-msg")
