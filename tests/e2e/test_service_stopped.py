"""The overview when the service stops under an open page (a tester's finding).

A ``heliotwin serve --no-demo`` of this module's own with a day of readings posted over
HTTP; the page shows that day, the service is stopped, and the operator steps to the day
before and back. The page said "No readings for … — pick another day", the loggers
"never" with 0 readings, the day's card "No energy recorded" and the banner "Failed to
fetch": a stopped service read as loggers that never reported. It must say that the
service did not answer, and claim nothing about the readings.
"""

from __future__ import annotations

import datetime as dt
import math
import sys
from pathlib import Path
from zoneinfo import ZoneInfo

import httpx
import pytest

from tests.e2e.conftest import open_page

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backend"))
from live_service import ServerProcess, new_database  # noqa: E402

TZ = ZoneInfo("America/Mexico_City")
DAY = dt.datetime.now(TZ).date() - dt.timedelta(days=2)


def _readings(array: str, scale: float) -> list[dict]:
    t0 = dt.datetime(DAY.year, DAY.month, DAY.day, tzinfo=TZ)
    out = []
    for m in range(1440):
        p = scale * 600 * max(0.0, math.sin(math.pi * (m / 60 - 6.5) / 11.5))
        out.append({"ts": (t0 + dt.timedelta(minutes=m)).isoformat(), "array": array,
                    "voltage_v": 24.0, "current_a": p / 24.0, "power_w": p})
    return out


def test_a_stopped_service_is_not_read_as_a_day_without_readings(
        browser, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    proc = ServerProcess(new_database("sqlite", tmp_path).url, tmp_path / "server.log")
    proc.start()
    try:
        token = proc.token("tehuantepec")
        for array, scale in (("tracker", 1.3), ("fixed", 1.0)):
            r = httpx.post(f"{proc.base_url}/api/v1/sites/tehuantepec/measurements",
                           json={"readings": _readings(array, scale)},
                           headers={"Authorization": f"Bearer {token}"}, timeout=120)
            assert r.status_code == 200, r.text
        # the browser logs each refused request as a console error: expected here
        with open_page(browser, request, timeout_ms=30_000,
                       ignore=lambda text: "ERR_CONNECTION_REFUSED" in text) as pg:
            pg.goto(f"{proc.base_url}/#overview?site=tehuantepec&day={DAY.isoformat()}")
            pg.wait_for_selector(f'body[data-overview-loaded="tehuantepec/{DAY.isoformat()}"]')
            assert pg.inner_text("[data-testid=readings-tracker]") == "1,440"
            assert pg.inner_text("#live-stamp").startswith("updated ")
            proc.stop()
            pg.click("#day-prev")
            pg.wait_for_function("() => !document.getElementById('banner').hidden")
            pg.click("#day-next")
            pg.wait_for_function("() => /could not be loaded/"
                                 ".test(document.getElementById('chart-power').innerText)")
            power = pg.inner_text("#chart-power")
            assert "No readings" not in power
            assert "did not answer" in power and "stopped or restarting" in power
            assert "did not answer" in pg.inner_text("#banner")
            assert "Failed to fetch" not in pg.inner_text("#banner")
            loggers = pg.inner_text("#loggers")
            assert "never" not in loggers and "no readings" not in loggers
            assert "unknown" in loggers
            assert pg.inner_text("#live-stamp").startswith("update failed ")
            day = pg.inner_text("#day-energy")
            assert "No energy recorded" not in day and "could not be loaded" in day
    finally:
        proc.stop()
