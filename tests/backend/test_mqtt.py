"""MQTT ingestion and Home Assistant discovery against a real Mosquitto and the service.

The service (in this process, ``live_service.InProcessServer``; MQTT on its own thread
as in ``heliotwin serve``) with ``HELIOTWIN_MQTT_URL`` set talks to the
Mosquitto at 127.0.0.1:1883 (``MQTT_TEST_URL`` to change it); the tests publish
and subscribe with paho-mqtt, as a field logger or Home Assistant would, and
read back over HTTP. Every run uses its own topic prefix (templates and
discovery prefix), so parallel runs on one broker do not see each other; the
retained messages it leaves are cleared at the end. The reconnection test runs
its own Mosquitto process on a free port, started after the service and killed
under it. Without a broker the tests skip, unless HELIOTWIN_REQUIRE_SERVICES=1.

The pure parts (topic templates, the per-minute assembly) are tested without a
broker at the top.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import json
import logging
import os
import shutil
import socket
import sqlite3
import subprocess
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx
import paho.mqtt.client as mqtt
import pytest
from live_service import (
    REQUIRE_SERVICES,
    InProcessServer,
    ServerProcess,
    free_port,
    new_database,
    tehuantepec_elsewhere,
)

from backend.measurements.parse import IngestError
from backend.mqtt.assemble import MinuteAssembler, parse_value
from backend.mqtt.service import OrderedAcks, check_no_echo
from backend.mqtt.topics import Template, Topics

BROKER = urlsplit(os.environ.get("MQTT_TEST_URL", "mqtt://127.0.0.1:1883"))
HOST, PORT = BROKER.hostname or "127.0.0.1", BROKER.port or 1883
SITE = "tehuantepec"
ADMIN = "mqtt-admin-token-for-tests"
WAIT_S = 30.0  # how long a test waits for something to arrive (not a speed check)


# ---------------------------------------------------------------- pure parts


def test_templates_match_filter_and_format() -> None:
    t = Template.parse("solar/{site_id}/{array}/{quantity}", ("site_id", "array", "quantity"))
    assert t.match("solar/tehuantepec/fixed/power") == {
        "site_id": "tehuantepec", "array": "fixed", "quantity": "power"}
    assert t.match("solar/tehuantepec/fixed") is None
    assert t.match("other/tehuantepec/fixed/power") is None
    assert t.filter(quantity="voltage") == "solar/+/+/voltage"
    assert t.format(site_id="a", array="b", quantity="c") == "solar/a/b/c"
    with pytest.raises(ValueError, match="cannot be an MQTT topic level"):
        t.format(site_id="a/b", array="b", quantity="c")
    with pytest.raises(ValueError, match="whole level"):
        Template.parse("x/site-{site_id}/{array}", ("site_id", "array"))
    with pytest.raises(ValueError, match="HELIOTWIN_MQTT_STATE_TOPIC"):
        Topics.from_settings("x/{site_id}/state", "x/{site_id}/{array}/{quantity}",
                             "x/{site_id}/errors", "x/{site_id}/{array}/{sensor}", "ha")


def test_published_topics_never_come_back_as_readings() -> None:
    ok = Topics.from_settings("h/{site_id}/{array}/state", "h/{site_id}/{array}/{quantity}",
                              "h/{site_id}/errors", "h/{site_id}/{array}/ha/{sensor}", "ha")
    check_no_echo(ok)
    echo = Topics.from_settings("h/{site_id}/{array}/state", "h/{site_id}/{array}/{quantity}",
                                "h/{site_id}/errors", "h/{site_id}/{array}/{sensor}", "ha")
    with pytest.raises(ValueError, match="HELIOTWIN_MQTT_HA_STATE_TOPIC"):
        check_no_echo(echo)  # the HA "power" state would be read as a single value


def test_single_values_are_assembled_per_minute() -> None:
    a = MinuteAssembler(grace_s=5.0)
    t = 1_710_525_600.0  # a minute start
    assert a.add("s", "fixed", "voltage", 25.0, "v", t + 1) == []
    assert a.add("s", "fixed", "voltage", 25.5, "v", t + 1.05) == []  # a later sample
    assert a.add("s", "fixed", "current", 2.0, "c", t + 1.1) == []
    closed = a.add("s", "fixed", "power", 50.0, "p", t + 1.2)  # complete: closes at once
    assert len(closed) == 1 and closed[0].minute_s == int(t) and not closed[0].missing
    assert closed[0].values == {"voltage_v": 25.0, "current_a": 2.0, "power_w": 50.0}
    assert a.add("s", "fixed", "voltage", 26.0, "v", t + 30) == []  # same minute: superseded
    assert a.superseded == 2  # the first value of each quantity is kept, open or closed
    # voltage and current only: closes after the grace, power left to the ingest rule
    a.add("s", "fixed", "voltage", 25.0, "v", t + 61)
    a.add("s", "fixed", "current", 2.0, "c", t + 62)
    assert a.due(t + 124) == []
    (late,) = a.due(t + 125)
    assert late.minute_s == int(t) + 60 and late.values == {"voltage_v": 25.0, "current_a": 2.0}
    assert not late.missing
    # voltage alone, then a value of the next minute: the first closes incomplete
    a.add("s", "fixed", "voltage", 25.0, "v", t + 121)
    (incomplete,) = a.add("s", "fixed", "power", 10.0, "p", t + 185)
    assert incomplete.missing == ["current"]
    assert [c.minute_s for c in a.flush()] == [int(t) + 180]
    # power alone (a meter, an inverter): after the grace a power-only reading
    a.add("s", "fixed", "power", 80.0, "p", t + 241)
    (power_only,) = a.due(t + 305)
    assert power_only.values == {"power_w": 80.0} and not power_only.missing


def test_acknowledgements_go_out_in_the_order_the_messages_came() -> None:
    sent: list[tuple[int, int]] = []
    acks = OrderedAcks(lambda mid, qos: sent.append((mid, qos)))
    first, second, third = acks.received(1, 1), acks.received(2, 1), acks.received(3, 1)
    assert acks.received(0, 0) is not None and acks.waiting == 3  # QoS 0: nothing to send
    second()  # handled (a rejection) while the first still waits for its commit
    third()
    assert sent == []
    first()
    assert sent == [(1, 1), (2, 1), (3, 1)] and acks.waiting == 0


def test_single_values_must_be_plain_numbers() -> None:
    """HTTP's rule of a CSV number, the field named as HTTP names it; a byte order mark
    dropped, as HTTP drops it; a long number is a number (400 digits were "not a decimal
    number", and a 70-character 26.1000…1 refused)."""
    assert parse_value(b"26.1", "power") == 26.1 and parse_value(b" -0.5\n", "power") == -0.5
    assert parse_value(b"1e3", "power") == 1000.0
    assert parse_value(b"\xef\xbb\xbf42", "voltage") == 42.0
    assert parse_value(b"26." + b"0" * 66 + b"1", "current") == 26.0
    for bad, kind in ((b"1_0", "type_error"), (b"nan", "type_error"), (b"inf", "type_error"),
                      (b"0x10", "type_error"), (b"", "type_error"), (b"26,1", "type_error"),
                      (b"1e999", "finite_number"), (b"1" * 400, "finite_number")):
        with pytest.raises(IngestError) as err:
            parse_value(bad, "current")
        assert [(e["field"], e["type"]) for e in err.value.errors] == [("current_a", kind)]


# ---------------------------------------------------------------- broker helpers


def _broker_up(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=2.0):
            return True
    except OSError:
        return False


def need_broker() -> None:
    """Skip (or fail under HELIOTWIN_REQUIRE_SERVICES=1) when Mosquitto does not answer."""
    if _broker_up(HOST, PORT):
        return
    why = f"no MQTT broker at {HOST}:{PORT} (start Mosquitto: docs/service.md)"
    if REQUIRE_SERVICES:
        pytest.fail(why + " (HELIOTWIN_REQUIRE_SERVICES=1)")
    pytest.skip(why)


class Watcher:
    """A paho-mqtt subscriber that keeps every message it gets."""

    def __init__(self, *filters: str, host: str = HOST, port: int = PORT) -> None:
        self.messages: list[mqtt.MQTTMessage] = []
        self._cond = threading.Condition()
        subscribed = threading.Event()
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2,
                                  client_id=f"ht-test-{uuid.uuid4().hex[:8]}")
        self.client.on_connect = lambda c, *_: c.subscribe([(f, 1) for f in filters])
        self.client.on_subscribe = lambda *_: subscribed.set()
        self.client.on_message = self._on_message
        self.client.connect(host, port)
        self.client.loop_start()
        assert subscribed.wait(WAIT_S), f"could not subscribe to {filters}"

    def _on_message(self, client: Any, userdata: Any, msg: mqtt.MQTTMessage) -> None:
        with self._cond:
            self.messages.append(msg)
            self._cond.notify_all()

    def wait(self, pred: Callable[[mqtt.MQTTMessage], bool], what: str) -> mqtt.MQTTMessage:
        """The first message for which ``pred`` holds (waiting up to WAIT_S for it)."""
        deadline = time.monotonic() + WAIT_S
        with self._cond:
            while True:
                hit = next((m for m in self.messages if pred(m)), None)
                if hit is not None:
                    return hit
                left = deadline - time.monotonic()
                got = [(m.topic, m.payload[:80]) for m in self.messages]
                assert left > 0, f"no {what}; got {got}"
                self._cond.wait(left)

    def close(self) -> None:
        self.client.disconnect()  # first: the network thread ends with it, not on its 1 s poll
        self.client.loop_stop()


