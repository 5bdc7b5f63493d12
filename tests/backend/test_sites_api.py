"""Sites you define, over HTTP (``PUT /api/v1/sites/{site_id}``, issue 14 item 8).

A service of its own (in this process, ``live_service.InProcessServer``), with a temporary
``HELIOTWIN_SITES_DIR`` and an admin token, on a real SQLite file and a PostgreSQL schema.
The twin energies after an edit are checked against the twin run by this test through
``sim.twin.simulate``, integrated with NumPy.
"""

from __future__ import annotations

import datetime as dt
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from zoneinfo import ZoneInfo

import httpx
import numpy as np
import pandas as pd
import pytest
from live_service import BACKENDS, ROOT, InProcessServer, new_database

ADMIN = "admin-secret-for-tests"
TZ = ZoneInfo("America/Mexico_City")
HAND_WRITTEN = {  # written from docs/site.schema.json: the required keys and two arrays
    "$schema": "https://heliotwin.example/docs/site.schema.json",
    "site_id": "my-roof", "name": "My roof, Greensboro NC",
    "latitude_deg": 36.1, "longitude_deg": -79.95, "altitude_m": 273,
    "timezone": "America/New_York",
    "arrays": {"tracker": {"mount": "tracker", "strings_in_parallel": 2},
               "fixed": {"mount": "fixed", "surface_tilt_deg": 36, "strings_in_parallel": 2}},
}


