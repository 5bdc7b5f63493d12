"""Pointing error from the tracker's encoder angles over real HTTP
(``GET /api/v1/sites/{site_id}/pointing``, ``backend/diagnosis/pointing.py``).

The logger's angles are pvlib's own sun position (``pvlib.solarposition``, not the
service's ``sim.sun``) plus known offsets; the expected error is the angle between
the two unit vectors, computed here.
"""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING

import httpx
import numpy as np
import pandas as pd
import pytest
from pvlib import solarposition
from test_measurements_api import TZ, post

if TYPE_CHECKING:
    from live_service import LiveServer

DAY = dt.date(2023, 3, 10)
URL = "/api/v1/sites/tehuantepec/pointing"


def _unit(az_deg: np.ndarray, el_deg: np.ndarray) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1)


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the angles, not storage
def test_encoder_angles_give_the_pointing_error_of_every_sunlit_minute(
        client: httpx.Client, live_server: LiveServer) -> None:
    from sim.sites import load_site

    site = load_site("tehuantepec")
    t0 = pd.Timestamp(dt.datetime(DAY.year, DAY.month, DAY.day, tzinfo=TZ))
    times = pd.date_range(t0, periods=24 * 60, freq="1min")
    sun = solarposition.get_solarposition(times, site.latitude, site.longitude, site.altitude,
                                          temperature=site.temp_air)
    rng = np.random.default_rng(7)
    d_az = 3.0 + 0.2 * rng.standard_normal(times.size)  # a 3° azimuth lag with jitter
    d_el = -1.5 + 0.1 * rng.standard_normal(times.size)
    az = (sun["azimuth"].to_numpy() + d_az) % 360.0
    el = np.clip(sun["apparent_elevation"].to_numpy() + d_el, -5.0, 90.0)
    readings = [{"ts": t.isoformat(), "array": "tracker", "voltage_v": 30.0, "current_a": 5.0,
                 "azimuth_deg": round(float(a), 4), "elevation_deg": round(float(e), 4)}
                for t, a, e in zip(times, az, el, strict=True)]
    for k in range(0, len(readings), 7):  # some minutes without encoder angles
        del readings[k]["azimuth_deg"], readings[k]["elevation_deg"]
    assert post(client, live_server.write_token, {"readings": readings}).status_code == 200

    body = client.get(URL, params={"start": DAY.isoformat(),
                                   "end": (DAY + dt.timedelta(days=1)).isoformat()}).json()
    has = np.ones(times.size, bool)
    has[::7] = False
    up = sun["apparent_elevation"].to_numpy() > 0.0
    sel = has & up
    expected = np.degrees(np.arccos(np.clip(np.sum(
        _unit(az, el) * _unit(sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()),
        axis=-1), -1.0, 1.0)))[sel]
    assert body["array"] == "tracker" and body["minutes"] == int(sel.sum())
    assert body["points_step"] == 1 and len(body["points"]) == sel.sum()
    got = np.array([p["error_deg"] for p in body["points"]])
    # the service's SPA and pvlib's agree to ~0.001°; the readings are rounded to 1e-4°
    assert np.abs(got - expected).max() < 0.01
    s = body["summary"]
    assert s["rms_deg"] == pytest.approx(np.sqrt(np.mean(expected**2)), abs=0.005)
    assert s["max_deg"] == pytest.approx(expected.max(), abs=0.01)
    assert s["mean_azimuth_error_deg"] == pytest.approx(d_az[sel].mean(), abs=0.01)
    assert s["mean_elevation_error_deg"] == pytest.approx(
        (el - sun["apparent_elevation"].to_numpy())[sel].mean(), abs=0.01)
    (day,) = body["days"]
    assert day["date"] == DAY.isoformat() and day["minutes"] == sel.sum()

    night = client.get(URL, params={"start": f"{DAY}T00:00:00-06:00",
                                    "end": f"{DAY}T05:00:00-06:00"}).json()
    assert night["minutes"] == 0 and night["summary"] is None and night["points"] == []


def test_a_site_without_a_tracker_or_angles_says_so(client: httpx.Client) -> None:
    camera = client.get("/api/v1/sites/guadalajara_fisheye/pointing",
                        params={"start": "2023-03-10", "end": "2023-03-11"}).json()
    assert camera["array"] is None and camera["minutes"] == 0
    bad = client.get(URL, params={"start": "2023-03-11", "end": "2023-03-10"})
    assert bad.status_code == 422 and "end" in bad.text
