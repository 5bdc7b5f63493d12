"""The Pointing page in Chromium (issue 25, item 6): its empty state where the tracker has sent
no camera offsets, then a day of offsets from a misaligned mount posted over HTTP, and the
page's terms table, summary and charts as ``GET …/pointing-model`` answers them."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import httpx
import numpy as np
import pandas as pd
import pytest
from pvlib import atmosphere
from sqlalchemy import create_engine

from backend.auth import create_token
from sim.pointing_model import PointingModel, predict_offsets_mrad
from sim.sites import load_site
from sim.sun import solar_position
from tests.e2e.conftest import open_page

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"
DAY = dt.date(2021, 10, 5)  # long before the demo logger's back-filled days
TZ = dt.timezone(dt.timedelta(hours=-6))
MOUNT = PointingModel(azimuth_zero_deg=1.2, elevation_zero_deg=-0.6,
                      pedestal_tilt_north_deg=0.8, pedestal_tilt_east_deg=-0.5)


def _readings(site_id: str) -> list[dict]:
    """Every other minute of DAY with the sun above 5°: the open loop on SPA, the offsets of
    MOUNT with 0.3 mrad of noise and three glints 20-30 mrad off."""
    site = load_site(site_id)
    t0 = dt.datetime(DAY.year, DAY.month, DAY.day, tzinfo=TZ)
    times = pd.DatetimeIndex([t0 + dt.timedelta(minutes=m) for m in range(0, 1440, 2)])
    sun = solar_position(times, site.latitude, site.longitude, site.altitude,
                         float(atmosphere.alt2pres(site.altitude)), site.temp_air)
    az, el = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    up = el > 5.0
    times, az, el = times[up], az[up], el[up]
    ox, oy = predict_offsets_mrad(MOUNT, az, el, az, el)
    rng = np.random.default_rng(5)
    ox, oy = ox + rng.normal(0, 0.3, az.size), oy + rng.normal(0, 0.3, az.size)
    glints = rng.choice(az.size, 3, replace=False)
    ox[glints] += rng.uniform(20, 30, 3)
    return [{"ts": t.isoformat(), "array": "tracker", "power_w": 500.0,
             "azimuth_deg": float(a), "elevation_deg": float(e),
             "sun_offset_x_mrad": float(x), "sun_offset_y_mrad": float(y)}
            for t, a, e, x, y in zip(times, az, el, ox, oy, strict=True)]


def _token(server, site_id: str) -> str:  # type: ignore[no-untyped-def]
    """An ingest token stored in the server's database (as `heliotwin token create` would,
    without starting a CLI process); the service finds it on its first use."""
    engine = create_engine(server.env["HELIOTWIN_DATABASE_URL"])
    try:
        with engine.begin() as conn:
            return create_token(conn, site_id, "e2e pointing page")
    finally:
        engine.dispose()


@pytest.fixture()
def pointing_page(browser, server, request: pytest.FixtureRequest):  # type: ignore[no-untyped-def]
    """A page (no console error may occur: the empty state's fit answered 422, which
    Chromium logged as a failed load) that also records every answer of 400 or more in
    ``page.failed_responses``."""
    with open_page(browser, request) as pg:
        pg.failed_responses = []  # type: ignore[attr-defined]
        pg.on("response", lambda r: r.status >= 400 and pg.failed_responses.append(
            f"{r.status} {r.url}"))
        yield pg


@pytest.mark.parametrize("site", ["tehuantepec", "guadalajara_fisheye"])
def test_the_empty_state_makes_no_failing_request(pointing_page, server, site: str) -> None:  # type: ignore[no-untyped-def]
    """A tracker without camera offsets (the demo logger sends none) and a camera site
    without a tracker: the page says which, and no request fails (the page asked for the
    fit and showed its 422 as the empty state; a camera site was told to send offsets)."""
    page = pointing_page
    requests: list[str] = []
    page.on("request", lambda r: "/pointing-model" in r.url and requests.append(r.url))
    page.goto(f"{server.url}/#pointing?site={site}")
    empty = page.locator("[data-testid=pointing-empty]")
    empty.wait_for(state="visible")
    page.wait_for_load_state("networkidle")
    text = empty.inner_text()
    if site == "tehuantepec":
        assert "0 observations with sun offsets" in text and "at least 10" in text
        assert "sun_offset_x_mrad" in text and "/pointing-model/observations" in text
        assert [u.split("?")[0].rsplit("/", 1)[1] for u in requests] == ["coverage"]
    else:
        assert "has no tracker array" in text and "no mount to fit" in text
        assert "sun_offset_x_mrad" not in text  # nothing to send: there is no tracker
        assert requests == []
    assert page.locator("[data-testid=pointing-results]").is_hidden()
    assert page.locator("#pointing-status").inner_text() == ""
    page.locator("#page-pointing").screenshot(
        path=str(ARTIFACTS / f"pointing-empty-{site}.png"))
    assert page.failed_responses == []
    assert page.console_errors == []


def test_the_pointing_page_shows_the_fitted_mount(pointing_page, server) -> None:  # type: ignore[no-untyped-def]
    page = pointing_page
    site = server.site["site_id"]
    page.goto(f"{server.url}/#pointing?site={site}")
    empty = page.locator("[data-testid=pointing-empty]")
    empty.wait_for(state="visible")  # the demo logger sends no camera offsets
    assert "sun_offset_x_mrad" in empty.inner_text() and "/pointing-model/observations" in \
        empty.inner_text()

    readings = _readings(site)
    r = httpx.post(f"{server.url}/api/v1/sites/{site}/measurements", json={"readings": readings},
                   headers={"Authorization": f"Bearer {_token(server, site)}"}, timeout=60)
    assert r.status_code == 200 and r.json()["accepted"] == len(readings), r.text
    rng = {"start": DAY.isoformat(), "end": (DAY + dt.timedelta(days=1)).isoformat()}
    body = httpx.get(f"{server.url}/api/v1/sites/{site}/pointing-model", params=rng,
                     timeout=60).raise_for_status().json()
    assert body["n_outliers"] == 3

    page.fill("#pointing-start", rng["start"])
    page.fill("#pointing-end", rng["end"])
    page.click("#pointing-run")
    page.wait_for_function(f"() => document.body.dataset.pointing === "
                           f"'{site}/{rng['start']}/{rng['end']}'")
    assert empty.is_hidden()
    rows = page.locator("[data-testid=pointing-term]")
    assert rows.count() == len(body["terms"])
    for i in range(rows.count()):
        name = rows.nth(i).get_attribute("data-term")
        value = float(rows.nth(i).locator("td").nth(1).inner_text().replace("−", "-"))
        assert abs(value - body["terms"][name]["value"]) <= 5e-5, name
        assert abs(value - MOUNT.as_dict()[name]) < 0.01, name
    summary = page.locator("[data-testid=pointing-summary]").inner_text()
    assert summary.startswith(f"{len(readings)} camera observations, 3 rejected as outliers")
    n_in = len(readings) - 3
    points = {c: int(page.locator(f"[data-testid={c}]").get_attribute("data-points"))
              for c in ("chart-pointing-day", "chart-pointing-azimuth",
                        "chart-pointing-elevation")}
    assert points == {"chart-pointing-day": 2 * n_in + 3, "chart-pointing-azimuth": 4 * n_in + 3,
                      "chart-pointing-elevation": 4 * n_in + 3}
    ARTIFACTS.mkdir(exist_ok=True)
    page.locator("#page-pointing").screenshot(path=str(ARTIFACTS / "pointing.png"))
    assert page.console_errors == []
