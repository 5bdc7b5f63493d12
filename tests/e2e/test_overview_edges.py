"""Overview edge cases, the range report and the Sites form in Chromium (issue 14, items 3, 8, 9).

A ``heliotwin serve --no-demo`` of this module's own (temporary SQLite file, temporary
``HELIOTWIN_SITES_DIR``, an admin token), so the readings are exactly those posted here
over HTTP: a full day and a half-day (06:00–12:00) of a sine-power day, stamped 17 s
past the minute. What the page shows is compared with the HTTP API's answers and with
pvlib called directly.
"""

from __future__ import annotations

import datetime as dt
import math
import re
import sys
from collections.abc import Iterator
from pathlib import Path
from zoneinfo import ZoneInfo

import httpx
import pytest

from tests.e2e.conftest import ARTIFACTS, open_page

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backend"))
from live_service import ServerProcess, new_database  # noqa: E402

ADMIN = "admin-token-e2e"
TZ = ZoneInfo("America/Mexico_City")
TODAY = dt.datetime.now(TZ).date()
HALF = TODAY - dt.timedelta(days=4)
FULL = HALF - dt.timedelta(days=1)
EMPTY = HALF + dt.timedelta(days=1)  # no readings at all
UNALIKE = FULL - dt.timedelta(days=2)  # the tracker all day, the fixed array 12:00–18:00
FIXED_ONLY = UNALIKE - dt.timedelta(days=1)  # the fixed array's logger alone, all day
OLD = TODAY - dt.timedelta(days=700)  # before the on-demand twin window


def _sine(day: dt.date, array: str, scale: float, steps: range,
          step_s: int = 60) -> list[dict]:
    t0 = dt.datetime(day.year, day.month, day.day, tzinfo=TZ)
    out = []
    for k in steps:
        m = k * step_s / 60
        p = scale * 600 * max(0.0, math.sin(math.pi * (m / 60 - 6.5) / 11.5)) ** 1.2
        out.append({"ts": (t0 + dt.timedelta(minutes=m, seconds=17)).isoformat(),
                    "array": array, "voltage_v": 24.0, "current_a": p / 24.0, "power_w": p})
    return out