def publish_all(messages: list[tuple[str, str | bytes]], retain: bool = False,
                host: str = HOST, port: int = PORT) -> None:
    """Publish with QoS 1, one connection, waiting for each acknowledgement."""
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"ht-pub-{uuid.uuid4().hex[:8]}")
    c.connect(host, port)
    c.loop_start()
    try:
        for topic, payload in messages:
            c.publish(topic, payload, qos=1, retain=retain).wait_for_publish(WAIT_S)
    finally:
        c.disconnect()  # before loop_stop, as Watcher.close
        c.loop_stop()


def publish(topic: str, payload: str | bytes, host: str = HOST, port: int = PORT) -> None:
    """Publish one message with QoS 1 and wait for the broker's acknowledgement."""
    publish_all([(topic, payload)], host=host, port=port)


def clear_retained(*filters: str) -> None:
    """Remove the retained messages under ``filters`` (``prefix/#`` first; an empty retained
    payload each). The broker queues a subscription's retained messages as it acknowledges
    it, so a message published after the acknowledgement arrives behind all of them."""
    assert filters[0].endswith("/#"), filters
    w = Watcher(*filters)
    try:
        marker = f"{filters[0][:-1]}retained-read-{uuid.uuid4().hex[:8]}"
        publish(marker, b"")
        w.wait(lambda m: m.topic == marker, "the message published after the retained ones")
    finally:
        w.close()
    topics = sorted({m.topic for m in w.messages if m.retain and m.payload})
    publish_all([(t, b"") for t in topics], retain=True)


