"""Partial days, the twin's reasons, the camera site's sun and range reports, over HTTP
(the service in this process).

Issue 14, items 3 and 9. Readings come from a generator of its own (a sine-power day,
nothing like the twin's clear-sky model), stamped 17 s past each minute as a logger
does; every expected value is computed here from what was posted and from the twin
series the service serves (``source=twin``), with NumPy — never by the service's code.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import math
import struct
from collections.abc import Iterator
from zoneinfo import ZoneInfo

import httpx
import numpy as np
import pytest
from live_service import BACKENDS, InProcessServer, new_database

TZ = ZoneInfo("America/Mexico_City")
BASE = "/api/v1/sites/tehuantepec"


@pytest.fixture(scope="module", params=BACKENDS)
def server(request: pytest.FixtureRequest,
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    tmp = tmp_path_factory.mktemp("report-api")
    db = new_database(request.param, tmp)
    proc = InProcessServer(db.url).start()
    try:
        yield proc
    finally:
        proc.stop()
        db.drop()


@pytest.fixture(scope="module")
def client(server: InProcessServer) -> Iterator[httpx.Client]:
    with server.client(timeout_s=120) as c:
        yield c


def sine_day(day: dt.date, array: str, scale: float, minutes: range) -> list[dict]:
    t0 = dt.datetime(day.year, day.month, day.day, tzinfo=TZ)
    out = []
    for m in minutes:
        h = m / 60
        p = scale * 600 * max(0.0, math.sin(math.pi * (h - 6.5) / 11.5)) ** 1.2
        out.append({"ts": (t0 + dt.timedelta(minutes=m, seconds=17)).isoformat(),
                    "array": array, "voltage_v": 24.0, "current_a": p / 24.0, "power_w": p})
    return out


TODAY = dt.datetime.now(TZ).date()
HALF = TODAY - dt.timedelta(days=6)  # readings 06:00–12:00 only
FULL = HALF - dt.timedelta(days=1)  # readings all day


@pytest.fixture(scope="module")
def posted(client: httpx.Client, server: InProcessServer) -> dict[str, list[dict]]:
    token = server.token("tehuantepec")
    out: dict[str, list[dict]] = {}
    for array, scale in (("tracker", 1.3), ("fixed", 1.0)):
        rows = sine_day(FULL, array, scale, range(0, 1440)) + sine_day(
            HALF, array, scale, range(6 * 60, 12 * 60))
        r = client.post(f"{BASE}/measurements", json={"readings": rows},
                        headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 200, r.text
        out[array] = rows
    return out


def _ts(rows: list[dict]) -> np.ndarray:
    return np.array([dt.datetime.fromisoformat(r["ts"]).timestamp() for r in rows])


def twin_over(client: httpx.Client, array: str, day: dt.date,
              measured: list[dict] | None) -> float:
    """The served twin of ``day`` integrated with numpy.trapezoid, over the minutes that
    hold a measured reading (or over the whole day when ``measured`` is None)."""
    body = client.get(f"{BASE}/measurements", params={
        "array": array, "source": "twin", "start": day.isoformat(),
        "end": (day + dt.timedelta(days=1)).isoformat(), "max_points": 5000}).json()
    t = np.array([dt.datetime.fromisoformat(p["ts"].replace("Z", "+00:00")).timestamp()
                  for p in body["points"]])
    p = np.array([pt["power_w"] for pt in body["points"]])
    assert body["bucket_s"] == 0 and t.size >= 1439
    if measured is not None:
        keep = np.isin(t, np.floor(_ts(measured) / 60) * 60)
        t, p = t[keep], p[keep]
    return float(np.trapezoid(p, t)) / 3600


def measured_wh(rows: list[dict], day: dt.date) -> float:
    t0 = dt.datetime(day.year, day.month, day.day, tzinfo=TZ).timestamp()
    sel = [r for r in rows if t0 <= dt.datetime.fromisoformat(r["ts"]).timestamp() < t0 + 86400]
    return float(np.trapezoid([r["power_w"] for r in sel], _ts(sel))) / 3600


def test_a_half_day_is_partial_and_compared_over_the_same_minutes(
        client: httpx.Client, posted: dict[str, list[dict]]) -> None:
    rows = client.get(f"{BASE}/energy", params={
        "start": FULL.isoformat(), "end": (HALF + dt.timedelta(days=1)).isoformat()}).json()["rows"]
    full, half = rows
    assert full["partial"] is False and half["partial"] is True
    half_rows = {a: [r for r in posted[a] if r["ts"].startswith(HALF.isoformat())]
                 for a in posted}
    for a in ("tracker", "fixed"):
        got = half["arrays"][a]
        matched = twin_over(client, a, HALF, half_rows[a])
        whole = twin_over(client, a, HALF, None)
        assert got["twin_matched_wh"] == pytest.approx(matched, rel=1e-6)
        assert got["twin_wh"] == pytest.approx(whole, rel=1e-6)
        assert got["coverage_pct"] == pytest.approx(100 * matched / whole, rel=1e-6)
        assert 30 < got["coverage_pct"] < 70  # a morning of a clear day
        assert got["performance_ratio"] == pytest.approx(
            measured_wh(posted[a], HALF) / matched, rel=1e-6)
        assert full["arrays"][a]["coverage_pct"] > 99.9
    m = {a: twin_over(client, a, HALF, half_rows[a]) for a in ("tracker", "fixed")}
    assert half["twin_matched_gain_pct"] == pytest.approx(
        100 * (m["tracker"] / m["fixed"] - 1), rel=1e-6)
    # the posted gain is +30 % at every minute: measured over the same minutes agrees
    assert half["gain_pct"] == pytest.approx(30.0, abs=0.01)


def test_a_day_older_than_the_twin_window_says_why(client: httpx.Client) -> None:
    old = dt.datetime.now(TZ).date() - dt.timedelta(days=700)
    row = client.get(f"{BASE}/energy", params={
        "start": old.isoformat(), "end": (old + dt.timedelta(days=1)).isoformat()}
    ).json()["rows"][0]
    assert row["arrays"]["tracker"]["twin_wh"] is None
    assert "older than the on-demand twin window" in row["twin_note"]
    assert "HELIOTWIN_TWIN_HISTORY_DAYS" in row["twin_note"]


def test_a_camera_site_shows_the_sun(client: httpx.Client) -> None:
    import pandas as pd
    import pvlib

    body = client.get("/api/v1/sites/guadalajara_fisheye/status").json()
    assert body["arrays"] == {}
    when = pd.DatetimeIndex([pd.Timestamp(body["twin_minute"])])
    # seed 003's place (data/sites/guadalajara_fisheye.json: 1560 m, 20 °C), pvlib's SPA
    # called directly, with the pressure of the altitude (as the twin computes it)
    ref = pvlib.solarposition.get_solarposition(when, 20.8667, -103.05, altitude=1560.0,
                                                temperature=20.0)
    assert body["sun"]["azimuth_deg"] == pytest.approx(float(ref["azimuth"].iloc[0]), abs=0.01)
    assert body["sun"]["elevation_deg"] == pytest.approx(
        float(ref["apparent_elevation"].iloc[0]), abs=0.05)


def test_the_report_sums_the_days_into_months_and_years(
        client: httpx.Client, posted: dict[str, list[dict]]) -> None:
    start, end = FULL - dt.timedelta(days=40), HALF + dt.timedelta(days=1)
    rep = client.get(f"{BASE}/report", params={"start": start.isoformat(),
                                               "end": end.isoformat()}).json()
    assert len(rep["days"]) == (end - start).days
    for a in ("tracker", "fixed"):
        want = measured_wh(posted[a], FULL) + measured_wh(posted[a], HALF)
        assert rep["totals"]["arrays"][a]["measured_wh"] == pytest.approx(want, rel=1e-6)
        month_sum = sum(r["arrays"][a]["measured_wh"] or 0 for r in rep["months"])
        year_sum = sum(r["arrays"][a]["measured_wh"] or 0 for r in rep["years"])
        assert month_sum == pytest.approx(want, rel=1e-9)
        assert year_sum == pytest.approx(want, rel=1e-9)
        twin_days = sum(r["arrays"][a]["twin_wh"] or 0 for r in rep["days"])
        assert rep["totals"]["arrays"][a]["twin_wh"] == pytest.approx(twin_days, rel=1e-9)
    assert rep["totals"]["partial"] is True  # 40 days of twin, two of readings
    assert rep["totals"]["gain_pct"] == pytest.approx(30.0, abs=0.01)


def test_report_csv_names_its_units_and_png_is_one_a4_page(client: httpx.Client,
                                                           posted: dict) -> None:
    params = {"start": FULL.isoformat(), "end": (HALF + dt.timedelta(days=1)).isoformat()}
    r = client.get(f"{BASE}/report.csv", params=params)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    table = list(csv.DictReader(io.StringIO(r.text)))
    assert [row["period"] for row in table].count("day") == 2
    assert table[-1]["period"] == "total"
    header = r.text.splitlines()[0].split(",")
    quantities = [c for c in header if c not in ("period", "period_start", "period_end",
                                                 "partial", "gain_note", "twin_note")]
    assert all(c.endswith(("_wh", "_pct", "_ratio")) for c in quantities), quantities
    day_rows = [row for row in table if row["period"] == "day"]
    assert [row["partial"] for row in day_rows] == ["False", "True"]
    png = client.get(f"{BASE}/report.png", params=params)
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    assert png.content[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", png.content[16:24])
    assert (width, height) == (1240, 1753)  # A4 (8.27 in × 11.69 in) at 150 dpi


def test_the_pngs_monthly_table_marks_a_partial_month(client: httpx.Client,
                                                     posted: dict) -> None:
    """A tester's report.png: the month the range cut (readings on a few of its days) was not
    marked, where the dashboard's table says "(partial)"."""
    from backend.reports import report_figure

    rep = client.get(f"{BASE}/report", params={
        "start": (FULL - dt.timedelta(days=40)).isoformat(),
        "end": (HALF + dt.timedelta(days=1)).isoformat()}).json()
    fig = report_figure(rep, "test")
    (ax,) = [a for a in fig.axes if a.get_title(loc="left") == "Monthly table"]
    cells = {k: c.get_text().get_text() for k, c in ax.tables[0].get_celld().items()}
    for i, month in enumerate(rep["months"], start=1):
        assert cells[(i, 0)].endswith("(partial)") == bool(month["partial"]), (i, cells[(i, 0)])
    assert any(m["partial"] for m in rep["months"])


