"""Power-only readings and the optional sensor fields, over real HTTP on SQLite and
PostgreSQL (``backend/measurements/fields.py``; issues 13 and 14), and the migration
that made room for them.

Expected values are computed here from the readings sent (NumPy), never read back
from the service's own aggregates.
"""

from __future__ import annotations

import datetime as dt
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest
from live_service import new_database
from sqlalchemy import text
from test_measurements_api import PATH, TZ, post

from backend.settings import get_settings
from backend.storage.engine import alembic_config, make_engine

if TYPE_CHECKING:
    from live_service import LiveServer


def _bell(day: dt.date, array: str, step_min: int = 1) -> tuple[list[dict], np.ndarray,
                                                                  np.ndarray]:
    """Power-only minute readings of a local day: readings, Unix seconds, power [W]."""
    t0 = dt.datetime(day.year, day.month, day.day, tzinfo=TZ)
    out, ts, pw = [], [], []
    for m in range(0, 24 * 60, step_min):
        h = m / 60.0
        s = math.sin(math.pi * (h - 6.5) / 12.0) if 6.5 < h < 18.5 else 0.0
        p = round(650.0 * s**1.3 + 0.01 * (m % 13), 3)
        t = t0 + dt.timedelta(minutes=m)
        out.append({"ts": t.isoformat(), "array": array, "power_w": p})
        ts.append(t.timestamp())
        pw.append(p)
    return out, np.array(ts), np.array(pw)


def test_a_power_only_logger_posts_and_its_energy_rests_on_power(
        client: httpx.Client, live_server: LiveServer) -> None:
    readings, ts, pw = _bell(dt.date(2023, 2, 1), "fixed")
    r = post(client, live_server.write_token, {"readings": readings})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["accepted"] == 1440 and body["power_only"] == 1440
    assert "rests on the logger's power_w" in body["note"]

    got = client.get(PATH, params={"array": "fixed", "start": "2023-02-01",
                                   "end": "2023-02-02"}).json()["points"]
    assert len(got) == 1440
    assert all(p["voltage_v"] is None and p["current_a"] is None for p in got)
    assert [p["power_w"] for p in got] == pw.tolist()

    energy = client.get("/api/v1/sites/tehuantepec/energy", params={
        "start": "2023-02-01", "end": "2023-02-02", "interval": "day"}).json()
    wh = energy["rows"][0]["arrays"]["fixed"]["measured_wh"]
    assert wh == pytest.approx(float(np.trapezoid(pw, ts)) / 3600.0, rel=1e-9)

    hourly = client.get(PATH, params={"array": "fixed", "start": "2023-02-01",
                                      "end": "2023-02-02", "max_points": 24}).json()
    assert hourly["bucket_s"] == 3600 and len(hourly["points"]) == 24  # the rollups, as stored
    noon = hourly["points"][12]
    assert noon["voltage_v"] is None and noon["voltage_v_min"] is None
    assert noon["power_w"] == pytest.approx(pw[720:780].mean(), rel=1e-12)
    assert noon["power_w_max"] == pw[720:780].max()


def test_bucket_means_of_mixed_readings_count_only_readings_with_the_value(
        client: httpx.Client, live_server: LiveServer) -> None:
    """One hour, every other minute power-only: the mean voltage is over the 30 readings
    with a voltage, not over all 60; a sensor mean over the readings that carried it."""
    t0 = dt.datetime(2023, 2, 13, 12, tzinfo=TZ)  # a day no other test posts to
    rows, volts, poa = [], [], []
    for m in range(60):
        t = (t0 + dt.timedelta(minutes=m)).isoformat()
        if m % 2:
            rows.append({"ts": t, "array": "tracker", "power_w": 500.0 + m})
        else:
            v = 30.0 + m / 10
            volts.append(v)
            rows.append({"ts": t, "array": "tracker", "voltage_v": v, "current_a": 10.0})
        if m % 3 == 0:
            rows[-1]["poa_irradiance_w_m2"] = 900.0 + m
            poa.append(900.0 + m)
    r = post(client, live_server.write_token, {"readings": rows})
    assert r.status_code == 200 and r.json()["power_only"] == 30
    day: dict[str, Any] = {"array": "tracker", "start": "2023-02-13T00:00:00-06:00",
                           "end": "2023-02-14T00:00:00-06:00", "max_points": 13}
    (hour,) = [p for p in client.get(PATH, params=day).json()["points"] if p["n"]]
    assert hour["n"] == 60  # a 2-hour bucket of the rollups
    assert hour["voltage_v"] == pytest.approx(np.mean(volts), rel=1e-12)
    assert hour["voltage_v_min"] == min(volts) and hour["voltage_v_max"] == max(volts)
    assert hour["poa_irradiance_w_m2"] == pytest.approx(np.mean(poa), rel=1e-12)
    assert "ghi_w_m2" not in hour  # no reading carried it
    # 4-minute buckets grouped from the raw rows: two readings with a voltage in each
    hours: dict[str, Any] = {"array": "tracker", "start": t0.isoformat(),
                             "end": (t0 + dt.timedelta(hours=1)).isoformat(), "max_points": 15}
    got = client.get(PATH, params=hours).json()
    assert got["bucket_s"] == 240 and [p["n"] for p in got["points"]] == [4] * 15
    assert [p["voltage_v"] for p in got["points"]] == pytest.approx(
        [np.mean(volts[2 * k:2 * k + 2]) for k in range(15)], rel=1e-12)


