"""The Overview's alerts card in Chromium (issue 13, item 7), against a ``heliotwin serve`` of
this module's own: yesterday's logger readings posted over HTTP, a stuck-tracker diagnosis of
yesterday put in the diagnosis cache (as the service stores it), alerts evaluated every
0.3 s with a 3 s silence threshold and a webhook receiver on a local port. The card must
list what ``GET /api/v1/alerts`` answers — the silent loggers, the fault, the low PR, the
cleared one under its fold — and follow a change of site; an operator acknowledges the fault
with the card's form (refused first with a logger's token) and, after a reload, sees it
shown as acknowledged, by whom and with the note.
"""

from __future__ import annotations

import datetime as dt
import http.server
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from zoneinfo import ZoneInfo

import httpx
import orjson
import pytest

from tests.e2e.conftest import open_page

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backend"))
from live_service import InProcessServer, ServerProcess, free_port, new_database  # noqa: E402

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
TZ = ZoneInfo("America/Mexico_City")
SITE = "tehuantepec"
ADMIN = "admin-token-of-the-alerts-page"
YESTERDAY = dt.datetime.now(TZ).date() - dt.timedelta(days=1)


class _Hook(http.server.BaseHTTPRequestHandler):
    received: list[dict] = []

    def do_POST(self) -> None:  # noqa: N802 - http.server's name
        body = self.rfile.read(int(self.headers.get("Content-Length", "0")))
        _Hook.received.append(orjson.loads(body))
        self.send_response(204)
        self.end_headers()

    def log_message(self, *args: object) -> None:
        pass


def _reading(ts: float, array: str) -> dict:
    return {"ts": dt.datetime.fromtimestamp(int(ts), dt.UTC).isoformat(), "array": array,
            "voltage_v": 26.0, "current_a": 5.0}


def _stuck_day(day: dt.date) -> dict:
    """A diagnosis payload of a stuck tracker (the features of backend/diagnosis/faults.py)."""
    return {"date": day.isoformat(),
            "sky": {"clearness_index": 0.74, "source": "fixed_array", "valid_minutes_pct": 98.0},
            "tracker": {"measured_wh": 3650.0, "expected_wh": 5400.0, "expected_wh_low": 5150.0,
                        "expected_wh_high": 5600.0, "performance_ratio": 0.676},
            "fixed": {"measured_wh": 4300.0, "expected_wh": 4300.0, "performance_ratio": 1.0},
            "gain_measured_pct": -15.1, "gain_expected_pct": 25.6,
            "features": {"missing_daylight_min": 0, "residual": 0.31,
                         "stuck": {"residual": 0.04, "tilt_deg": 55.0, "azimuth_deg": 181.0},
                         "azimuth_offset": {"residual": 0.27, "offset_deg": 12.0},
                         "clock_offset": {"residual": 0.29, "offset_s": 0.0, "scale": 1.0}}}


def _inject(db_url: str, day: dt.date, payload: dict) -> None:
    from sqlalchemy import insert

    from backend.diagnosis.service import CACHE_VERSION, site_key
    from backend.settings import get_settings
    from backend.storage.engine import make_engine
    from backend.storage.tables import DiagnosisDay
    from sim.sites import load_site

    nxt = day + dt.timedelta(days=1)
    start = dt.datetime(day.year, day.month, day.day, tzinfo=TZ)
    end = dt.datetime(nxt.year, nxt.month, nxt.day, tzinfo=TZ)
    engine = make_engine(get_settings(database_url=db_url))
    try:
        with engine.begin() as conn:
            conn.execute(insert(DiagnosisDay).values(
                site_id=SITE, day_start_s=int(start.timestamp()), day_end_s=int(end.timestamp()),
                payload_json=orjson.dumps({**payload, "cache_version": CACHE_VERSION,
                                           "site_key": site_key(load_site(SITE))}).decode()))
    finally:
        engine.dispose()