@pytest.mark.parametrize("n_days", [1, 2, 5, 31])
def test_the_pngs_daily_chart_labels_each_day_under_its_bars(client: httpx.Client,
                                                             n_days: int) -> None:
    """A short range's daily chart: one label per day (every few past ten), each under the
    middle of its day's bars (the automatic ticks fell every 12 hours, repeated each date,
    and a bar straddled two: a new user's finding)."""
    import matplotlib.dates as mdates

    from backend.reports import report_figure

    start = FULL - dt.timedelta(days=n_days - 1)
    rep = client.get(f"{BASE}/report", params={
        "start": start.isoformat(), "end": (FULL + dt.timedelta(days=1)).isoformat()}).json()
    fig = report_figure(rep, "test")
    (ax,) = [a for a in fig.axes if a.get_title().startswith("Daily energy")]
    fig.canvas.draw()
    labels = [t.get_text() for t in ax.get_xticklabels()]
    dates = [start + dt.timedelta(days=k) for k in range(n_days)][::max(1, n_days // 10)]
    assert labels == [d.strftime("%d %b") for d in dates]
    noon = [mdates.date2num(dt.datetime.combine(start + dt.timedelta(days=k), dt.time(12)))
            for k in range(n_days)]
    assert list(ax.get_xticks()) == pytest.approx(noon[::max(1, n_days // 10)])
    # the bars: one per array and day, drawn array by array; a day's centred on its noon
    centres = np.array([p.get_x() + p.get_width() / 2 for p in ax.patches])
    assert centres.size == n_days * len(rep["arrays"])
    np.testing.assert_allclose(centres.reshape(len(rep["arrays"]), n_days).mean(axis=0), noon)


@pytest.mark.parametrize(("params", "words"), [
    ({"start": "2026-11-10", "end": "2026-11-01"}, "end"),
    ({"start": "2010-01-01", "end": "2026-01-01"}, "at most 3700 days"),
    ({"start": "yesterday", "end": "2026-11-01"}, "start"),
])
def test_a_bad_report_range_is_a_422_naming_it(client: httpx.Client, params: dict,
                                               words: str) -> None:
    r = client.get(f"{BASE}/report.png", params=params)
    assert r.status_code == 422 and words in r.json()["detail"]


SILENT = HALF + dt.timedelta(days=2)  # the fixed logger silent 08:00–08:25, past the gap


def test_a_logger_silent_for_minutes_leaves_no_gain_over_minutes_it_missed(
        client: httpx.Client, server: InProcessServer) -> None:
    """The fixed logger silent 26 minutes (over the 20 min energy gap; a logger_silent
    alert; today's case is the same: the minutes since its last reading): the day is not
    partial (its readings cover ~97 % of its twin), but the tracker read minutes it did
    not. The gain was taken as over the same minutes (+33 % for the +30 % posted at every
    minute, a tester's
    +39.5 % beside the twin's +35.4 %); it is null with why, and the twin's gain over the
    minutes both read stays."""
    token = server.token("tehuantepec")
    for array, scale in (("tracker", 1.3), ("fixed", 1.0)):
        minutes = [m for m in range(1440) if array == "tracker" or not 480 <= m < 505]
        r = client.post(f"{BASE}/measurements", json={"readings": sine_day(
            SILENT, array, scale, minutes)}, headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 200, r.text
    day = client.get(f"{BASE}/energy", params={
        "start": SILENT.isoformat(),
        "end": (SILENT + dt.timedelta(days=1)).isoformat()}).json()["rows"][0]
    assert day["partial"] is False and day["arrays"]["fixed"]["coverage_pct"] > 95
    assert day["gain_pct"] is None and "different minutes" in day["gain_note"]
    tr, fx = day["arrays"]["tracker"], day["arrays"]["fixed"]
    assert tr["twin_shared_wh"] < 0.99 * tr["twin_covered_wh"]
    assert day["twin_matched_gain_pct"] == pytest.approx(
        100 * (tr["twin_shared_wh"] / fx["twin_shared_wh"] - 1))


def test_a_date_time_range_is_titled_in_the_sites_zone(client: httpx.Client) -> None:
    """start=…T00:00:00Z is 18:00 the day before in Mexico City: the PNG's title and the
    CSV's total row say so (they read the UTC dates and +00:00 among −06:00 rows)."""
    from backend.reports import report_figure

    day = HALF + dt.timedelta(days=2)
    params = {"start": f"{day.isoformat()}T00:00:00Z",
              "end": f"{(day + dt.timedelta(days=2)).isoformat()}T00:00:00Z"}
    rep = client.get(f"{BASE}/report", params=params).json()
    before = day - dt.timedelta(days=1)
    assert rep["start"] == f"{before.isoformat()}T18:00:00-06:00"
    title = [t.get_text() for t in report_figure(rep, "test").texts if " to " in t.get_text()]
    assert f"{before.isoformat()} 18:00 -06:00 to " in title[0], title
    table = list(csv.DictReader(io.StringIO(client.get(f"{BASE}/report.csv",
                                                       params=params).text)))
    assert all(r["period_start"].endswith("-06:00") and r["period_end"].endswith("-06:00")
               for r in table), [r["period_start"] for r in table if r["period"] == "total"]


def _png_text(png: bytes) -> dict[str, str]:
    """The PNG's tEXt chunks (keyword → text), read from the bytes by the PNG spec."""
    out, at = {}, 8
    while at < len(png):
        length, kind = struct.unpack(">I4s", png[at:at + 8])
        if kind == b"tEXt":
            key, _, text = png[at + 8:at + 8 + length].partition(b"\0")
            out[key.decode("latin-1")] = text.decode("latin-1")
        at += 12 + length
    return out


@pytest.mark.parametrize(("start", "end", "words"), [
    # a range to come (a tester's empty chart, drawn without a word)
    (TODAY + dt.timedelta(days=30), TODAY + dt.timedelta(days=32), ": the range has not begun"),
    # a past range the loggers did not read (the twin alone)
    (HALF + dt.timedelta(days=4), HALF + dt.timedelta(days=5), ""),
])
def test_a_range_without_readings_says_so_in_json_and_png(
        client: httpx.Client, posted: dict, start: dt.date, end: dt.date, words: str) -> None:
    """No reading in the range: the JSON's ``readings_note`` names the range (200, as the
    report of any range: the twin's numbers stand), and the PNG carries the same words
    over its daily chart and in its Description (its chart was drawn empty, silently)."""
    from backend.reports import report_figure

    params = {"start": start.isoformat(), "end": end.isoformat()}
    rep = client.get(f"{BASE}/report", params=params).json()
    want = (f"No readings between {start.isoformat()} and {end.isoformat()} "
            f"(end exclusive){words}")
    assert rep["readings_note"] == want
    assert all(a["readings"] == 0 for a in rep["totals"]["arrays"].values())
    png = client.get(f"{BASE}/report.png", params=params)
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    assert _png_text(png.content)["Description"] == want
    (ax,) = [a for a in report_figure(rep, "test").axes
             if a.get_title().startswith("Daily energy")]
    assert any(t.get_text().startswith(f"{want}.") for t in ax.texts)


def test_a_range_with_readings_has_no_readings_note(client: httpx.Client,
                                                    posted: dict) -> None:
    params = {"start": FULL.isoformat(), "end": (FULL + dt.timedelta(days=1)).isoformat()}
    assert client.get(f"{BASE}/report", params=params).json()["readings_note"] is None
    png = client.get(f"{BASE}/report.png", params=params)
    meta = _png_text(png.content)
    assert "Description" not in meta and f"{FULL.isoformat()} to " in meta["Title"]