def test_sensor_fields_over_json_and_csv_are_stored_as_sent(
        client: httpx.Client, live_server: LiveServer) -> None:
    t = dt.datetime(2023, 2, 5, 11, tzinfo=TZ)
    r = post(client, live_server.write_token, {"readings": [{
        "ts": t.isoformat(), "array": "tracker", "voltage_v": 30.0, "current_a": 10.0,
        "poa_irradiance_w_m2": 870.5, "ghi_w_m2": 610.0, "temp_module_c": 47.25,
        "temp_air_c": 29.0, "azimuth_deg": -170.0, "elevation_deg": 61.5,
        "wind_speed_m_s": 3.4}]})
    assert r.status_code == 200, r.text
    assert "power_only" not in r.json()
    csv_body = ("ts,array,power_w,temp_air_c,elevation_deg,wind_speed_m_s\n"
                f"{(t + dt.timedelta(minutes=1)).isoformat()},tracker,250.5,29.5,,0.8\n")
    assert post(client, live_server.write_token, csv_body).status_code == 200
    got = client.get(PATH, params={"array": "tracker", "start": t.isoformat(),
                                   "end": (t + dt.timedelta(minutes=2)).isoformat()}).json()
    a, b = got["points"]
    assert (a["poa_irradiance_w_m2"], a["ghi_w_m2"], a["temp_module_c"], a["temp_air_c"],
            a["elevation_deg"], a["wind_speed_m_s"]) == (870.5, 610.0, 47.25, 29.0, 61.5, 3.4)
    assert a["azimuth_deg"] == pytest.approx(190.0)  # −170° clockwise from north
    assert (b["voltage_v"], b["power_w"], b["temp_air_c"], b["poa_irradiance_w_m2"],
            b["elevation_deg"], b["wind_speed_m_s"]) == (None, 250.5, 29.5, None, None, 0.8)
    as_csv = client.get(PATH, params={"array": "tracker", "start": t.isoformat(),
                                      "end": (t + dt.timedelta(minutes=2)).isoformat(),
                                      "format": "csv"}).text.splitlines()
    header = as_csv[0].split(",")
    assert "poa_irradiance_w_m2" in header
    second = dict(zip(header, as_csv[2].split(","), strict=True))
    assert second["voltage_v"] == "" and second["power_w"] == "250.5"
    assert second["wind_speed_m_s"] == "0.8"


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # a schema, not storage
def test_the_readings_schema_lists_every_sensor_field_with_its_range(
        client: httpx.Client) -> None:
    """The OpenAPI schema of a reading shows each optional sensor field (one list:
    ``SENSOR_FIELDS``) with its bounds, the wind speed of issue 27 among them."""
    from backend.measurements.fields import SENSOR_FIELDS

    ops = client.get("/openapi.json").json()["paths"]["/api/v1/sites/{site_id}/measurements"]
    readings = ops["post"]["requestBody"]["content"]["application/json"]["schema"]["oneOf"][0]
    props = readings["properties"]["readings"]["items"]["properties"]
    for f in SENSOR_FIELDS:
        number = next(x for x in props[f.name]["anyOf"] if x.get("type") == "number")
        assert (number["minimum"], number["maximum"]) == (f.low, f.high), f.name
    assert props["wind_speed_m_s"]["anyOf"][0]["maximum"] == 113.3


def test_emoncms_rows_with_null_voltage_are_power_only(
        client: httpx.Client, live_server: LiveServer) -> None:
    t = int(dt.datetime(2023, 2, 6, 12, tzinfo=TZ).timestamp())
    r = post(client, live_server.write_token, [[t, "fixed", None, None, 123.0],
                                               [t + 60, "fixed", 25.0, 4.0, 100.0]])
    assert r.status_code == 200 and r.json()["power_only"] == 1


