"""Power-only loggers (issue 21, item 2): readings with ``power_w`` and no voltage/current.

Inverter and meter loggers report power alone, often every 5 minutes. Each way in is
checked end to end — JSON and CSV over HTTP (SQLite and PostgreSQL), the MQTT state
topic and a lone ``power`` value topic through the real Mosquitto — and so is what comes
out: null voltage and current (never NaN or 0), NaN-aware bucket means, the day's energy
in ``/energy`` and the overview's tiles (``/status``). Expected energies are NumPy's
trapezoid of the power posted, never the service's own aggregates.
"""

from __future__ import annotations

import datetime as dt
import json
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest
from live_service import InProcessServer, new_database
from sqlalchemy import create_engine, text
from test_measured_fields import _bell
from test_measurements_api import PATH, post
from test_mqtt import (
    HOST,
    PORT,
    SITE,
    WAIT_S,
    clear_retained,
    iso,
    meta,
    minute,
    mqtt_env,
    need_broker,
    publish,
    stored,
    wait_state,
)

if TYPE_CHECKING:
    from live_service import LiveServer

ENERGY = "/api/v1/sites/tehuantepec/energy"


def _day_energy_wh(client: httpx.Client, day: str, array: str) -> float:
    nxt = (dt.date.fromisoformat(day) + dt.timedelta(days=1)).isoformat()
    r = client.get(ENERGY, params={"start": day, "end": nxt, "interval": "day"})
    assert r.status_code == 200, r.text
    (row,) = r.json()["rows"]
    return float(row["arrays"][array]["measured_wh"])


def test_a_5_minute_power_only_day_over_json(client: httpx.Client,
                                            live_server: LiveServer) -> None:
    """An inverter's day every 5 minutes: stored with null V/I, buckets with null V/I
    means, and the day's energy the trapezoid of what was posted."""
    readings, ts, pw = _bell(dt.date(2023, 11, 14), "tracker", step_min=5)
    r = post(client, live_server.write_token, {"readings": readings})
    assert r.status_code == 200, r.text
    assert (r.json()["accepted"], r.json()["power_only"]) == (288, 288)
    day = {"array": "tracker", "start": "2023-11-14", "end": "2023-11-15"}
    raw = client.get(PATH, params=day).json()
    assert raw["bucket_s"] == 0 and len(raw["points"]) == 288
    assert {(p["voltage_v"], p["current_a"]) for p in raw["points"]} == {(None, None)}
    assert [p["power_w"] for p in raw["points"]] == pw.tolist()
    hourly = client.get(PATH, params={**day, "max_points": 24}).json()["points"]
    noon = hourly[12]
    assert (noon["voltage_v"], noon["current_a"], noon["voltage_v_max"]) == (None, None, None)
    assert noon["n"] == 12 and noon["power_w"] == pytest.approx(pw[144:156].mean(), rel=1e-12)
    expected_wh = float(np.trapezoid(pw, ts)) / 3600.0
    assert _day_energy_wh(client, "2023-11-14", "tracker") == pytest.approx(expected_wh,
                                                                           rel=1e-9)