def mqtt_env(prefix: str, url: str) -> dict[str, str]:
    return {
        "HELIOTWIN_MQTT_URL": url,
        "HELIOTWIN_MQTT_STATE_TOPIC": prefix + "/{site_id}/{array}/state",
        "HELIOTWIN_MQTT_VALUE_TOPIC": prefix + "/{site_id}/{array}/{quantity}",
        "HELIOTWIN_MQTT_ERRORS_TOPIC": prefix + "/{site_id}/errors",
        "HELIOTWIN_MQTT_HA_STATE_TOPIC": prefix + "/{site_id}/{array}/ha/{sensor}",
        "HELIOTWIN_MQTT_HA_PREFIX": prefix + "_ha",
        "HELIOTWIN_MQTT_PUBLISH_INTERVAL_S": "2",
        "HELIOTWIN_MQTT_RETRY_MAX_S": "2",
    }


def meta(c: httpx.Client) -> dict[str, Any]:
    return c.get("/api/v1/meta").json()  # type: ignore[no-any-return]


def wait_state(c: httpx.Client, state: str) -> dict[str, Any]:
    deadline = time.monotonic() + WAIT_S
    while True:
        m = meta(c)
        if m["mqtt"] == state:
            return m
        assert time.monotonic() < deadline, f"mqtt never {state}: {m['mqtt_status']}"
        time.sleep(0.2)


def stored(c: httpx.Client, array: str, start: str, end: str, want: int) -> list[dict[str, Any]]:
    """The readings of ``array`` in ``[start, end)``, once there are ``want`` of them."""
    deadline = time.monotonic() + WAIT_S
    while True:
        r = c.get(f"/api/v1/sites/{SITE}/measurements",
                  params={"array": array, "start": start, "end": end})
        assert r.status_code == 200, r.text
        points: list[dict[str, Any]] = r.json()["points"]
        if len(points) >= want:
            return points
        assert time.monotonic() < deadline, f"{len(points)} readings stored, not {want}"
        time.sleep(0.2)


def minute(offset_min: int) -> dt.datetime:
    now = dt.datetime.now(dt.UTC).replace(second=0, microsecond=0)
    return now + dt.timedelta(minutes=offset_min)


def iso(t: dt.datetime) -> str:
    return t.isoformat().replace("+00:00", "Z")


# ---------------------------------------------------------------- against the shared broker


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[httpx.Client, str]]:
    """A running service on the shared broker: ``(an HTTP client on it, topic prefix)``."""
    need_broker()
    prefix = f"httest{uuid.uuid4().hex[:10]}"
    tmp = tmp_path_factory.mktemp("mqtt")
    db = new_database("sqlite", tmp)
    env = {**mqtt_env(prefix, f"mqtt://{HOST}:{PORT}"),
           "HELIOTWIN_SITES_DIR": str(tmp / "user-sites"), "HELIOTWIN_ADMIN_TOKEN": ADMIN}
    proc = InProcessServer(db.url, extra_env=env)
    try:
        with proc, proc.client(timeout_s=30.0) as c:
            wait_state(c, "connected")
            yield c, prefix
    finally:
        clear_retained(f"{prefix}/#", f"{prefix}_ha/#")


