"""Sun offsets in, the pointing model and its command out, over HTTP in process (issue 25).

The readings come from a misaligned mount built here from scipy's Rotation (issue 25's
R = R_y(t_east)·R_x(−t_north), pose Rz(−az)·Rx(el)), not from sim/pointing_model.py;
the sun is SPA's apparent position with the site's pressure and air temperature.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from typing import TYPE_CHECKING

import httpx
import numpy as np
import pandas as pd
import pytest
from pvlib import atmosphere
from scipy.spatial.transform import Rotation
from test_measurements_api import PATH, TZ, post

from sim.sites import load_site
from sim.sun import solar_position
from vision.sphere import enu_from_sky

if TYPE_CHECKING:
    from live_service import LiveServer

MODEL = "/api/v1/sites/tehuantepec/pointing-model"
SITE = load_site("tehuantepec")
TRUE = {"azimuth_zero_deg": -1.1, "elevation_zero_deg": 0.7,
        "pedestal_tilt_north_deg": -1.4, "pedestal_tilt_east_deg": 0.9}
DAY = dt.date(2021, 10, 5)


def _sun(times: pd.DatetimeIndex) -> tuple[np.ndarray, np.ndarray]:
    s = solar_position(times, SITE.latitude, SITE.longitude, SITE.altitude,
                       float(atmosphere.alt2pres(SITE.altitude)), SITE.temp_air)
    return s["azimuth"].to_numpy(), s["apparent_elevation"].to_numpy()


def _normal(az_enc: np.ndarray, el_enc: np.ndarray) -> Rotation:
    mount = Rotation.from_euler("xy", [-TRUE["pedestal_tilt_north_deg"],
                                       TRUE["pedestal_tilt_east_deg"]], degrees=True)
    pose = Rotation.from_euler("xz", np.stack([el_enc + TRUE["elevation_zero_deg"],
                                               -(az_enc + TRUE["azimuth_zero_deg"])], axis=1),
                               degrees=True)
    return mount * pose


def _day_readings() -> list[dict]:
    """Every other minute of DAY with the sun above 5°: open loop on SPA, 0.3 mrad noise."""
    rng = np.random.default_rng(7)
    t0 = dt.datetime(DAY.year, DAY.month, DAY.day, tzinfo=TZ)
    times = pd.DatetimeIndex([t0 + dt.timedelta(minutes=m) for m in range(0, 1440, 2)])
    az, el = _sun(times)
    up = el > 5.0
    times, az, el = times[up], az[up], el[up]
    r = _normal(az, el)
    s = enu_from_sky(az, el)
    h, n, u = (r.apply(v) for v in np.eye(3))
    dot = lambda a, b: np.einsum("ij,ij->i", a, b)  # noqa: E731
    ox = 1000 * np.arctan2(dot(s, h), dot(s, n)) + rng.normal(0, 0.3, az.size)
    oy = 1000 * np.arctan2(dot(s, u), dot(s, n)) + rng.normal(0, 0.3, az.size)
    return [{"ts": t.isoformat(), "array": "tracker", "power_w": 500.0,
             "azimuth_deg": round(float(a), 6), "elevation_deg": round(float(e), 6),
             "sun_offset_x_mrad": round(float(x), 4), "sun_offset_y_mrad": round(float(y), 4)}
            for t, a, e, x, y in zip(times, az, el, ox, oy, strict=True)]


@pytest.fixture(scope="module")
def posted_day(client_module: httpx.Client, live_server: LiveServer) -> list[dict]:
    readings = _day_readings()
    r = post(client_module, live_server.write_token, {"readings": readings})
    assert r.status_code == 200, r.text
    assert r.json()["accepted"] == len(readings)
    return readings


@pytest.fixture(scope="module")
def client_module(live_server: LiveServer) -> Iterator[httpx.Client]:
    with live_server.client() as c:
        yield c


def test_offsets_post_store_and_read_back(client: httpx.Client, live_server: LiveServer,
                                          posted_day: list[dict]) -> None:
    got = client.get(PATH, params={"array": "tracker", "start": DAY.isoformat(),
                                   "end": (DAY + dt.timedelta(days=1)).isoformat(),
                                   "max_points": 5000}).json()["points"]
    assert [p["sun_offset_x_mrad"] for p in got] == [p["sun_offset_x_mrad"] for p in posted_day]
    assert [p["sun_offset_y_mrad"] for p in got] == [p["sun_offset_y_mrad"] for p in posted_day]
    csv = ("ts,array,power_w,sun_offset_x_mrad,sun_offset_y_mrad\n"
           "2021-10-07T12:00:00-06:00,tracker,400,12.5,-3.25\n")
    assert post(client, live_server.write_token, csv).status_code == 200
    row = client.get(PATH, params={"array": "tracker", "start": "2021-10-07T12:00:00-06:00",
                                   "end": "2021-10-07T12:01:00-06:00"}).json()["points"]
    assert (row[0]["sun_offset_x_mrad"], row[0]["sun_offset_y_mrad"]) == (12.5, -3.25)


@pytest.mark.parametrize(("field", "value"), [("sun_offset_x_mrad", 600.0),
                                              ("sun_offset_y_mrad", -470.0)])
def test_an_offset_outside_the_cameras_field_is_refused(
        client: httpx.Client, live_server: LiveServer, field: str, value: float) -> None:
    body = {"readings": [{"ts": "2021-10-08T12:00:00-06:00", "array": "tracker",
                          "power_w": 400.0, field: value}]}
    r = post(client, live_server.write_token, body)
    assert 400 <= r.status_code < 500
    assert field in r.text


def test_the_model_recovers_the_mount_and_its_command_holds_the_sun(
        client: httpx.Client, posted_day: list[dict]) -> None:
    rng = {"start": DAY.isoformat(), "end": (DAY + dt.timedelta(days=1)).isoformat()}
    r = client.get(MODEL, params=rng)
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["site_id"] == "tehuantepec"
    assert body["n_observations"] == len(posted_day) and body["n_outliers"] == 0
    assert body["residual_rms_mrad"] == pytest.approx(0.3, rel=0.2)
    for name, value in TRUE.items():
        assert body["terms"][name]["value"] == pytest.approx(value, abs=0.01), name
        assert 0 < body["terms"][name]["std"] < 0.01
    assert set(TRUE) <= set(body["identifiable"])

    when = "2021-10-06T10:17:00-06:00"
    r = client.get(f"{MODEL}/command", params={**rng, "time": when})
    assert r.status_code == 200, r.text
    cmd = r.json()
    az, el = _sun(pd.DatetimeIndex([pd.Timestamp(when)]))
    assert (cmd["sun_azimuth_deg"], cmd["sun_elevation_deg"]) == pytest.approx((az[0], el[0]))

    def miss_mrad(az_cmd: float, el_cmd: float) -> float:
        n = _normal(np.array([az_cmd]), np.array([el_cmd])).apply([0.0, 1.0, 0.0])
        return 1000 * float(np.arccos(min(1.0, float(n[0] @ enu_from_sky(az[0], el[0])))))

    assert miss_mrad(cmd["azimuth_deg"], cmd["elevation_deg"]) < 0.3
    assert miss_mrad(az[0], el[0]) > 10.0  # the plain open loop on SPA


def test_too_few_observations_and_a_naive_time_are_422s(client: httpx.Client) -> None:
    r = client.get(MODEL, params={"start": "2021-11-01", "end": "2021-11-02"})
    assert r.status_code == 422
    assert "0 observations with sun offsets" in r.text and "at least" in r.text
    r = client.get(f"{MODEL}/command", params={"start": "2021-10-05", "end": "2021-10-06",
                                               "time": "2021-10-06T10:00:00"})
    assert r.status_code == 422 and "time" in r.text


def test_a_range_over_the_bound_is_refused_before_it_is_read(client: httpx.Client) -> None:
    """An anonymous read is bounded: 1990–2100 is a 422 naming end, not a scan of it all."""
    r = client.get(MODEL, params={"start": "1990-01-01", "end": "2100-01-01"})
    assert r.status_code == 422 and "end" in r.text and "400 days" in r.text
