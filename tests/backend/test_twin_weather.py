"""``GET …/measurements?source=twin_weather`` over real HTTP: the twin under the sky the
fixed array measured (``backend/diagnosis/weather_twin.py``).

Its accuracy against independently made logger days is the diagnosis benchmark's
(``benchmarks/bench_diagnosis.py``); here: that the endpoint serves that pipeline on
the stored readings, says what the sky rests on, buckets honestly and refuses what
it cannot do.
"""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING

import httpx
import numpy as np
import pandas as pd
import pytest
from test_measurements_api import PATH, TZ, post

if TYPE_CHECKING:
    from live_service import LiveServer

DAY = dt.date(2023, 4, 12)


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the twin, not storage
def test_the_weather_aware_twin_follows_the_fixed_arrays_sky(
        client: httpx.Client, live_server: LiveServer) -> None:
    from sim import sky_sensor, twin
    from sim.sites import load_site

    site = load_site("tehuantepec")
    t0 = pd.Timestamp(dt.datetime(DAY.year, DAY.month, DAY.day, tzinfo=TZ))
    clear = twin.simulate(site, t0, t0 + pd.Timedelta(days=1)).series
    hazy = 0.7 * clear["fixed_power_w"].fillna(0.0).to_numpy()  # a uniformly hazy day
    readings = [{"ts": t.isoformat(), "array": "fixed", "power_w": round(float(p), 3)}
                for t, p in zip(clear.index, hazy, strict=True)]
    assert post(client, live_server.write_token, {"readings": readings}).status_code == 200

    params = {"start": DAY.isoformat(), "end": (DAY + dt.timedelta(days=1)).isoformat()}
    got = client.get(PATH, params={**params, "array": "tracker", "source": "twin_weather"})
    assert got.status_code == 200, got.text
    body = got.json()
    assert body["source"] == "twin_weather" and body["count"] == 1440
    assert body["sky"]["source"] == "fixed_array"
    assert body["sky"]["valid_daylight_minutes_pct"] > 90
    power = np.array([p["power_w"] for p in body["points"]])
    direct = sky_sensor.weather_aware_twin(site, t0.tz_convert("UTC"),
                                           (t0 + pd.Timedelta(days=1)).tz_convert("UTC"),
                                           np.round(hazy, 3))["tracker_power_w"].to_numpy()
    assert np.abs(power - direct).max() < 0.01  # the same pipeline on the stored readings
    tracker_clear = clear["tracker_power_w"].fillna(0.0).to_numpy()
    ratio = power.sum() / tracker_clear.sum()
    # a hazy sky, not the clear one: 0.7 of the fixed plane's clear-sky power reads as mostly
    # lost beam, which the tracker lives on, so it keeps less than 0.7 (0.54 measured)
    assert 0.45 < ratio < 0.65
    assert all(p["voltage_v"] is None for p in body["points"])

    hourly = client.get(PATH, params={**params, "array": "tracker", "source": "twin_weather",
                                      "max_points": 24}).json()
    assert hourly["bucket_s"] == 3600 and len(hourly["points"]) == 24
    noon = hourly["points"][12]
    assert noon["n"] == 60 and noon["power_w"] == pytest.approx(power[720:780].mean())
    assert noon["power_w_max"] == pytest.approx(power[720:780].max())


def test_twin_weather_without_a_sky_or_over_a_long_range_says_why(
        client: httpx.Client) -> None:
    none = client.get(PATH, params={"array": "tracker", "source": "twin_weather",
                                    "start": "2023-04-20", "end": "2023-04-21"}).json()
    assert none["sky"]["source"] == "clear_sky"  # no fixed readings that day
    long = client.get(PATH, params={"array": "tracker", "source": "twin_weather",
                                    "start": "2023-01-01", "end": "2023-03-01"})
    assert long.status_code == 422 and "31 days" in long.text
    bad = client.get(PATH, params={"array": "tracker", "source": "weather",
                                   "start": "2023-04-20", "end": "2023-04-21"})
    assert bad.status_code == 422 and "twin_weather" in bad.text


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the twin, not storage
def test_energy_of_the_weather_aware_twin_by_day_and_by_hour_agree(
        client: httpx.Client, live_server: LiveServer) -> None:
    """The day's energy from the diagnosis's per-day cache and the hours' from the minute
    twin are two paths to the same integral; both equal the minute power summed here."""
    from sim import twin
    from sim.sites import load_site

    day = DAY + dt.timedelta(days=2)
    site = load_site("tehuantepec")
    t0 = pd.Timestamp(dt.datetime(day.year, day.month, day.day, tzinfo=TZ))
    clear = twin.simulate(site, t0, t0 + pd.Timedelta(days=1)).series
    fixed = 0.8 * clear["fixed_power_w"].fillna(0.0).to_numpy()
    assert post(client, live_server.write_token, {"readings": [
        {"ts": t.isoformat(), "array": "fixed", "power_w": round(float(p), 3)}
        for t, p in zip(clear.index, fixed, strict=True)]}).status_code == 200
    params = {"start": day.isoformat(), "end": (day + dt.timedelta(days=1)).isoformat()}
    minutes = client.get(PATH, params={**params, "array": "tracker",
                                       "source": "twin_weather"}).json()["points"]
    expected_wh = sum(p["power_w"] for p in minutes) / 60.0
    daily = client.get("/api/v1/sites/tehuantepec/energy",
                       params={**params, "interval": "day", "source": "twin_weather"})
    assert daily.status_code == 200, daily.text
    (row,) = daily.json()["rows"]
    assert row["arrays"]["tracker"]["twin_weather_wh"] == pytest.approx(expected_wh, rel=1e-4)
    assert row["twin_weather_note"] is None
    assert row["twin_weather_gain_pct"] == pytest.approx(100.0 * (
        row["arrays"]["tracker"]["twin_weather_wh"] / row["arrays"]["fixed"]["twin_weather_wh"]
        - 1.0))
    hourly = client.get("/api/v1/sites/tehuantepec/energy",
                        params={**params, "interval": "hour", "source": "twin_weather"}).json()
    assert len(hourly["rows"]) == 24
    assert sum(r["arrays"]["tracker"]["twin_weather_wh"] for r in hourly["rows"]) == \
        pytest.approx(expected_wh, rel=1e-4)
    plain = client.get("/api/v1/sites/tehuantepec/energy",
                       params={**params, "interval": "day"}).json()
    assert "twin_weather_wh" not in plain["rows"][0]["arrays"]["tracker"]