def test_a_published_reading_is_stored_once(service: tuple[httpx.Client, str]) -> None:
    c, prefix = service
    t0, t1 = minute(-12), minute(-11)
    topic = f"{prefix}/{SITE}/tracker/state"
    publish(topic, json.dumps({"ts": iso(t0), "voltage_v": 25.0, "current_a": 4.0,
                               "power_w": 100.0}))
    publish(topic, json.dumps({"ts": t1.isoformat(), "voltage_v": 25.0, "current_a": 8.0}))
    points = stored(c, "tracker", iso(t0), iso(t1 + dt.timedelta(minutes=1)), 2)
    assert [(p["ts"], p["voltage_v"], p["current_a"], p["power_w"]) for p in points] == [
        (iso(t0), 25.0, 4.0, 100.0), (iso(t1), 25.0, 8.0, 200.0)]  # power: voltage·current
    before = meta(c)["mqtt_status"]["duplicates"]
    publish(topic, json.dumps({"ts": iso(t0), "voltage_v": 25.0, "current_a": 4.0}))
    deadline = time.monotonic() + WAIT_S
    while meta(c)["mqtt_status"]["duplicates"] == before:
        assert time.monotonic() < deadline, "the repeated reading was never counted"
        time.sleep(0.2)
    assert len(stored(c, "tracker", iso(t0), iso(t1 + dt.timedelta(minutes=1)), 2)) == 2


def test_a_reading_with_a_byte_order_mark_is_stored(service: tuple[httpx.Client, str]) -> None:
    """As HTTP takes it (Windows tools write one): it had been "invalid JSON" over MQTT."""
    c, prefix = service
    t0 = minute(-90)
    publish(f"{prefix}/{SITE}/fixed/state", b"\xef\xbb\xbf" + json.dumps({
        "ts": iso(t0), "voltage_v": 25.0, "current_a": 2.0}).encode())
    (p,) = stored(c, "fixed", iso(t0), iso(t0 + dt.timedelta(minutes=1)), 1)
    assert (p["voltage_v"], p["current_a"], p["power_w"]) == (25.0, 2.0, 50.0)


def test_a_power_only_reading_with_sensor_fields_is_stored(
        service: tuple[httpx.Client, str]) -> None:
    """MQTT takes what HTTP takes: power alone and the optional sensor fields."""
    c, prefix = service
    t0 = minute(-60)  # over the energy's gap rule (20 min) from the module's other fixed readings
    publish(f"{prefix}/{SITE}/fixed/state", json.dumps({
        "ts": iso(t0), "power_w": 310.5, "poa_irradiance_w_m2": 640.0, "temp_module_c": 41.5}))
    (p,) = stored(c, "fixed", iso(t0), iso(t0 + dt.timedelta(minutes=1)), 1)
    assert (p["voltage_v"], p["current_a"], p["power_w"]) == (None, None, 310.5)
    assert (p["poa_irradiance_w_m2"], p["temp_module_c"]) == (640.0, 41.5)


@pytest.mark.parametrize(("where", "payload", "reason"), [
    ("tracker/state", '{"ts": "2024-03-15T12:00:00", "voltage_v"', "invalid JSON"),
    ("tracker/state", '{"ts": "2024-03-15T12:00:00", "voltage_v": 26, "current_a": 1}',
     "no UTC offset"),
    ("tracker/state", '{"ts": "2024-03-15T12:00:00Z", "voltage_v": 26, "current_a": 1, '
                      '"power_w": 500}', "disagrees"),
    ("tracker/state", '{"ts": "2024-03-15T12:00:00Z", "voltage_v": 26, "current_a": 1, '
                      '"array": "fixed"}', "not the topic's array"),
    ("tracker/state", '[{"ts": "2024-03-15T12:00:00Z"}]', "one JSON object"),
    ("roof/state", '{"ts": "2024-03-15T12:00:00Z", "voltage_v": 26, "current_a": 1}',
     "unknown array 'roof'"),
    ("fixed/voltage", "1_0", "voltage_v: not a number: '1_0'"),
    ("fixed/power", "1" * 400, "power_w: not a finite number"),
    ("tracker/state", '{"ts": "2024-03-15T12:00:00Z", "voltage_v": NaN, "current_a": 1}',
     "voltage_v: not a finite number: nan"),
])
def test_a_rejected_message_is_reported_with_its_reason(
        service: tuple[httpx.Client, str], where: str, payload: str, reason: str) -> None:
    c, prefix = service
    errors = Watcher(f"{prefix}/{SITE}/errors")
    try:
        topic = f"{prefix}/{SITE}/{where}"
        publish(topic, payload)
        msg = errors.wait(lambda m: json.loads(m.payload)["topic"] == topic
                          and json.loads(m.payload)["payload"] == payload[:256],
                          f"error on {topic}")
    finally:
        errors.close()
    body = json.loads(msg.payload)
    assert reason in body["reason"], body
    assert body["received_at"].endswith("+00:00")
    r = c.get(f"/api/v1/sites/{SITE}/measurements",
              params={"array": "tracker", "start": "2024-03-15", "end": "2024-03-16"})
    assert r.json()["points"] == []


