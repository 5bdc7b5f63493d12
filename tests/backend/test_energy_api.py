"""Energy per period over real HTTP (``backend/api/routes/energy.py``).

Expected energies come from an independent integration of what was posted
(``numpy.trapezoid`` over each run of readings not split by a long gap), never
from the service's own code.
"""

from __future__ import annotations

import datetime as dt
import math
from typing import TYPE_CHECKING

import httpx
import numpy as np
import pytest

if TYPE_CHECKING:
    from live_service import LiveServer

TZ = dt.timezone(dt.timedelta(hours=-6))
BASE = "/api/v1/sites/tehuantepec"
MAX_GAP_S = 1200  # the service default HELIOTWIN_ENERGY_MAX_GAP_S (sim/energy.py)


def bell(day: dt.date, array: str, scale: float, minutes: list[int]) -> list[dict]:
    t0 = dt.datetime(day.year, day.month, day.day, tzinfo=TZ)
    out = []
    for m in minutes:
        h = m / 60
        s = math.sin(math.pi * (h - 6.5) / 12) if 6.5 < h < 18.5 else 0.0
        p = scale * 700 * s**1.3 + 0.002 * (m % 89)
        v = 25.0 if p > 0.01 else 0.0
        out.append({"ts": (t0 + dt.timedelta(minutes=m)).isoformat(), "array": array,
                    "voltage_v": v, "current_a": p / v if v else 0.0, "power_w": p if v else 0.0})
    return out


def independent_energy_wh(readings: list[dict], t0: float, t1: float) -> float:
    """Trapezoid per run of readings no more than MAX_GAP_S apart, clipped to [t0, t1)."""
    ts = np.array([dt.datetime.fromisoformat(r["ts"]).timestamp() for r in readings])
    p = np.array([r["power_w"] for r in readings])
    order = np.argsort(ts)
    ts, p = ts[order], p[order]
    runs = np.split(np.arange(ts.size), np.flatnonzero(np.diff(ts) > MAX_GAP_S) + 1)
    total = 0.0
    for run in runs:
        sel = run[(ts[run] >= t0) & (ts[run] <= t1)]
        if sel.size > 1:
            total += float(np.trapezoid(p[sel], ts[sel])) / 3600.0
    return total