def test_the_energy_under_the_measured_sky_computes_a_month_without_a_token(
        client: httpx.Client, live_server: LiveServer) -> None:
    """``energy?source=twin_weather`` diagnoses the days it sums: without a token, as the
    diagnosis itself, at most 31 days not diagnosed yet (a 422 naming ``end``), so that no
    anonymous request costs a year of diagnosis; with a token the same range is served,
    and then, its days diagnosed, without one too."""
    params = {"start": "2022-02-01", "end": "2022-03-15", "interval": "day",
              "source": "twin_weather"}
    url = "/api/v1/sites/tehuantepec/energy"
    refused = client.get(url, params=params)
    assert refused.status_code == 422 and "end" in refused.text and "31" in refused.text
    served = client.get(url, params=params,
                        headers={"Authorization": f"Bearer {live_server.write_token}"})
    assert served.status_code == 200, served.text
    assert len(served.json()["rows"]) == 42
    again = client.get(url, params=params)  # the same 42 days, now diagnosed: no cost
    assert again.status_code == 200, again.text
    assert again.json()["rows"] == served.json()["rows"]


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the twin, not storage
def test_both_arrays_asked_at_once_share_one_computation(
        client: httpx.Client, live_server: LiveServer, monkeypatch: pytest.MonkeyPatch) -> None:
    """The Overview asks for the tracker's and the fixed array's weather twin of a day at
    once (``frontend/js/overview.js``, ``weatherTwin``); both are columns of one
    :func:`sim.sky_sensor.weather_aware_twin` frame, which the second request now waits for
    instead of computing it again (before: two computations, two thirds of the served
    dashboard's busy time in the browser tests, py-spy). The first computation is held
    until the second request has arrived; the answers are those of a request alone."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from backend.diagnosis import weather_twin as wt
    from sim import sky_sensor

    arrived, computed = threading.Semaphore(0), []
    need_twin, twin = wt._need_twin, sky_sensor.weather_aware_twin

    def arriving(info):  # type: ignore[no-untyped-def]
        arrived.release()
        return need_twin(info)

    def held(*args, **kwargs):  # type: ignore[no-untyped-def]
        computed.append(1)
        if len(computed) == 1:  # the first: hold it until both requests are in
            assert arrived.acquire(timeout=30) and arrived.acquire(timeout=30)
            threading.Event().wait(0.2)  # the second from its arrival to the shared wait
        return twin(*args, **kwargs)

    monkeypatch.setattr(wt, "_need_twin", arriving)
    monkeypatch.setattr(sky_sensor, "weather_aware_twin", held)
    params = {"start": "2023-04-20", "end": "2023-04-21", "source": "twin_weather"}

    def get(array: str) -> httpx.Response:
        with live_server.client() as c:
            return c.get(PATH, params={**params, "array": array})

    with ThreadPoolExecutor(2) as pool:
        tracker, fixed = pool.map(get, ["tracker", "fixed"])
    assert tracker.status_code == fixed.status_code == 200, (tracker.text, fixed.text)
    assert len(computed) == 1
    monkeypatch.setattr(wt, "_need_twin", need_twin)
    monkeypatch.setattr(sky_sensor, "weather_aware_twin", twin)
    for array, shared in (("tracker", tracker), ("fixed", fixed)):
        alone = client.get(PATH, params={**params, "array": array})
        assert alone.json()["points"] == shared.json()["points"]
        assert alone.json()["sky"] == shared.json()["sky"]
    assert tracker.json()["points"] != fixed.json()["points"]