@pytest.fixture(scope="module")
def edge_server(browser, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    tmp = tmp_path_factory.mktemp("overview-edges")
    proc = ServerProcess(new_database("sqlite", tmp).url, tmp / "server.log", extra_env={
        "HELIOTWIN_SITES_DIR": str(tmp / "user-sites"), "HELIOTWIN_ADMIN_TOKEN": ADMIN})
    proc.start()
    try:
        token = proc.token("tehuantepec")
        with httpx.Client(base_url=proc.base_url, timeout=120) as c:
            # the tracker's logger of the full day reads every 20 s (4,320 readings)
            for array, scale, step_s in (("tracker", 1.3, 20), ("fixed", 1.0, 60)):
                rows = _sine(FULL, array, scale, range(86400 // step_s), step_s) + _sine(
                    HALF, array, scale, range(360, 720)) + _sine(
                    UNALIKE, array, scale, range(1440) if array == "tracker" else range(720, 1080)
                ) + (_sine(FIXED_ONLY, array, scale, range(1440)) if array == "fixed" else [])
                r = c.post("/api/v1/sites/tehuantepec/measurements", json={"readings": rows},
                           headers={"Authorization": f"Bearer {token}"})
                assert r.status_code == 200, r.text
        yield proc
    finally:
        proc.stop()


@pytest.fixture()
def pg(browser, edge_server: ServerProcess, request: pytest.FixtureRequest) -> Iterator[object]:
    """A fresh page on the module's server (``conftest.open_page``)."""
    with open_page(browser, request, timeout_ms=30_000,
                   ignore=lambda text: "422" in text) as page:  # the malformed-site test's 422
        yield page


def _open(page, server: ServerProcess, site: str, day: dt.date) -> None:
    page.goto(f"{server.base_url}/#overview?site={site}&day={day.isoformat()}")
    page.wait_for_selector(f'body[data-overview-loaded="{site}/{day.isoformat()}"]')


def _api(server: ServerProcess, path: str, **params: str) -> dict:
    return httpx.get(server.base_url + path, params=params, timeout=120).json()


def test_an_edited_address_is_followed(pg, edge_server: ServerProcess) -> None:
    _open(pg, edge_server, "tehuantepec", FULL)
    pg.evaluate(f"location.hash = '#overview?site=tehuantepec&day={HALF.isoformat()}'")
    pg.wait_for_selector(f'body[data-overview-loaded="tehuantepec/{HALF.isoformat()}"]')
    assert pg.input_value("#day-input") == HALF.isoformat()
    assert f"day={HALF.isoformat()}" in pg.evaluate("location.hash")
    pg.evaluate("location.hash = '#overview?site=guadalajara_fisheye&day=" + FULL.isoformat() + "'")
    pg.wait_for_selector(f'body[data-overview-loaded="guadalajara_fisheye/{FULL.isoformat()}"]')
    assert pg.input_value("#site-select") == "guadalajara_fisheye"


def test_a_camera_site_shows_the_sun(pg, edge_server: ServerProcess) -> None:
    import pandas as pd
    import pvlib

    _open(pg, edge_server, "guadalajara_fisheye", TODAY)
    tile = pg.locator("[data-testid=tile]", has_text="Sun now")
    shown = float(tile.locator(".value").inner_text().rstrip("°").replace(",", ""))
    now = pd.DatetimeIndex([pd.Timestamp.now(tz="UTC").floor("min")])
    ref = pvlib.solarposition.get_solarposition(now, 20.8667, -103.05, altitude=1560.0,
                                                temperature=20.0)
    # the tile is of the minute the status was read; the sun moves < 0.25° a minute
    assert shown == pytest.approx(float(ref["apparent_elevation"].iloc[0]), abs=0.5)


def test_the_four_weeks_keep_their_length(pg, edge_server: ServerProcess) -> None:
    _open(pg, edge_server, "tehuantepec", HALF)
    dates = pg.evaluate("() => document.getElementById('chart-daily').data[0].x")
    assert len(dates) == 28 and dates[-1] == HALF.isoformat()  # not cut at the first reading


def test_a_half_day_is_flagged_and_compared_over_the_same_minutes(
        pg, edge_server: ServerProcess) -> None:
    _open(pg, edge_server, "tehuantepec", HALF)
    row = _api(edge_server, "/api/v1/sites/tehuantepec/energy", start=HALF.isoformat(),
               end=EMPTY.isoformat())["rows"][0]
    assert row["partial"] is True
    note = pg.locator("[data-testid=partial-day]").inner_text()
    cov, arr = min((row["arrays"][a]["coverage_pct"], a) for a in ("tracker", "fixed"))
    assert f"the {arr}'s readings cover {round(cov)} %" in note
    twin = pg.locator("[data-testid=gain-day-twin]").inner_text()
    assert f"{row['twin_matched_gain_pct']:+.1f} % over the same minutes" in twin
    assert pg.locator("[data-testid=gain-day]").inner_text() == f"{row['gain_pct']:+.1f} %"
    _open(pg, edge_server, "tehuantepec", FULL)
    assert pg.locator("[data-testid=partial-day]").count() == 0
    # a day only the fixed array's logger reported (its readings cover 100 % of its twin)
    # named the readings' cover 100 %: the tracker, which covers nothing, names the day
    _open(pg, edge_server, "tehuantepec", FIXED_ONLY)
    assert pg.locator("[data-testid=partial-day]").inner_text() == (
        "Partial day: the tracker has no readings, so the readings are compared with the "
        "twin over the same minutes.")


def test_loggers_over_different_minutes_show_no_gain_and_say_why(
        pg, edge_server: ServerProcess) -> None:
    """The tracker's logger all day, the fixed array's from noon: no measured gain (their
    energies over different minutes would read a gain of the tracker's morning), and the page
    says why."""
    _open(pg, edge_server, "tehuantepec", UNALIKE)
    row = _api(edge_server, "/api/v1/sites/tehuantepec/energy", start=UNALIKE.isoformat(),
               end=(UNALIKE + dt.timedelta(days=1)).isoformat())["rows"][0]
    assert row["gain_pct"] is None
    # no big red "—" under the note: the note says why there is none
    assert pg.locator("[data-testid=gain-day]").count() == 0
    note = pg.locator("[data-testid=gain-unalike]").inner_text()
    assert note == f"No measured gain: {row['gain_note']}." and "different minutes" in note
    _open(pg, edge_server, "tehuantepec", FULL)
    assert pg.locator("[data-testid=gain-unalike]").count() == 0


def test_a_logger_faster_than_a_minute_shows_its_readings_not_the_charts_points(
        pg, edge_server: ServerProcess) -> None:
    """The loggers table counts the day's readings: a 20-s logger's 4,320, which the chart
    draws as minute buckets (the page read 1,440, the bucket count, for it)."""
    _open(pg, edge_server, "tehuantepec", FULL)
    end = (FULL + dt.timedelta(days=1)).isoformat()
    for array, readings, points in (("tracker", 4320, 1440), ("fixed", 1440, 1440)):
        answer = _api(edge_server, "/api/v1/sites/tehuantepec/measurements", array=array,
                      start=FULL.isoformat(), end=end, max_points="1440")  # as the page asks
        assert (answer["count"], len(answer["points"])) == (readings, points)
        assert pg.locator(f"[data-testid=readings-{array}]").inner_text() == f"{readings:,}"


def test_a_day_without_readings_does_not_say_no_gaps(pg, edge_server: ServerProcess) -> None:
    _open(pg, edge_server, "tehuantepec", EMPTY)
    for array in ("tracker", "fixed"):
        assert pg.locator(f"[data-testid=gaps-{array}]").inner_text() == "no readings"


def test_a_site_without_readings_says_so(pg, edge_server: ServerProcess) -> None:
    """A tester's site without readings: the daily chart drew an empty 0–1 % gain axis, the
    day a large red "—" under "No measured gain", and the pointing card said the tracker's
    logger sends no encoder angles when it had sent nothing at all."""
    import json

    from sim.paths import default_sites_dir

    config = json.loads((default_sites_dir() / "tehuantepec.json").read_text())
    config.update(site_id="quiet", name="Quiet site")
    r = httpx.put(f"{edge_server.base_url}/api/v1/sites/quiet", json=config, timeout=120,
                  headers={"Authorization": f"Bearer {ADMIN}"})
    assert r.status_code in (200, 201), r.text
    _open(pg, edge_server, "quiet", HALF)
    assert "No measured gain" in pg.locator("[data-testid=gain-unalike]").inner_text()
    assert pg.locator("[data-testid=gain-day]").count() == 0
    assert pg.locator("[data-testid=gain-day-twin]").inner_text().startswith("the twin expects")
    daily = pg.evaluate("() => { const c = document.getElementById('chart-daily');"
                        " return [c.layout.yaxis2 === undefined, c.data.map((t) => t.name),"
                        " (c.layout.annotations || []).map((a) => a.text)]; }")
    no_axis, names, notes = daily
    assert no_axis and "gain" not in names, daily
    assert notes == ["no measured gain in these four weeks: no day with readings of both "
                     "arrays"]
    pg.locator("[data-testid=pointing-note]").scroll_into_view_if_needed()
    pg.wait_for_function("() => document.querySelector('[data-testid=pointing-note]')"
                         ".textContent.startsWith('No readings')", timeout=120_000)
    assert pg.locator("[data-testid=pointing-note]").inner_text() == (
        "No readings from the tracker's logger in this range: no encoder angles to compare "
        "with the sun.")
    pg.locator("#page-overview").screenshot(path=str(ARTIFACTS / "overview-no-readings.png"))


def test_a_day_before_the_twin_window_says_why(pg, edge_server: ServerProcess) -> None:
    _open(pg, edge_server, "tehuantepec", OLD)
    note = pg.locator("[data-testid=twin-note]").inner_text()
    assert "older than the on-demand twin window" in note


def test_the_range_report_shows_totals_months_and_downloads(pg, edge_server: ServerProcess) -> None:
    _open(pg, edge_server, "tehuantepec", HALF)
    pg.select_option("#report-kind", "custom")
    pg.fill("#report-start", FULL.isoformat())
    pg.fill("#report-end", EMPTY.isoformat())
    pg.click("#report-run")
    pg.wait_for_selector(
        f'body[data-report-loaded="tehuantepec/{FULL.isoformat()}/{EMPTY.isoformat()}"]')
    rep = _api(edge_server, "/api/v1/sites/tehuantepec/report", start=FULL.isoformat(),
               end=EMPTY.isoformat())
    for a in ("tracker", "fixed"):
        shown = pg.locator(f"[data-testid=report-pr-{a}]").inner_text()
        assert shown == f"{rep['totals']['arrays'][a]['performance_ratio']:.2f}"
    assert f"{rep['totals']['gain_pct']:+.1f} % measured" in pg.locator(
        "[data-testid=report-gain]").inner_text()
    months = pg.locator("[data-testid=report-months] tr").count() - 1
    assert months == len(rep["months"]) >= 1
    assert pg.locator("[data-testid=report-years] tr").count() - 1 == len(rep["years"])
    png = pg.request.get(edge_server.base_url + pg.get_attribute("#report-png", "href"))
    assert png.status == 200 and png.headers["content-type"] == "image/png"
    with pg.expect_download() as dl:
        pg.click("#report-csv")
    header = Path(dl.value.path()).read_text().splitlines()[0]
    assert header.startswith("period,period_start,period_end,tracker_measured_wh")
    # a preset range follows the start: a week is Monday to Monday
    pg.select_option("#report-kind", "week")
    start = dt.date.fromisoformat(pg.input_value("#report-start"))
    assert start.weekday() == 0
    assert dt.date.fromisoformat(pg.input_value("#report-end")) == start + dt.timedelta(days=7)


def _report(page, start: dt.date, end: dt.date) -> None:
    page.select_option("#report-kind", "custom")
    page.fill("#report-start", start.isoformat())
    page.fill("#report-end", end.isoformat())
    page.click("#report-run")


def test_a_refused_report_range_leaves_none_of_the_previous_ranges_tables(
        pg, edge_server: ServerProcess) -> None:
    """A valid range, then one the service refuses (422, the end before the start): the
    error is shown and nothing of the range before stays — its tables stayed under the
    error, read as the new range's answer (a tester's finding) — nor its downloads."""
    _open(pg, edge_server, "tehuantepec", HALF)
    _report(pg, FULL, EMPTY)
    pg.wait_for_selector(
        f'body[data-report-loaded="tehuantepec/{FULL.isoformat()}/{EMPTY.isoformat()}"]')
    assert pg.locator("[data-testid=report-months] tr").count() >= 2
    _report(pg, EMPTY, FULL)
    error = pg.locator("[data-testid=report-error]")
    error.wait_for()
    assert error.inner_text().startswith("422") and "end" in error.inner_text()
    for part in ("report-months", "report-years"):
        assert pg.locator(f"[data-testid={part}]").inner_text() == ""
    assert pg.locator("[data-testid=report-gain]").count() == 0
    assert pg.locator("[data-testid=report-pr-tracker]").count() == 0
    assert pg.get_attribute("body", "data-report-loaded") is None
    assert not pg.is_visible("#report-csv") and not pg.is_visible("#report-png")
    ARTIFACTS.mkdir(exist_ok=True)
    pg.locator("#report-card").screenshot(path=str(ARTIFACTS / "e2e-report-refused.png"))
    assert pg.inner_text("#banner").startswith("Report unavailable: 422")
    # the next valid range's answer takes the refused one's banner away (it stayed: a tester)
    _report(pg, FULL, EMPTY)
    pg.wait_for_selector(
        f'body[data-report-loaded="tehuantepec/{FULL.isoformat()}/{EMPTY.isoformat()}"]')
    assert not pg.is_visible("#banner")


def test_a_report_range_to_come_says_it_has_no_readings(pg, edge_server: ServerProcess) -> None:
    """A range in the future: the card says the service's words (``readings_note``), as the
    PNG does over its chart, instead of tables of dashes without a word."""
    start, end = TODAY + dt.timedelta(days=40), TODAY + dt.timedelta(days=42)
    _open(pg, edge_server, "tehuantepec", HALF)
    _report(pg, start, end)
    pg.wait_for_selector(
        f'body[data-report-loaded="tehuantepec/{start.isoformat()}/{end.isoformat()}"]')
    note = pg.locator("[data-testid=report-no-readings]").inner_text()
    assert note == (f"No readings between {start.isoformat()} and {end.isoformat()} "
                    "(end exclusive): the range has not begun.")
    ARTIFACTS.mkdir(exist_ok=True)
    pg.locator("#report-card").screenshot(path=str(ARTIFACTS / "e2e-report-to-come.png"))
    _report(pg, FULL, EMPTY)    # a range with readings: no such note
    pg.wait_for_selector(
        f'body[data-report-loaded="tehuantepec/{FULL.isoformat()}/{EMPTY.isoformat()}"]')
    assert pg.locator("[data-testid=report-no-readings]").count() == 0


def test_a_refused_diagnosis_range_leaves_none_of_the_previous_pointing_error(
        pg, edge_server: ServerProcess) -> None:
    """The diagnosis card's pointing error belongs to its range too: a range the service
    refuses leaves the range before's note and chart no more than its faults."""
    _open(pg, edge_server, "tehuantepec", HALF)
    pg.fill("#diag-start", FULL.isoformat())
    pg.fill("#diag-end", EMPTY.isoformat())
    pg.click("#diag-run")
    pg.wait_for_function("() => document.querySelector('[data-testid=pointing-note]')"
                         ".textContent.includes('no encoder angles')", timeout=120_000)
    pg.fill("#diag-start", EMPTY.isoformat())
    pg.fill("#diag-end", FULL.isoformat())
    pg.click("#diag-run")
    pg.wait_for_function("() => document.querySelector('[data-testid=diag-faults]')"
                         ".textContent.startsWith('Diagnosis failed: 422')")
    pg.wait_for_function("() => document.querySelector('[data-testid=pointing-note]')"
                         ".textContent.startsWith('Pointing error failed: 422')")
    assert pg.get_attribute("#chart-pointing", "data-points") == "0"


def test_a_site_made_in_the_form_joins_the_built_in_ones(pg, edge_server: ServerProcess) -> None:
    pg.goto(f"{edge_server.base_url}/#sites?site=tehuantepec")
    pg.wait_for_function("() => document.getElementById('site-json').value.includes('tehuantepec')")
    pg.click("#site-new")
    pg.fill("#site-id", "hand-made")
    pg.fill("#site-name", "Hand-made site")
    pg.fill("#site-lat", "100")
    pg.fill("#site-lon", "-99.13")
    pg.fill("#site-tz-input", "America/Mexico_City")
    assert "azimuth_min_deg" not in pg.input_value("#site-json")  # the new place's, not a copy
    # nor the selected site's altitude (Tehuantepec's 50 m was kept for any place)
    assert pg.input_value("#site-alt") == "" and "altitude_m" not in pg.input_value("#site-json")
    assert pg.input_value("#site-stamped") == ""  # the selected site's: the default
    pg.select_option("#site-stamped", "interval_end")  # an hourly logger's means
    assert '"readings_stamped": "interval_end"' in pg.input_value("#site-json")
    pg.fill("#site-token", ADMIN)
    # the id of a site that exists: refused on the page (a PUT would have replaced it)
    pg.fill("#site-id", "guadalajara_fisheye")
    pg.click("#site-save")
    error = pg.locator("[data-testid=site-result] .error")
    error.wait_for()
    assert "exists already" in error.inner_text(), error.inner_text()
    pg.fill("#site-id", "hand-made")
    pg.click("#site-save")
    # "Saving…" replaces the message of the save before at once, then the answer's
    pg.wait_for_function("() => document.querySelector('[data-testid=site-result]')"
                         ".innerText.includes('latitude_deg')")
    error = pg.locator("[data-testid=site-result] .error")
    assert "latitude_deg" in error.inner_text() and "90" in error.inner_text()
    pg.fill("#site-lat", "19.43")
    pg.click("#site-save")
    pg.wait_for_selector('body[data-overview-loaded^="hand-made/"]', timeout=120_000)
    options = pg.eval_on_selector_all("#site-select option", "els => els.map(e => e.value)")
    assert {"hand-made", "tehuantepec", "guadalajara_fisheye"} <= set(options)
    assert pg.input_value("#site-select") == "hand-made"
    site = _api(edge_server, "/api/v1/sites/hand-made")
    assert (site["latitude_deg"], site["origin"]) == (19.43, "user")
    assert site["readings_stamped"] == "interval_end"
    config = _api(edge_server, "/api/v1/sites/hand-made/config")
    assert "tracker.azimuth_min_deg" in config["assumed"], config.get("assumed")
    from pvlib.location import lookup_altitude
    assert "altitude_m" in config["assumed"], config.get("assumed")
    assert config["altitude_m"] == pytest.approx(lookup_altitude(19.43, -99.13), abs=1)


def test_a_submit_the_browser_blocks_replaces_the_forms_message(
        pg, edge_server: ServerProcess) -> None:
    """A submit the browser's own validation stops (a required field empty, a pattern not
    met) fires no ``submit`` event: the message of the save before stayed beside the
    browser's bubble as if it were this one's. It now says the field and the reason."""
    pg.goto(f"{edge_server.base_url}/#sites?site=tehuantepec")
    pg.wait_for_function("() => document.getElementById('site-json').value.includes('tehuantepec')")
    pg.click("#site-new")
    pg.fill("#site-id", "guadalajara_fisheye")
    pg.click("#site-save")
    result = pg.locator("[data-testid=site-result]")
    pg.wait_for_function("() => document.querySelector('[data-testid=site-result]')"
                         ".innerText.includes('exists already')")
    pg.fill("#site-id", "")
    pg.click("#site-save")
    assert pg.evaluate("() => document.getElementById('site-id').validity.valueMissing")
    pg.wait_for_function("() => !document.querySelector('[data-testid=site-result]')"
                         ".innerText.includes('exists already')", timeout=5_000)
    assert result.inner_text().startswith("Not saved: Site id: "), result.inner_text()
    pg.fill("#site-id", "Not An Id!")
    pg.click("#site-save")
    pg.wait_for_function("() => document.querySelector('[data-testid=site-result]')"
                         ".innerText.includes('lower-case letters')", timeout=5_000)
    ARTIFACTS.mkdir(exist_ok=True)
    pg.locator("#page-sites").screenshot(path=str(ARTIFACTS / "sites-blocked-submit.png"))
    # the Pointing page's range: an empty end, said beside the button
    pg.goto(f"{edge_server.base_url}/#pointing?site=tehuantepec")
    pg.locator("[data-testid=pointing-empty]").wait_for(state="visible")
    pg.fill("#pointing-end", "")
    pg.click("#pointing-run")
    pg.wait_for_function("() => document.getElementById('pointing-status').innerText"
                         ".startsWith('End (exclusive)')", timeout=5_000)


# -- the 4-week chart's gain axis (issue 22.4): from zero, round ticks, whole days only --

def _round_step(step: float) -> bool:
    """1, 2, 2.5 or 5 × 10^k."""
    mantissa = step / 10 ** math.floor(math.log10(step))
    return any(math.isclose(mantissa, m) for m in (1, 2, 2.5, 5))


def test_gain_axis_starts_at_zero_and_ignores_partial_days(pg, edge_server) -> None:
    _open(pg, edge_server, "tehuantepec", HALF)
    chart = pg.evaluate("""() => { const el = document.getElementById('chart-daily');
        return { axis: el.layout.yaxis2, traces: el.data.map((t) => ({ name: t.name,
                 x: t.x, y: t.y, opacity: t.opacity, marker: t.marker })) }; }""")
    rows = _api(edge_server, "/api/v1/sites/tehuantepec/energy", start=FULL.isoformat(),
                end=HALF.isoformat(), interval="day")["rows"]
    whole_gain = rows[0]["gain_pct"]
    axis = chart["axis"]
    assert axis["range"][0] == 0 and _round_step(axis["dtick"]) and axis["tick0"] == 0
    # the whole day sets the axis: the next round tick above its gain
    assert axis["range"][1] - axis["dtick"] < whole_gain <= axis["range"][1]
    gain = next(t for t in chart["traces"] if t["name"] == "gain")
    partial = next(t for t in chart["traces"] if t["name"] == "gain, partial day")
    on_line = dict(zip(gain["x"], gain["y"], strict=True))
    assert on_line[FULL.isoformat()] == whole_gain and on_line[HALF.isoformat()] is None
    assert partial["x"] == [HALF.isoformat()] and partial["opacity"] < 1
    bars = next(t for t in chart["traces"] if t["name"] == "tracker measured")
    k = bars["x"].index(HALF.isoformat())
    assert bars["marker"]["pattern"]["shape"][k] == "/" and bars["marker"]["opacity"][k] < 1


def test_a_polar_night_run_draws_the_sun_below_the_horizon_and_says_why(
        pg, edge_server: ServerProcess) -> None:
    """A tester's finding: at Tromsø in December the angles chart's axis stopped at 0°, so
    the sun's path (at most −3° at noon) was not drawn, and the tiles read 0 Wh and a bare
    "—" gain with no reason."""
    from live_service import tehuantepec_elsewhere

    with httpx.Client(base_url=edge_server.base_url, timeout=60) as c:
        body = tehuantepec_elsewhere(c, "tromso-night", latitude_deg=69.65, longitude_deg=18.96,
                                     timezone="Europe/Oslo")
        r = c.put("/api/v1/sites/tromso-night", json=body,
                  headers={"Authorization": f"Bearer {ADMIN}"})
        assert r.status_code in (200, 201), r.text
    pg.goto(f"{edge_server.base_url}/#simulation?site=tromso-night")
    pg.wait_for_selector("#sim-start")
    pg.fill("#sim-start", "2024-12-20")
    pg.fill("#sim-end", "2024-12-21")
    pg.select_option("#sim-step", "900")
    pg.click("#sim-run")
    pg.wait_for_selector("body[data-simulation-done]", timeout=90_000)
    title = pg.inner_text("#sim-angles-title")
    highest = float(re.fullmatch(r"Polar night: the sun at most (-[\d.]+)°", title).group(1))
    assert -4.0 < highest < -2.0  # pvlib: about −3° at Tromsø's noon on 20 December
    chart = pg.evaluate("""() => { const el = document.getElementById('chart-sim-angles');
        return { range: el.layout.yaxis.range,
                 sun: el.data.find((t) => t.name === 'sun elevation').y }; }""")
    assert chart["range"][0] <= -10 and max(v for v in chart["sun"] if v is not None) == \
        pytest.approx(highest, abs=0.06)
    assert "the fixed array made no energy" in pg.inner_text("#sim-summary")
    ARTIFACTS.mkdir(exist_ok=True)
    pg.screenshot(path=str(ARTIFACTS / "simulation-polar-night.png"), full_page=True)