def test_an_unknown_site_is_reported_on_the_unknown_errors_topic(
        service: tuple[httpx.Client, str]) -> None:
    _, prefix = service
    errors = Watcher(f"{prefix}/_unknown/errors")
    try:
        publish(f"{prefix}/atlantis/tracker/state", '{"ts": "2024-03-15T12:00:00Z"}')
        msg = errors.wait(lambda m: True, "error for the unknown site")
    finally:
        errors.close()
    body = json.loads(msg.payload)
    assert body["topic"] == f"{prefix}/atlantis/tracker/state"
    assert "unknown site 'atlantis'" in body["reason"] and SITE in body["reason"]


def test_opendtu_style_values_are_assembled_into_a_minute(
        service: tuple[httpx.Client, str]) -> None:
    c, prefix = service
    while dt.datetime.now(dt.UTC).second >= 50:  # keep the three values in one minute
        time.sleep(0.5)
    now = minute(0)
    for quantity, value in (("voltage", "25.5"), ("current", "2"), ("power", "51.0")):
        publish(f"{prefix}/{SITE}/fixed/{quantity}", value)
    points = stored(c, "fixed", iso(now), iso(now + dt.timedelta(minutes=2)), 1)
    assert points[0]["ts"] == iso(now)
    assert (points[0]["voltage_v"], points[0]["current_a"], points[0]["power_w"]) == (
        25.5, 2.0, 51.0)


def test_retained_single_values_are_not_stored_again_at_a_connection(
        tmp_path: Path) -> None:
    """A logger's last values left retained on the broker reach every new subscription:
    stored as the minute the service connected, a restart invented a reading (and a silent
    logger looked alive). They are counted as ignored; so is an empty payload, how a
    retained message is deleted."""
    need_broker()
    prefix = f"httest{uuid.uuid4().hex[:10]}"
    publish_all([(f"{prefix}/{SITE}/tracker/{q}", v)
                 for q, v in (("voltage", "30"), ("current", "2"), ("power", "60"))],
                retain=True)
    db = new_database("sqlite", tmp_path)
    try:
        with InProcessServer(db.url, extra_env=mqtt_env(prefix, f"mqtt://{HOST}:{PORT}")) as p, \
                p.client(timeout_s=30.0) as c:
            wait_state(c, "connected")
            deadline = time.monotonic() + WAIT_S
            while meta(c)["mqtt_status"]["ignored"] < 3:
                assert time.monotonic() < deadline, meta(c)["mqtt_status"]
                time.sleep(0.2)
            publish(f"{prefix}/{SITE}/tracker/power", b"")  # not an error
            while meta(c)["mqtt_status"]["ignored"] < 4:
                assert time.monotonic() < deadline, meta(c)["mqtt_status"]
                time.sleep(0.2)
            status = meta(c)["mqtt_status"]
            assert status["stored"] == 0 and status["rejected"] == 0, status
        # the stop closed every open minute (an assembled one is stored then, not only once
        # its minute and grace are over, which a fixed wait here seldom reached)
        with InProcessServer(db.url) as again, again.client(timeout_s=30.0) as c:
            r = c.get(f"/api/v1/sites/{SITE}/measurements",
                      params={"array": "tracker", "start": iso(minute(-5)),
                              "end": iso(minute(5))})
            assert r.json()["points"] == []
    finally:
        clear_retained(f"{prefix}/#")
        db.drop()