@pytest.fixture(scope="module")
def alert_server(browser, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    tmp = tmp_path_factory.mktemp("alerts-page")
    hook = http.server.ThreadingHTTPServer(("127.0.0.1", free_port()), _Hook)
    threading.Thread(target=hook.serve_forever, daemon=True).start()
    db = new_database("sqlite", tmp)
    # yesterday's readings, stored by the service (in this process: only the served one
    # below is the browser's)
    with InProcessServer(db.url, extra_env={"HELIOTWIN_ALERTS": "false"}) as first, \
            first.client() as c:
        token = first.token(SITE)
        noon = dt.datetime(YESTERDAY.year, YESTERDAY.month, YESTERDAY.day, 12, tzinfo=TZ)
        rows = [_reading(noon.timestamp() + 60 * k, a) for k in range(30)
                for a in ("tracker", "fixed")]
        r = c.post(f"/api/v1/sites/{SITE}/measurements", json={"readings": rows},
                   headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 200, r.text
    _inject(db.url, YESTERDAY, _stuck_day(YESTERDAY))
    proc = ServerProcess(db.url, tmp / "server.log", extra_env={
        "HELIOTWIN_ALERT_INTERVAL_S": "0.3", "HELIOTWIN_ALERT_SILENT_MIN": "0.05",
        "HELIOTWIN_ALERT_SILENT_DAYLIGHT_ONLY": "false",  # the test runs at any hour
        "HELIOTWIN_ADMIN_TOKEN": ADMIN,  # to make the operator's site-scope token
        "HELIOTWIN_ALERT_WEBHOOK_URL": f"http://127.0.0.1:{hook.server_address[1]}/hook"})
    proc.start()
    proc.write_token = token  # type: ignore[attr-defined]
    try:
        deadline = time.monotonic() + 30
        while len(_Hook.received) < 4:  # two silent loggers, the fault, the low PR
            assert time.monotonic() < deadline, _Hook.received
            time.sleep(0.1)
        # the fixed logger reports again (stamped ahead, so it stays fresh): one cleared
        r = httpx.post(f"{proc.base_url}/api/v1/sites/{SITE}/measurements",
                       json={"readings": [_reading(time.time() + 300, "fixed")]},
                       headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 200, r.text
        while len(_Hook.received) < 5:
            assert time.monotonic() < deadline + 30, _Hook.received
            time.sleep(0.1)
        time.sleep(0.5)  # the webhook outcomes are stored
        yield proc
    finally:
        proc.stop()
        hook.shutdown()
        hook.server_close()


@pytest.fixture()
def pg(browser, alert_server: ServerProcess, request: pytest.FixtureRequest) -> Iterator[object]:
    """A fresh page on the module's server (``conftest.open_page``)."""
    with open_page(browser, request, timeout_ms=30_000) as page:
        yield page


def test_the_alerts_card_lists_what_the_api_answers(pg, alert_server: ServerProcess) -> None:
    api = httpx.get(f"{alert_server.base_url}/api/v1/alerts", params={"site_id": SITE},
                    timeout=30).json()
    active = [a for a in api["alerts"] if a["state"] == "active"]
    cleared = [a for a in api["alerts"] if a["state"] == "cleared"]
    assert {(a["kind"], a["array"], a["fault_kind"]) for a in active} == {
        ("logger_silent", "tracker", None), ("fault", "tracker", "stuck"),
        ("low_performance_ratio", "tracker", None)}
    assert [(a["kind"], a["array"]) for a in cleared] == [("logger_silent", "fixed")]
    assert all(a["webhook_status"] == "delivered" for a in api["alerts"])

    pg.goto(f"{alert_server.base_url}/#overview?site={SITE}&day={YESTERDAY.isoformat()}")
    pg.wait_for_selector(f'body[data-alerts-loaded="{SITE}"]')
    card = pg.locator("[data-testid=alerts-card]")
    assert pg.locator("#alerts-title").inner_text() == "Alerts — 3 unacknowledged"
    shown = card.locator("[data-testid=alerts-active] [data-testid=alert]")
    assert shown.count() == 3
    text = card.locator("[data-testid=alerts-active]").inner_text()
    for a in active:
        assert a["detail"] in text
    assert "Fault: tracker stuck" in text and "Logger silent" in text
    assert "Low performance ratio" in text and "68 %" in text
    assert "webhook: delivered" in text
    rules = pg.locator("#alerts-rules").inner_text()
    assert "logger silent 0 min" not in rules and "webhook http://127.0.0.1:" in rules
    assert "/hook" not in rules  # only the scheme and host of the URL are shown
    # the cleared one waits under its fold
    assert pg.locator("#alerts-cleared-summary").inner_text() == "Recently cleared (1 of 1)"
    pg.click("#alerts-cleared-summary")
    folded = card.locator("[data-testid=alerts-cleared] [data-testid=alert]")
    assert folded.count() == 1 and folded.get_attribute("data-state") == "cleared"
    assert "the fixed logger reports again" in folded.inner_text()
    ARTIFACTS.mkdir(exist_ok=True)
    card.screenshot(path=str(ARTIFACTS / "e2e-alerts-card.png"))
    pg.screenshot(path=str(ARTIFACTS / "e2e-alerts-overview.png"))

    # another site has none; back on this one the list follows what happened meanwhile
    pg.select_option("#site-select", "guadalajara_fisheye")
    pg.wait_for_selector('body[data-alerts-loaded="guadalajara_fisheye"]')
    assert card.locator("[data-testid=alerts-none]").inner_text() == "No active alerts."
    assert pg.locator("#alerts-title").inner_text() == "Alerts"
    r = httpx.post(f"{alert_server.base_url}/api/v1/sites/{SITE}/measurements",
                   json={"readings": [_reading(time.time() + 300, "tracker")]},
                   headers={"Authorization": f"Bearer {alert_server.write_token}"})
    assert r.status_code == 200, r.text
    deadline = time.monotonic() + 20
    while httpx.get(f"{alert_server.base_url}/api/v1/alerts",
                    params={"site_id": SITE, "state": "active"}).json()["counts"]["active"] != 2:
        assert time.monotonic() < deadline
        time.sleep(0.1)
    pg.select_option("#site-select", SITE)
    pg.wait_for_function("() => document.getElementById('alerts-title').textContent"
                         " === 'Alerts — 2 unacknowledged'")
    assert pg.locator("#alerts-cleared-summary").inner_text() == "Recently cleared (2 of 2)"


def test_an_operator_acknowledges_an_alert(browser, alert_server: ServerProcess,
                                           request: pytest.FixtureRequest) -> None:
    base = alert_server.base_url
    r = httpx.post(f"{base}/api/v1/tokens", headers={"Authorization": f"Bearer {ADMIN}"},
                   json={"site_id": SITE, "scope": "site", "label": "Ana (night shift)"})
    assert r.status_code == 201, r.text
    operator = r.json()["token"]
    before = httpx.get(f"{base}/api/v1/alerts", params={"site_id": SITE}).json()["counts"]
    assert before["active_unacknowledged"] >= 2, before  # the fault and the low PR at least
    # the logger's token is refused (403): the browser logs the failed request
    with open_page(browser, request, timeout_ms=30_000,
                   ignore=lambda text: "status of 403" in text) as pg:
        pg.goto(f"{base}/#overview?site={SITE}&day={YESTERDAY.isoformat()}")
        pg.wait_for_selector(f'body[data-alerts-loaded="{SITE}"]')
        assert pg.locator("#alerts-title").inner_text() == \
            f"Alerts — {before['active_unacknowledged']} unacknowledged"
        fault = pg.locator("[data-testid=alerts-active] [data-testid=alert][data-kind=fault]")
        assert fault.get_attribute("data-acknowledged") == "false"
        fault.locator("[data-testid=alert-ack]").click()
        ack_form = pg.locator("[data-testid=alerts-ack]")
        assert ack_form.is_visible()
        assert "Acknowledge “Fault: tracker stuck” on the tracker" in ack_form.inner_text()
        pg.fill("#alerts-ack-note", "sent Luis to the azimuth drive")
        pg.fill("#alerts-ack-token", alert_server.write_token)  # type: ignore[attr-defined]
        pg.click("#alerts-ack-send")
        status = pg.locator("[data-testid=alerts-ack-status]")
        pg.wait_for_function("() => document.querySelector('[data-testid=alerts-ack-status]')"
                             ".textContent.startsWith('Not acknowledged')")
        assert "scope 'ingest'" in status.inner_text() and ack_form.is_visible()
        ARTIFACTS.mkdir(exist_ok=True)
        pg.locator("[data-testid=alerts-card]").screenshot(
            path=str(ARTIFACTS / "e2e-alerts-ack-form.png"))
        pg.fill("#alerts-ack-token", operator)
        pg.click("#alerts-ack-send")
        pg.wait_for_selector("[data-testid=alerts-active] [data-kind=fault]"
                             "[data-acknowledged=true]")
        assert status.inner_text() == "“Fault: tracker stuck” acknowledged by Ana (night shift)."
        assert not ack_form.is_visible()

    stored = httpx.get(f"{base}/api/v1/alerts", params={
        "site_id": SITE, "state": "active", "acknowledged": "true"}).json()["alerts"]
    assert [(a["kind"], a["acknowledged_by"], a["acknowledged_note"]) for a in stored] == [
        ("fault", "Ana (night shift)", "sent Luis to the azimuth drive")]
    with open_page(browser, request, timeout_ms=30_000) as pg:  # a colleague opens it later
        pg.goto(f"{base}/#overview?site={SITE}&day={YESTERDAY.isoformat()}")
        pg.wait_for_selector(f'body[data-alerts-loaded="{SITE}"]')
        left = before["active_unacknowledged"] - 1
        assert pg.locator("#alerts-title").inner_text() == \
            f"Alerts — {left} unacknowledged · 1 acknowledged"
        items = pg.locator("[data-testid=alerts-active] [data-testid=alert]")
        flags = [items.nth(i).get_attribute("data-acknowledged") for i in range(items.count())]
        assert flags == ["false"] * left + ["true"]  # the ones nobody has taken first
        fault = items.nth(left)
        assert fault.get_attribute("data-kind") == "fault"
        by = fault.locator("[data-testid=alert-ack-by]").inner_text()
        assert by.startswith("Acknowledged by Ana (night shift), ")
        assert by.endswith(": sent Luis to the azimuth drive")
        assert fault.locator("[data-testid=alert-ack]").count() == 0
        assert items.nth(0).locator("[data-testid=alert-ack]").count() == 1
        # calmer: no red edge on it, and the card keeps its red edge for the others
        edge = fault.evaluate("e => getComputedStyle(e).borderLeftColor")
        assert edge == "rgb(173, 181, 189)", edge
        assert "has-active" in (pg.locator("#alerts-card").get_attribute("class") or "")
        ARTIFACTS.mkdir(exist_ok=True)
        pg.locator("[data-testid=alerts-card]").screenshot(
            path=str(ARTIFACTS / "e2e-alerts-acknowledged.png"))
        # at phone width the card, its buttons and the open form fit (docs/dashboard.md)
        pg.set_viewport_size({"width": 390, "height": 900})
        items.nth(0).locator("[data-testid=alert-ack]").click()
        assert pg.locator("[data-testid=alerts-ack]").is_visible()
        assert pg.evaluate("document.documentElement.scrollWidth") <= 390
        pg.locator("[data-testid=alerts-card]").screenshot(
            path=str(ARTIFACTS / "e2e-alerts-ack-phone.png"))
        pg.click("#alerts-ack-cancel")
        assert not pg.locator("[data-testid=alerts-ack]").is_visible()