@pytest.mark.parametrize(("reading", "field", "words"), [
    ({"voltage_v": 30.0}, "current_a", "current_a is missing"),
    ({"current_a": 3.0, "power_w": 90.0}, "voltage_v", "voltage_v is missing"),
    ({"power_w": 2.0e6}, "power_w", "outside"),
    ({"power_w": 10.0, "poa_irradiance_w_m2": 2500.0}, "poa_irradiance_w_m2", "outside"),
    ({"power_w": 10.0, "elevation_deg": 95.0}, "elevation_deg", "outside"),
    ({"power_w": 10.0, "temp_module_c": "hot"}, "temp_module_c", "not a number"),
    ({"power_w": 10.0, "wind_speed_m_s": -1.5}, "wind_speed_m_s", "outside"),
    ({"power_w": 10.0, "wind_speed_m_s": 120.0}, "wind_speed_m_s", "outside"),
])
def test_bad_power_only_and_sensor_values_name_the_field(
        client: httpx.Client, live_server: LiveServer, reading: dict, field: str,
        words: str) -> None:
    body = {"readings": [{"ts": "2023-02-07T12:00:00Z", "array": "fixed", **reading}]}
    r = post(client, live_server.write_token, body)
    assert r.status_code == 422, r.text
    (err,) = r.json()["detail"]
    assert err["field"] == field and words in err["msg"], err


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_migration_0006_keeps_stored_readings_and_rollups(backend: str, tmp_path: Path) -> None:
    """A database at 0005 with readings and rollups (one an energy-only bucket with the
    ±inf extremes 0005 wrote) upgrades with every value kept (0006's and 0011's rollup
    sums and counts of the sensor fields 0 for the hours stored before)."""
    from alembic import command

    db = new_database(backend, tmp_path)
    engine = make_engine(get_settings(database_url=db.url))
    cfg = alembic_config(engine)
    try:
        with engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "0005_diagnosis")
            conn.execute(text(
                "INSERT INTO sites VALUES ('s', 'S', 0, 0, 0, 'UTC', 0, '{}', "
                "'2026-01-01T00:00:00+00:00')"))
            conn.execute(text(
                "INSERT INTO arrays (id, site_id, name, kind, config_json, adc_bits, adc_vref_v, "
                "current_zero_v, current_sensitivity_mv_per_a, divider_ratio) "
                "VALUES (1, 's', 'fixed', 'fixed', '{}', 10, 5, 2.5, 100, 10)"))
            conn.execute(text("INSERT INTO measurements VALUES (1, 0, 3600, 25.0, 4.0, 100.0)"))
            conn.execute(text(
                "INSERT INTO measurement_rollups VALUES (1, 0, 3600, 1, 0.5, 25, 4, 100, "
                "25, 4, 100, 25, 4, 100, 3600, 3600), (1, 0, 7200, 0, 0.25, 0, 0, 0, "
                ":inf, :inf, :inf, :ninf, :ninf, :ninf, 4611686018427387904, "
                "-4611686018427387904)"), {"inf": math.inf, "ninf": -math.inf})
        with engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "heads")
            m = conn.execute(text("SELECT ts_s, voltage_v, current_a, power_w, azimuth_deg "
                                  "FROM measurements")).all()
            r = conn.execute(text("SELECT bucket_s, n, energy_wh, min_voltage_v, max_power_w, "
                                  "n_vi, sum_ghi_w_m2, n_ghi_w_m2, sum_wind_speed_m_s, "
                                  "n_wind_speed_m_s FROM measurement_rollups "
                                  "ORDER BY bucket_s")).all()
        assert [tuple(x) for x in m] == [(3600, 25.0, 4.0, 100.0, None)]
        assert [tuple(x) for x in r] == [(3600, 1, 0.5, 25.0, 100.0, 1, 0.0, 0, 0.0, 0),
                                         (7200, 0, 0.25, None, None, 0, 0.0, 0, 0.0, 0)]
        if backend == "sqlite":  # still clustered on the primary key
            with engine.connect() as conn:
                ddl = conn.execute(text("SELECT sql FROM sqlite_master WHERE name IN "
                                        "('measurements', 'measurement_rollups')")).scalars()
                assert all("WITHOUT ROWID" in d for d in ddl)
    finally:
        engine.dispose()
        db.drop()