def test_home_assistant_discovery_is_retained(service: tuple[httpx.Client, str]) -> None:
    c, prefix = service
    # a reading pair of the fixed array: 100 W then 200 W a minute apart = 2.5 Wh, the fixed
    # array's whole energy (its other readings in this module are single, each over the
    # gap rule's 20 min from any other)
    t0 = minute(-120)
    topic = f"{prefix}/{SITE}/fixed/state"
    for k, amps in enumerate((4.0, 8.0)):
        publish(topic, json.dumps({"ts": iso(t0 + dt.timedelta(minutes=k)),
                                   "voltage_v": 25.0, "current_a": amps}))
    stored(c, "fixed", iso(t0), iso(t0 + dt.timedelta(minutes=2)), 2)
    # a subscriber that comes later still gets every config (retained)
    ha = Watcher(f"{prefix}_ha/sensor/+/config")
    try:
        configs = {}
        for array in ("tracker", "fixed"):
            for sensor in ("energy", "energy_today", "power", "twin_power",
                           "twin_energy_today"):
                oid = f"heliotwin_{SITE}_{array}_{sensor}"
                def is_config(m: mqtt.MQTTMessage, t: str = f"{prefix}_ha/sensor/{oid}/config"
                              ) -> bool:
                    return bool(m.topic == t)
                msg = ha.wait(is_config, f"config of {oid}")
                assert msg.retain
                configs[oid] = json.loads(msg.payload)
    finally:
        ha.close()
    energy = configs[f"heliotwin_{SITE}_fixed_energy"]
    assert (energy["device_class"], energy["state_class"], energy["unit_of_measurement"]) == (
        "energy", "total_increasing", "kWh")
    power = configs[f"heliotwin_{SITE}_tracker_power"]
    assert (power["device_class"], power["unit_of_measurement"]) == ("power", "W")
    assert power["availability"] == [
        {"topic": f"{prefix}_ha/heliotwin/availability"},
        {"topic": f"{prefix}/{SITE}/tracker/ha/power/availability"}]
    assert power["availability_mode"] == "all"
    assert energy["availability"] == [{"topic": f"{prefix}_ha/heliotwin/availability"}]
    assert energy["device"]["identifiers"] == power["device"]["identifiers"]
    assert energy["unique_id"] == f"heliotwin_{SITE}_fixed_energy"
    # the state topic of the all-time energy carries the stored readings' energy
    states = Watcher(energy["state_topic"])
    try:
        states.wait(lambda m: m.payload == b"0.0025", "fixed energy of 0.0025 kWh")
    finally:
        states.close()


def test_a_site_added_while_connected_reaches_home_assistant(
        service: tuple[httpx.Client, str]) -> None:
    """A site created over the API (as ``heliotwin site create`` or a dropped file) gets
    its discovery configs and states within a publish interval, without a reconnection."""
    c, prefix = service
    site = f"added{uuid.uuid4().hex[:6]}"
    ha = Watcher(f"{prefix}_ha/sensor/+/config", f"{prefix}/{site}/+/ha/+")
    try:
        r = c.put(f"/api/v1/sites/{site}", json=tehuantepec_elsewhere(c, site),
                  headers={"Authorization": f"Bearer {ADMIN}"})
        assert r.status_code == 201, r.text
        t0 = minute(-1)
        publish(f"{prefix}/{site}/fixed/state",
                json.dumps({"ts": iso(t0), "voltage_v": 25.0, "current_a": 4.0}))
        config = ha.wait(lambda m: m.topic == f"{prefix}_ha/sensor/heliotwin_{site}_fixed_power"
                                               "/config", f"the config of {site}'s power")
        assert json.loads(config.payload)["unique_id"] == (
            f"heliotwin_{site}_fixed_power")
        ha.wait(lambda m: m.topic == f"{prefix}/{site}/fixed/ha/power" and m.payload == b"100.0",
                f"{site}'s fixed power of 100 W")
    finally:
        ha.close()


def test_home_assistant_power_goes_offline_past_its_age(
        service: tuple[httpx.Client, str]) -> None:
    """A 5-minute logger stopped 7 minutes ago: its power's availability is ``offline``
    (retained) and no power state is published — it was published for 2.5 cadences
    (12.5 min) and stayed retained as current. A new reading brings it back ``online``."""
    c, prefix = service
    site = f"stopped{uuid.uuid4().hex[:6]}"
    r = c.put(f"/api/v1/sites/{site}", json=tehuantepec_elsewhere(c, site),
              headers={"Authorization": f"Bearer {ADMIN}"})
    assert r.status_code == 201, r.text
    for k in (-12, -7):
        publish(f"{prefix}/{site}/fixed/state",
                json.dumps({"ts": iso(minute(k)), "voltage_v": 25.0, "current_a": 4.0}))
    stored_at = f"/api/v1/sites/{site}/measurements"
    deadline = time.monotonic() + WAIT_S
    while len(c.get(stored_at, params={"array": "fixed", "start": iso(minute(-13)),
                                       "end": iso(minute(1))}).json()["points"]) < 2:
        assert time.monotonic() < deadline
        time.sleep(0.2)
    avail = f"{prefix}/{site}/fixed/ha/power/availability"
    service_avail = f"{prefix}_ha/heliotwin/availability"
    w = Watcher(f"{prefix}/{site}/fixed/ha/#", service_avail)
    try:
        w.wait(lambda m: m.topic == service_avail and m.payload == b"online", "service online")
        w.wait(lambda m: m.topic == avail and m.payload == b"offline", "power offline")
        w.wait(lambda m: m.topic == f"{prefix}/{site}/fixed/ha/energy", "the energy state")
        time.sleep(2.5)  # a publish interval more
        powers = [m.payload for m in w.messages if m.topic == f"{prefix}/{site}/fixed/ha/power"]
        assert powers == [], "a power published for a reading 7 min old"
        publish(f"{prefix}/{site}/fixed/state",
                json.dumps({"ts": iso(minute(-1)), "voltage_v": 25.0, "current_a": 8.0}))
        w.wait(lambda m: m.topic == avail and m.payload == b"online", "power online again")
        w.wait(lambda m: m.topic == f"{prefix}/{site}/fixed/ha/power" and m.payload == b"200.0",
               "the new power")
    finally:
        w.close()