@pytest.fixture(scope="module", params=BACKENDS)
def server(request: pytest.FixtureRequest,
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    tmp = tmp_path_factory.mktemp("sites-api")
    db = new_database(request.param, tmp)
    proc = InProcessServer(db.url, extra_env={
        "HELIOTWIN_SITES_DIR": str(tmp / "user-sites"), "HELIOTWIN_ADMIN_TOKEN": ADMIN})
    proc.start()
    try:
        yield proc
    finally:
        proc.stop()
        db.drop()


@pytest.fixture()
def client(server: InProcessServer) -> Iterator[httpx.Client]:
    with server.client(timeout_s=120) as c:
        yield c


@pytest.fixture()
def my_roof(client: httpx.Client) -> str:
    """The hand-written site, made if this test is the first to need it (each test stands
    alone: run in any order, none relies on another having made its site)."""
    r = client.put("/api/v1/sites/my-roof", json=HAND_WRITTEN, headers=bearer(ADMIN))
    assert r.status_code in (200, 201), r.text
    return "my-roof"


def _sites_dir(server: InProcessServer) -> Path:
    return Path(server.extra_env["HELIOTWIN_SITES_DIR"])


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def test_the_schema_endpoint_serves_the_shipped_schema(client: httpx.Client) -> None:
    r = client.get("/api/v1/sites/schema.json")
    assert r.status_code == 200
    assert r.json() == json.loads((ROOT / "docs" / "site.schema.json").read_text())


def test_creating_a_site_needs_the_admin_token(client: httpx.Client,
                                               server: InProcessServer) -> None:
    url = "/api/v1/sites/new-roof"
    body = {**HAND_WRITTEN, "site_id": "new-roof"}
    r = client.put(url, json=body)
    assert r.status_code == 401 and "admin token" in r.json()["detail"]
    r = client.put(url, json=body, headers=bearer(server.token("tehuantepec")))
    assert r.status_code == 403 and "only the admin token" in r.json()["detail"]
    assert not (_sites_dir(server) / "new-roof.json").exists()
    before = {s["site_id"] for s in client.get("/api/v1/sites").json()}
    r = client.put(url, json=body, headers=bearer(ADMIN))
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["created"] and body["origin"] == "user" and not body["overrides_builtin"]
    assert body["arrays"]["fixed"]["surface_tilt_deg"] == 36.0
    ids = {s["site_id"] for s in client.get("/api/v1/sites").json()}
    assert ids == before | {"new-roof"}
    assert {"guadalajara_fisheye", "tehuantepec"} <= ids
    stored = json.loads((_sites_dir(server) / "new-roof.json").read_text())
    assert stored["latitude_deg"] == 36.1 and "$schema" not in stored
    r = client.put(url, json={**HAND_WRITTEN, "site_id": "new-roof"}, headers=bearer(ADMIN))
    assert r.status_code == 200 and not r.json()["created"]  # a second PUT replaces it


def test_the_new_site_takes_readings_and_has_a_twin(client: httpx.Client,
                                                    server: InProcessServer,
                                                    my_roof: str) -> None:
    token = server.token("my-roof")  # the CLI knows the site once the service made it
    day = dt.date.today() - dt.timedelta(days=3)
    ts = dt.datetime(day.year, day.month, day.day, 12, tzinfo=ZoneInfo("America/New_York"))
    r = client.post("/api/v1/sites/my-roof/measurements", headers=bearer(token), json={
        "readings": [{"ts": (ts + dt.timedelta(minutes=k)).isoformat(), "array": a,
                      "voltage_v": 30.0, "current_a": 10.0} for k in range(5)
                     for a in ("tracker", "fixed")]})
    assert r.status_code == 200 and r.json()["accepted"] == 10, r.text
    e = client.get("/api/v1/sites/my-roof/energy", params={
        "start": day.isoformat(), "end": (day + dt.timedelta(days=1)).isoformat()}).json()
    row = e["rows"][0]
    assert row["arrays"]["tracker"]["twin_wh"] > row["arrays"]["fixed"]["twin_wh"] > 0
    assert row["partial"] is True  # five minutes of a day


def test_a_site_whose_arrays_the_twin_does_not_know_stores_readings_but_has_no_diagnosis(
        client: httpx.Client, server: InProcessServer) -> None:
    """Arrays named otherwise than ``tracker`` and ``fixed`` take readings and energies,
    but the twin does not simulate them: the diagnosis and the weather-aware twin answer a
    422 naming the arrays it needs (a KeyError in the sky's inversion, a 500, before)."""
    config = {**HAND_WRITTEN, "site_id": "named-arrays",
              "arrays": {"trk": {"mount": "tracker"},
                         "ref": {"mount": "fixed", "surface_tilt_deg": 36}}}
    r = client.put("/api/v1/sites/named-arrays", json=config, headers=bearer(ADMIN))
    assert r.status_code == 201, r.text
    day = dt.date.today() - dt.timedelta(days=3)
    ts = dt.datetime(day.year, day.month, day.day, 12, tzinfo=ZoneInfo("America/New_York"))
    r = client.post("/api/v1/sites/named-arrays/measurements",
                    headers=bearer(server.token("named-arrays")), json={
                        "readings": [{"ts": (ts + dt.timedelta(minutes=k)).isoformat(),
                                      "array": a, "voltage_v": 30.0, "current_a": 10.0}
                                     for k in range(5) for a in ("trk", "ref")]})
    assert r.status_code == 200 and r.json()["accepted"] == 10, r.text
    span = {"start": day.isoformat(), "end": (day + dt.timedelta(days=1)).isoformat()}
    r = client.get("/api/v1/sites/named-arrays/energy", params=span)
    assert r.status_code == 200 and r.json()["totals"]["arrays"]["trk"]["measured_wh"] > 0
    r = client.get("/api/v1/sites/named-arrays/diagnosis", params=span)
    assert r.status_code == 422 and "named 'tracker'" in r.json()["detail"], r.text
    r = client.get("/api/v1/sites/named-arrays/energy", params={**span,
                                                                "source": "twin_weather"})
    assert r.status_code == 422 and "source:" in r.json()["detail"], r.text


@pytest.mark.parametrize(("change", "words"), [
    ({"latitude_deg": 136.1}, "body: latitude_deg: Input should be less than or equal to 90"),
    ({"arrays": {"fixed": {"surface_tilt_deg": 36, "tilt": 3}}}, "arrays.fixed.tilt: unknown key"),
    ({"timezone": "Eastern"}, "timezone: 'Eastern' is not an IANA time zone"),
    ({"timezone": "localtime"}, "timezone: 'localtime' is not an IANA time zone"),
    ({"site_id": "other"}, "site_id: 'other' does not match the path's 'my-roof'"),
    # PostgreSQL refused the NUL with a 500 after the file was written: the service then
    # could not start
    ({"name": "my\u0000roof"}, "body: name: holds a control character"),
    # a boolean is not a number: true moved a site to 1° (a tester's finding)
    ({"latitude_deg": True}, "body: latitude_deg: Input should be a valid number"),
    ({"temp_air_c": "25"}, "body: temp_air_c: Input should be a valid number"),
    # not an object: place_defaults' dict() of it answered 500 (adversary, session 27)
    ({"assumed": "by hand"}, "body: assumed: Input should be a valid dictionary"),
    ({"assumed": ["altitude_m"]}, "body: assumed: Input should be a valid dictionary"),
    # a 422 echoes at most 200 characters of a key or message: the zone of 1 MB came back whole
    ({"timezone": "x" * 1_000_000}, "body: timezone: 'xxxx"),
    ({"arrays": {"fixed": {"surface_tilt_deg": 36, "t" * 1_000_000: 3}}}, "arrays.fixed.ttt"),
])
def test_a_malformed_site_is_a_422_naming_the_field(client: httpx.Client, server: InProcessServer,
                                                    my_roof: str, change: dict,
                                                    words: str) -> None:
    before = (_sites_dir(server) / "my-roof.json").read_text()
    r = client.put("/api/v1/sites/my-roof", json={**HAND_WRITTEN, **change}, headers=bearer(ADMIN))
    assert r.status_code == 422
    assert words in r.json()["detail"] and len(r.content) < 2_000, r.text[:500]
    assert (_sites_dir(server) / "my-roof.json").read_text() == before  # nothing written


def _twin_day_wh(site_config: dict, day: dt.date) -> dict[str, float]:
    """The clear-sky twin of one local day, run here and integrated with numpy.trapezoid."""
    from sim.sites import site_from_dict
    from sim.twin import simulate

    site = site_from_dict(site_config)
    t0 = pd.Timestamp(day.isoformat(), tz=site.timezone)
    series = simulate(site, t0, t0 + pd.Timedelta(days=1), step_s=60).series
    t = series.index.as_unit("s").asi8.astype(float)
    return {a: float(np.trapezoid(series[f"{a}_power_w"].to_numpy(), t)) / 3600
            for a in ("tracker", "fixed")}


def test_editing_a_site_drops_its_cached_twin(client: httpx.Client,
                                              server: InProcessServer) -> None:
    day = dt.datetime.now(TZ).date() - dt.timedelta(days=5)
    params = {"start": day.isoformat(), "end": (day + dt.timedelta(days=1)).isoformat()}
    url = "/api/v1/sites/tehuantepec"
    before = client.get(f"{url}/energy", params=params).json()["rows"][0]["arrays"]
    config = client.get(f"{url}/config").json()
    expected_before = _twin_day_wh(config, day)
    assert before["fixed"]["twin_wh"] == pytest.approx(expected_before["fixed"], rel=1e-6)
    config["arrays"]["fixed"]["surface_tilt_deg"] = 45.0  # from 16°: a winter tilt
    r = client.put(url, json=config, headers=bearer(server.token("tehuantepec", scope="site")))
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["twin_readings_dropped"] >= 2 * 1440  # the day read above, both arrays
    assert body["origin"] == "user" and body["overrides_builtin"] is True
    after = client.get(f"{url}/energy", params=params).json()["rows"][0]["arrays"]
    expected_after = _twin_day_wh(config, day)
    assert after["fixed"]["twin_wh"] == pytest.approx(expected_after["fixed"], rel=1e-6)
    assert abs(after["fixed"]["twin_wh"] / before["fixed"]["twin_wh"] - 1) > 0.05  # not the cache
    assert after["tracker"]["twin_wh"] == pytest.approx(before["tracker"]["twin_wh"], rel=1e-9)


def test_a_zone_on_another_hour_grid_is_refused(client: httpx.Client,
                                                server: InProcessServer) -> None:
    config = client.get("/api/v1/sites/tehuantepec/config").json()
    r = client.put("/api/v1/sites/tehuantepec", json={**config, "timezone": "Asia/Kolkata"},
                   headers=bearer(server.token("tehuantepec", scope="site")))
    assert r.status_code == 409 and "timezone" in r.json()["detail"]


def test_user_sites_are_there_after_a_restart_and_run_in_simulate(
        client: httpx.Client, server: InProcessServer, heliotwin_cli: Callable,
        my_roof: str) -> None:
    config = client.get("/api/v1/sites/tehuantepec/config").json()
    config["name"] = "Tehuantepec, renamed"  # a built-in site overridden
    r = client.put("/api/v1/sites/tehuantepec", json=config,
                   headers=bearer(server.token("tehuantepec", scope="site")))
    assert r.status_code == 200, r.text
    client.close()
    server.stop()
    server.start()
    with server.client(timeout_s=60) as c:
        sites = {s["site_id"]: s for s in c.get("/api/v1/sites").json()}
    assert {"my-roof", "tehuantepec", "guadalajara_fisheye"} <= set(sites)
    assert sites["tehuantepec"]["name"] == "Tehuantepec, renamed"
    assert sites["tehuantepec"]["origin"] == "user"
    assert sites["guadalajara_fisheye"]["origin"] == "builtin"
    run = heliotwin_cli("simulate", "--site", "my-roof", "--start", "2024-06-21", "--end",
                        "2024-06-22", "--step-s", "600", "--json", env=server.env)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["tracker_energy_wh"] > 0


def test_days_split_at_a_midnight_off_the_rollup_grid(client: httpx.Client,
                                                      server: InProcessServer) -> None:
    """Caracas was UTC−04:30 until 2016 and is −04:00 since: the hourly rollups are phased
    to today's offset, so a 2010 midnight cuts a rollup bucket. Readings at 100 W up to
    23:59 and 300 W from 00:00 to 01:00 (trapezoids: 59 minutes of 100 W, the minute to
    midnight at 200 W mean, then 60 minutes of 300 W). Before, the bucket was given whole
    to one day: 251.67 and 150 Wh."""
    body = {**HAND_WRITTEN, "site_id": "caracas", "name": "Caracas",
            "latitude_deg": 10.5, "longitude_deg": -66.9, "timezone": "America/Caracas"}
    r = client.put("/api/v1/sites/caracas", json=body, headers=bearer(ADMIN))
    assert r.status_code == 201, r.text
    zone = dt.timezone(-dt.timedelta(hours=4, minutes=30))
    t0 = dt.datetime(2010, 6, 1, 23, 0, tzinfo=zone)
    readings = [{"ts": (t0 + dt.timedelta(minutes=k)).isoformat(), "array": "fixed",
                 "power_w": 100.0 if k < 60 else 300.0} for k in range(121)]
    r = client.post("/api/v1/sites/caracas/measurements", json={"readings": readings},
                    headers=bearer(server.token("caracas")))
    assert r.status_code == 200 and r.json()["accepted"] == 121, r.text
    e = client.get("/api/v1/sites/caracas/energy", params={
        "start": "2010-06-01", "end": "2010-06-03", "interval": "day"}).json()
    got = [row["arrays"]["fixed"]["measured_wh"] for row in e["rows"]]
    assert got == pytest.approx([59 * 100 / 60 + 200 / 60, 300.0], rel=1e-9)
    hours = client.get("/api/v1/sites/caracas/energy", params={
        "start": "2010-06-01T23:00:00-04:30", "end": "2010-06-02T01:00:00-04:30",
        "interval": "hour"}).json()
    assert [row["arrays"]["fixed"]["measured_wh"] for row in hours["rows"]] == pytest.approx(
        [59 * 100 / 60 + 200 / 60, 300.0], rel=1e-9)


def test_a_zone_far_from_the_longitude_is_written_with_a_warning(client: httpx.Client) -> None:
    body = {**HAND_WRITTEN, "site_id": "far-zone", "timezone": "Asia/Tokyo"}
    r = client.put("/api/v1/sites/far-zone", json=body, headers=bearer(ADMIN))
    assert r.status_code == 201, r.text
    (warning,) = r.json()["warnings"]
    assert "timezone Asia/Tokyo UTC+9 h is" in warning and "-80.0° / 15 = -5.3 h" in warning
    r = client.put("/api/v1/sites/far-zone", json={**body, "timezone": "America/New_York"},
                   headers=bearer(ADMIN))
    assert r.status_code == 200 and r.json()["warnings"] == []