def _post(client: httpx.Client, token: str, readings: list[dict]) -> None:
    for k in range(0, len(readings), 5000):
        r = client.post(f"{BASE}/measurements", json={"readings": readings[k:k + 5000]},
                        headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 200, r.text


def test_energy_per_day_matches_independent_trapezoid(client: httpx.Client,
                                                      live_server: LiveServer) -> None:
    days = [dt.date(2023, 6, 1) + dt.timedelta(days=k) for k in range(3)]
    tracker = [x for d in days for x in bell(d, "tracker", 1.0, list(range(1440)))]
    fixed = [x for d in days for x in bell(d, "fixed", 0.8, list(range(0, 1440, 2)))]
    _post(client, live_server.write_token, tracker + fixed)
    r = client.get(f"{BASE}/energy", params={"start": "2023-06-01", "end": "2023-06-04",
                                             "interval": "day"})
    assert r.status_code == 200, r.text
    data = r.json()
    assert [row["period_start"] for row in data["rows"]] == [
        f"2023-06-0{k}T00:00:00-06:00" for k in (1, 2, 3)]
    for d, row in zip(days, data["rows"], strict=True):
        t0 = dt.datetime(d.year, d.month, d.day, tzinfo=TZ).timestamp()
        t1 = t0 + 86400
        exp_tr = independent_energy_wh(tracker, t0, t1)
        exp_fx = independent_energy_wh(fixed, t0, t1)
        got_tr = row["arrays"]["tracker"]["measured_wh"]
        got_fx = row["arrays"]["fixed"]["measured_wh"]
        assert got_tr == pytest.approx(exp_tr, rel=1e-9)
        assert got_fx == pytest.approx(exp_fx, rel=1e-9)
        assert row["gain_pct"] == pytest.approx(100 * (exp_tr / exp_fx - 1), rel=1e-9)
        assert row["arrays"]["tracker"]["readings"] == 1440
    # hours add up to the day, months hold the whole range
    hours = client.get(f"{BASE}/energy", params={"start": "2023-06-02", "end": "2023-06-03",
                                                 "interval": "hour"}).json()["rows"]
    assert len(hours) == 24
    assert sum(h["arrays"]["tracker"]["measured_wh"] or 0 for h in hours) == pytest.approx(
        data["rows"][1]["arrays"]["tracker"]["measured_wh"], rel=1e-9)
    month = client.get(f"{BASE}/energy", params={"start": "2023-06-01", "end": "2023-07-01",
                                                 "interval": "month"}).json()["rows"]
    assert len(month) == 1
    assert month[0]["arrays"]["tracker"]["measured_wh"] == pytest.approx(
        independent_energy_wh(tracker, 0, 4e9), rel=1e-9)


def test_energy_does_not_bridge_long_gaps(client: httpx.Client,
                                          live_server: LiveServer) -> None:
    day = dt.date(2023, 7, 1)
    minutes = [m for m in range(1440) if not 600 <= m < 660]  # a 61-minute outage at 10:00
    minutes += [m for m in range(720, 730)]  # re-sent minutes do not count twice
    rd = bell(day, "tracker", 1.0, minutes)
    _post(client, live_server.write_token, rd)
    row = client.get(f"{BASE}/energy", params={"start": "2023-07-01", "end": "2023-07-02"}
                     ).json()["rows"][0]
    unique = bell(day, "tracker", 1.0, sorted(set(minutes)))
    full = bell(day, "tracker", 1.0, list(range(1440)))
    t0 = dt.datetime(2023, 7, 1, tzinfo=TZ).timestamp()
    got = row["arrays"]["tracker"]["measured_wh"]
    assert got == pytest.approx(independent_energy_wh(unique, t0, t0 + 86400), rel=1e-9)
    assert got < independent_energy_wh(full, t0, t0 + 86400) - 300  # the gap is not filled
    assert row["gain_pct"] is None and row["arrays"]["fixed"]["measured_wh"] is None


def test_unaligned_range_and_out_of_order_posts(client: httpx.Client,
                                                live_server: LiveServer) -> None:
    day = dt.date(2023, 8, 1)
    rd = bell(day, "fixed", 1.0, list(range(1440)))
    _post(client, live_server.write_token, rd[700:])  # afternoon first,
    _post(client, live_server.write_token, rd[:700])  # then the morning (rollups refreshed)
    start = dt.datetime(2023, 8, 1, 9, 17, 30, tzinfo=TZ)
    end = dt.datetime(2023, 8, 1, 15, 42, 10, tzinfo=TZ)
    rows = client.get(f"{BASE}/energy", params={"start": start.isoformat(),
                                                "end": end.isoformat(), "interval": "day"}
                      ).json()["rows"]
    assert len(rows) == 1
    ts = np.array([dt.datetime.fromisoformat(r["ts"]).timestamp() for r in rd])
    p = np.array([r["power_w"] for r in rd])
    grid = np.arange(start.timestamp(), end.timestamp() + 0.5, 0.5)
    expected = float(np.trapezoid(np.interp(grid, ts, p), grid)) / 3600  # dense, independent
    assert rows[0]["arrays"]["fixed"]["measured_wh"] == pytest.approx(expected, rel=1e-6)


def test_a_period_between_two_bridged_readings_has_its_energy(
        client: httpx.Client, live_server: LiveServer) -> None:
    """A 15-minute logger at 600 W; the hours of 10:50–11:05: the 10:50–11:00 row holds no
    reading but lies inside the bridged 10:45–11:00 interval. It said null ("no readings")
    while the totals counted its 100 Wh: the rows did not add up (a tester's finding)."""
    day = "2023-09-21"
    rd = [{"ts": f"{day}T{h}:00-06:00", "array": a, "power_w": 600.0}
          for h in ("10:00", "10:15", "10:30", "10:45", "11:00", "11:15")
          for a in ("tracker", "fixed")]
    _post(client, live_server.write_token, rd)
    data = client.get(f"{BASE}/energy", params={"start": f"{day}T10:50:00-06:00",
                                                "end": f"{day}T11:05:00-06:00",
                                                "interval": "hour"}).json()
    first, second = (row["arrays"]["tracker"] for row in data["rows"])
    assert first["readings"] == 0 and first["measured_wh"] == pytest.approx(100.0)
    assert second["measured_wh"] == pytest.approx(50.0)
    assert data["totals"]["arrays"]["tracker"]["measured_wh"] == pytest.approx(150.0)
    assert data["rows"][0]["gain_pct"] == pytest.approx(0.0)


def test_twin_energy_exists_for_past_days(client: httpx.Client) -> None:
    d0 = dt.datetime.now(TZ).date() - dt.timedelta(days=40)  # within HELIOTWIN_TWIN_HISTORY_DAYS
    day = [(d0 + dt.timedelta(days=k)).isoformat() for k in range(4)]
    r = client.get(f"{BASE}/energy", params={"start": day[0], "end": day[3]})
    rows = r.json()["rows"]
    assert len(rows) == 3
    for row in rows:
        tr, fx = row["arrays"]["tracker"]["twin_wh"], row["arrays"]["fixed"]["twin_wh"]
        # clear-sky days at 16° N: 4 × 205 Wp arrays give several kWh a day
        assert 3000 < fx < tr < 9000
        assert row["twin_gain_pct"] > 10
        assert row["arrays"]["tracker"]["measured_wh"] is None
    twin = client.get(f"{BASE}/measurements", params={
        "array": "tracker", "source": "twin", "start": day[1], "end": day[2],
        "max_points": 2000}).json()
    assert len(twin["points"]) == 1440 and max(p["power_w"] for p in twin["points"]) > 500
    csv_text = client.get(f"{BASE}/energy", params={"start": day[0], "end": day[3],
                                                    "format": "csv"}).text
    assert csv_text.splitlines()[0].startswith("period_start,period_end,tracker_measured_wh")
    assert len(csv_text.splitlines()) == 4


def test_a_period_without_sun_says_why_it_has_no_twin_gain(client: httpx.Client) -> None:
    """A tester's Svalbard December (polar night) read twin_wh 0, ``twin_gain_pct`` and
    ``twin_note`` null: nothing said why. A night hour is such a period too; a daylight one
    keeps its gain and no note."""
    from backend.measurements.energy import NO_SUN_NOTE

    d0 = dt.datetime.now(TZ).date() - dt.timedelta(days=40)
    rows = client.get(f"{BASE}/energy", params={
        "start": d0.isoformat(), "end": (d0 + dt.timedelta(days=1)).isoformat(),
        "interval": "hour"}).json()["rows"]
    night, noon = rows[2], rows[12]  # 02:00 and 12:00 local
    assert night["arrays"]["tracker"]["twin_wh"] == 0 and night["twin_gain_pct"] is None
    assert night["twin_note"] == NO_SUN_NOTE
    assert noon["twin_gain_pct"] is not None and noon["twin_note"] is None


def test_the_range_is_echoed_in_the_sites_zone(client: httpx.Client) -> None:
    """A tester's range with an offset of its own read back in UTC beside periods and an
    ``end`` in the site's zone; now both in the site's, the same instants."""
    d0 = dt.datetime.now(TZ).date() - dt.timedelta(days=40)
    body = client.get(f"{BASE}/energy", params={
        "start": f"{d0.isoformat()}T00:00:00+01:00",
        "end": (d0 + dt.timedelta(days=1)).isoformat()}).json()
    start = dt.datetime.fromisoformat(body["start"])
    assert start == dt.datetime(d0.year, d0.month, d0.day, tzinfo=dt.timezone(
        dt.timedelta(hours=1)))
    assert start.utcoffset() == dt.datetime.fromisoformat(body["end"]).utcoffset() \
        == dt.datetime.fromisoformat(body["rows"][0]["period_start"]).utcoffset()


def test_energy_errors(client: httpx.Client) -> None:
    r = client.get(f"{BASE}/energy", params={"start": "2022-01-02", "end": "2022-01-01"})
    assert r.status_code == 422
    r = client.get(f"{BASE}/energy", params={"start": "2022-01-01", "end": "2022-01-02",
                                             "interval": "week"})
    assert r.status_code == 422
    r = client.get(f"{BASE}/energy", params={"start": "2022-01-01T00:00:00", "end": "2022-01-02"})
    assert r.status_code == 422 and "offset" in r.json()["detail"]
    # an offset's '+' typed into the URL unencoded arrives as a space: the answer says so
    r = client.get(f"{BASE}/energy?start=2022-01-01T00:00:00+01:00&end=2022-01-02")
    assert r.status_code == 422 and "%2B" in r.json()["detail"], r.text
    # ranges beyond what a calendar can hold, or too many periods: 422, not 500
    r = client.get(f"{BASE}/energy", params={"start": "0001-01-01", "end": "9999-12-31",
                                             "interval": "month"})
    assert r.status_code == 422 and "start" in r.json()["detail"]
    r = client.get(f"{BASE}/energy", params={"start": "1950-01-01", "end": "2150-01-01",
                                             "interval": "hour"})
    assert r.status_code == 422 and "limit" in r.json()["detail"]


def test_twin_on_demand_is_bounded_to_recent_or_measured_days(client: httpx.Client,
                                                              live_server: LiveServer) -> None:
    """Anonymous reads fill the twin only for recent days or days after the first
    measured reading; far older ranges stay empty instead of growing the database."""
    r = client.get(f"{BASE}/energy", params={"start": "1995-03-01", "end": "1995-03-03",
                                             "interval": "day"})
    assert r.status_code == 200, r.text
    assert all(row["arrays"]["tracker"]["twin_wh"] in (None, 0) for row in r.json()["rows"])
    recent = dt.datetime.now(TZ).date() - dt.timedelta(days=3)
    r = client.get(f"{BASE}/energy", params={"start": recent.isoformat(),
                                             "end": (recent + dt.timedelta(days=1)).isoformat(),
                                             "interval": "day"})
    assert r.status_code == 200, r.text
    assert r.json()["rows"][0]["arrays"]["tracker"]["twin_wh"] > 1000


def test_one_address_without_a_token_holds_at_most_two_places_at_the_reader() -> None:
    """Energy and report reads run one at a time for everybody, in order of arrival: 16
    100-year reads of one address (5 s each, within its CPU allowance) kept another
    address's 28-day read waiting 38–130 s (a tester's finding). An address without a
    token now has two places in that line at once; its third waits off the line until one
    is given back, while another address and a caller with a token join at once."""
    import asyncio
    from contextlib import AsyncExitStack

    from live_service import run_in_own_thread
    from starlette.requests import Request

    from backend.api.routes.energy import READS_IN_LINE_PER_CLIENT, in_line

    def request(host: str) -> Request:
        return Request({"type": "http", "client": (host, 5000), "headers": []})

    async def joins_within(host: str, caller: object, seconds: float,
                           held: AsyncExitStack) -> bool:
        try:
            await asyncio.wait_for(held.enter_async_context(in_line(request(host), caller)),
                                   seconds)
        except TimeoutError:
            return False
        return True

    async def main() -> None:
        async with AsyncExitStack() as first:
            for _ in range(READS_IN_LINE_PER_CLIENT):
                assert await joins_within("10.0.0.1", None, 1.0, first)
            async with AsyncExitStack() as others:
                assert not await joins_within("10.0.0.1", None, 0.2, others)  # it waits
                assert await joins_within("10.0.0.2", None, 1.0, others)
                assert await joins_within("10.0.0.1", "a token's caller", 1.0, others)
            third = asyncio.ensure_future(in_line(request("10.0.0.1"), None).__aenter__())
            await asyncio.sleep(0.1)
            assert not third.done()
        await asyncio.wait_for(third, 1.0)  # a place given back: the third joins

    assert READS_IN_LINE_PER_CLIENT == 2
    run_in_own_thread(main())  # not asyncio.run: a browser test's loop may run here