def test_home_assistant_energy_today_is_zero_after_local_midnight(
        service: tuple[httpx.Client, str]) -> None:
    """A logger that reported last evening and not yet today: energy today is 0 from local
    midnight. It was not published, so the retained value of yesterday stayed "today" until
    the first reading of the new day (a tester's finding). The site's zone is chosen so that
    local midnight has just passed (Etc/GMT±h), its readings at 23:00–23:05 local."""
    c, prefix = service
    now = dt.datetime.now(dt.UTC)
    hours = (24 - now.hour) % 24  # local = UTC + hours: 00:MM now
    zone = "Etc/GMT" + (f"-{hours}" if hours <= 14 else f"+{24 - hours}") if hours else "UTC"
    site = f"midnight{uuid.uuid4().hex[:6]}"
    r = c.put(f"/api/v1/sites/{site}", json=tehuantepec_elsewhere(c, site, timezone=zone),
              headers={"Authorization": f"Bearer {ADMIN}"})
    assert r.status_code == 201, r.text
    evening = minute(-now.minute - 60)  # 23:00 local, yesterday
    for k in (0, 5):
        publish(f"{prefix}/{site}/fixed/state",
                json.dumps({"ts": iso(evening + dt.timedelta(minutes=k)), "voltage_v": 25.0,
                            "current_a": 20.0}))
    w = Watcher(f"{prefix}/{site}/fixed/ha/#")
    try:
        w.wait(lambda m: m.topic == f"{prefix}/{site}/fixed/ha/energy" and m.payload != b"0.0000",
               "yesterday's energy")
        w.wait(lambda m: m.topic == f"{prefix}/{site}/fixed/ha/energy_today"
               and m.payload == b"0.0000", "energy today reset to 0")
    finally:
        w.close()


# ---------------------------------------------------------------- reconnection