def test_power_only_csv_with_or_without_the_voltage_columns(client: httpx.Client,
                                                           live_server: LiveServer) -> None:
    """CSV with only ``power_w``, and CSV whose voltage/current cells are empty on some
    rows (a logger that lost its voltage sensor at noon): both stored, energy by power."""
    readings, ts, pw = _bell(dt.date(2023, 11, 15), "fixed", step_min=5)
    csv = "ts,array,power_w\n" + "".join(f"{r['ts']},fixed,{r['power_w']}\n"
                                         for r in readings)
    r = post(client, live_server.write_token, csv)
    assert r.status_code == 200, r.text
    assert (r.json()["accepted"], r.json()["power_only"]) == (288, 288)
    assert _day_energy_wh(client, "2023-11-15", "fixed") == pytest.approx(
        float(np.trapezoid(pw, ts)) / 3600.0, rel=1e-9)

    readings, ts, pw = _bell(dt.date(2023, 11, 16), "fixed", step_min=5)
    lines = []
    for k, rd in enumerate(readings):
        p = rd["power_w"]
        vi = f"25,{p / 25!r}" if k < 144 else ","  # from noon: power alone
        lines.append(f"{rd['ts']},fixed,{vi},{p}\n")
    r = post(client, live_server.write_token, "ts,array,voltage_v,current_a,power_w\n"
             + "".join(lines))
    assert r.status_code == 200, r.text
    assert (r.json()["accepted"], r.json()["power_only"]) == (288, 144)
    points = client.get(PATH, params={"array": "fixed", "start": "2023-11-16",
                                      "end": "2023-11-17"}).json()["points"]
    assert [p["voltage_v"] for p in points] == [25.0] * 144 + [None] * 144
    assert _day_energy_wh(client, "2023-11-16", "fixed") == pytest.approx(
        float(np.trapezoid(pw, ts)) / 3600.0, rel=1e-9)


# ---------------------------------------------------------------- MQTT, real Mosquitto


@pytest.fixture
def mqtt_service(tmp_path: Path) -> Iterator[tuple[InProcessServer, str]]:
    """The service on the shared broker with its own topic prefix (not yet started)."""
    need_broker()
    prefix = f"htpo{uuid.uuid4().hex[:10]}"
    db = new_database("sqlite", tmp_path)
    try:
        yield InProcessServer(db.url, extra_env=mqtt_env(prefix, f"mqtt://{HOST}:{PORT}")), prefix
    finally:
        clear_retained(f"{prefix}/#", f"{prefix}_ha/#")


def _stored_rows(database_url: str, array: str) -> list[tuple[Any, ...]]:
    engine = create_engine(database_url)
    try:
        with engine.connect() as conn:
            return [tuple(r) for r in conn.execute(text(
                "SELECT m.ts_s, m.voltage_v, m.current_a, m.power_w FROM measurements m "
                "JOIN arrays a ON a.id = m.array_id "
                "WHERE a.site_id = :site AND a.name = :array AND m.source = 0 "
                "ORDER BY m.ts_s"), {"site": SITE, "array": array})]
    finally:
        engine.dispose()


def test_power_only_over_mqtt_state_and_value_topics(
        mqtt_service: tuple[InProcessServer, str]) -> None:
    """A state message with power alone is stored and is what the overview's tiles show; a
    lone ``power`` value closes as a power-only minute (after the grace, or at the latest
    at shutdown, which closes every open minute) instead of being refused for the voltage
    that never comes."""
    proc, prefix = mqtt_service
    t0 = minute(-20)
    with proc, proc.client(timeout_s=30.0) as c:
        wait_state(c, "connected")
        publish(f"{prefix}/{SITE}/fixed/state", json.dumps({"ts": iso(t0), "power_w": 287.5}))
        (p,) = stored(c, "fixed", iso(t0), iso(t0 + dt.timedelta(minutes=1)), 1)
        assert (p["voltage_v"], p["current_a"], p["power_w"]) == (None, None, 287.5)
        fixed = c.get(f"/api/v1/sites/{SITE}/status").json()["arrays"]["fixed"]
        assert (fixed["last_ts"], fixed["power_w"], fixed["voltage_v"]) == (iso(t0), 287.5,
                                                                            None)
        before = meta(c)["mqtt_status"]["received"]
        publish(f"{prefix}/{SITE}/tracker/power", "412.5")
        deadline = time.monotonic() + WAIT_S
        while meta(c)["mqtt_status"]["received"] == before:
            assert time.monotonic() < deadline, "the power value never arrived"
            time.sleep(0.2)
        sent_s = time.time()
    ((ts_s, volt, amp, power),) = _stored_rows(proc.database_url, "tracker")
    assert (volt, amp, power) == (None, None, 412.5)
    assert ts_s % 60 == 0 and sent_s - 120 < ts_s <= sent_s  # the minute it arrived in