def _mosquitto(port: int, folder: Path) -> subprocess.Popen[bytes]:
    exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    conf = folder / "mosquitto.conf"
    conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n")
    proc = subprocess.Popen([exe, "-c", str(conf)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + WAIT_S
    while not _broker_up("127.0.0.1", port):
        assert proc.poll() is None and time.monotonic() < deadline, "mosquitto did not start"
        time.sleep(0.1)
    return proc


def test_the_service_reconnects_with_backoff(tmp_path: Path,
                                            caplog: pytest.LogCaptureFixture) -> None:
    if not (shutil.which("mosquitto") or Path("/usr/sbin/mosquitto").exists()):
        if REQUIRE_SERVICES:
            pytest.fail("no mosquitto executable (HELIOTWIN_REQUIRE_SERVICES=1)")
        pytest.skip("no mosquitto executable to start a broker of the test's own")
    port = free_port()
    prefix = f"httest{uuid.uuid4().hex[:10]}"
    db = new_database("sqlite", tmp_path)
    caplog.set_level(logging.WARNING, logger="backend.mqtt.service")
    proc = InProcessServer(db.url, extra_env=mqtt_env(prefix, f"mqtt://127.0.0.1:{port}"))
    proc.start()  # the broker is not there yet
    broker = None
    c = proc.client(timeout_s=30.0)
    try:
        m = wait_state(c, "retrying")
        assert m["mqtt_status"]["broker"] == f"127.0.0.1:{port}"
        broker = _mosquitto(port, tmp_path)
        wait_state(c, "connected")
        topic = f"{prefix}/{SITE}/tracker/state"
        t0 = minute(-20)
        publish(topic, json.dumps({"ts": iso(t0), "voltage_v": 25.0, "current_a": 1.0}),
                port=port)
        stored(c, "tracker", iso(t0), iso(minute(1)), 1)

        broker.terminate()  # the connection drops under the service
        broker.wait(10)
        wait_state(c, "retrying")
        broker = _mosquitto(port, tmp_path)
        m = wait_state(c, "connected")
        assert m["mqtt_status"]["retries"] >= 2
        publish(topic, json.dumps({"ts": iso(t0 + dt.timedelta(minutes=1)), "voltage_v": 25.0,
                                   "current_a": 2.0}), port=port)
        stored(c, "tracker", iso(t0), iso(minute(1)), 2)
    finally:
        c.close()
        proc.stop()
        if broker is not None:
            broker.terminate()
            broker.wait(10)
    retries = [line for line in caplog.messages if "retry" in line]
    assert any(f"127.0.0.1:{port}" in line for line in retries), retries


@dataclasses.dataclass
class Session:
    """A service's persistent MQTT session on the shared broker, for a service that goes
    away and one that comes back: the first a real process (in this process, a thread that
    outlived its service could still hold the session and store the reading), the other
    in this process."""

    first: ServerProcess
    back: InProcessServer
    prefix: str

    def publish_reading(self, t: dt.datetime, current_a: float) -> None:
        publish(f"{self.prefix}/{SITE}/tracker/state",
                json.dumps({"ts": iso(t), "voltage_v": 25.0, "current_a": current_a}))

    def stored_power_w(self, t: dt.datetime) -> float:
        """The power of the reading at ``t``, as the service that came back stored it."""
        with self.back.start().client(timeout_s=30.0) as c:
            points = stored(c, "tracker", iso(t), iso(t + dt.timedelta(minutes=1)), 1)
        return float(points[0]["power_w"])


@contextlib.contextmanager
def persistent_session(tmp_path: Path) -> Iterator[tuple[Session, Path]]:
    """A :class:`Session` on a fresh SQLite file (its path the second item); ended on the
    broker, with its retained messages, afterwards."""
    need_broker()
    prefix = f"httest{uuid.uuid4().hex[:10]}"
    client_id = f"heliotwin-test-{uuid.uuid4().hex[:8]}"
    db = new_database("sqlite", tmp_path)
    env = {**mqtt_env(prefix, f"mqtt://{HOST}:{PORT}"), "HELIOTWIN_MQTT_CLIENT_ID": client_id}
    session = Session(ServerProcess(db.url, tmp_path / "server.log", extra_env=env).start(),
                      InProcessServer(db.url, extra_env=env), prefix)
    try:
        yield session, Path(db.url.removeprefix("sqlite:///"))
    finally:
        session.first.kill()
        session.back.stop()
        gone = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id,
                           clean_session=True)  # end the session on the broker
        gone.connect(HOST, PORT)
        gone.disconnect()
        clear_retained(f"{prefix}/#", f"{prefix}_ha/#")


@pytest.mark.slow
def test_a_reading_received_but_not_committed_comes_again_after_a_sigkill(
        tmp_path: Path) -> None:
    """A reading the service has received but not stored when it is killed is not lost:
    the acknowledgement waits for the commit, so the broker hands the reading over again to
    the persistent session. The commit is held back by the test's own write lock on the
    SQLite file (WAL: the service's reads go on; its writer waits on the busy timeout)."""
    t0 = minute(-30)
    with persistent_session(tmp_path) as (session, sqlite_file):
        lock = sqlite3.connect(sqlite_file, isolation_level=None)
        try:
            with httpx.Client(base_url=session.first.base_url, timeout=30.0) as c:
                wait_state(c, "connected")
                lock.execute("BEGIN IMMEDIATE")  # the service's next commit waits
                session.publish_reading(t0, 5.0)
                deadline = time.monotonic() + WAIT_S
                while meta(c)["mqtt_status"]["received"] < 1:
                    assert time.monotonic() < deadline, "the service never got the reading"
                    time.sleep(0.1)
                assert meta(c)["mqtt_status"]["stored"] == 0
            availability = f"{session.prefix}_ha/heliotwin/availability"
            ha = Watcher(availability)  # as Home Assistant: the killed service goes offline
            try:
                ha.wait(lambda m: m.payload == b"online", "the service online (retained)")
                session.first.kill()
                ha.wait(lambda m: m.payload == b"offline", "the Last Will: offline")
            finally:
                ha.close()
        finally:
            lock.close()  # its transaction rolled back
        assert session.stored_power_w(t0) == 125.0


@pytest.mark.slow
def test_a_persistent_session_keeps_readings_while_the_service_is_away(
        tmp_path: Path) -> None:
    t0 = minute(-40)
    with persistent_session(tmp_path) as (session, _):
        with httpx.Client(base_url=session.first.base_url, timeout=30.0) as c:
            wait_state(c, "connected")  # the broker now knows the session
        ha = Watcher(f"{session.prefix}_ha/heliotwin/availability")
        try:
            session.first.stop()  # a graceful stop says offline itself (no Last Will then)
            ha.wait(lambda m: m.payload == b"offline", "offline at a graceful stop")
        finally:
            ha.close()
        session.publish_reading(t0, 3.0)  # while no service is connected
        assert session.stored_power_w(t0) == 75.0
