"""MQTT ingestion against HTTP single readings, and the InfluxDB export against CSV.

Starts a real ``heliotwin serve`` (SQLite in a temp dir, no demo logger, no live
twin, no viser) connected to the Mosquitto at 127.0.0.1:1883 (``MQTT_TEST_URL``)
with a topic prefix of its own, and measures in one run:

- baseline: single readings posted over HTTP on one keep-alive connection, back
  to back (each answer means committed) — what a logger without MQTT does;
- MQTT: the same number of readings published (QoS 1) by one paho-mqtt client
  to ``…/tracker/state`` in windows of 500 (each stored before the next is sent),
  timed from the first publish until the service's ``mqtt_status.stored`` counts
  them all (committed);
- export: 90 days of minute readings of one array (129,600), fetched as CSV
  (baseline) and as InfluxDB line protocol over the same HTTP connection, median
  of 3 after a first call.

Prints one Markdown section to stdout; progress on stderr. Needs the broker: it
exits 1 with a message when none answers.
"""

from __future__ import annotations

import datetime as dt
import http.client
import os
import socket
import statistics
import sys
import tempfile
import time
import uuid
from pathlib import Path
from urllib.parse import urlsplit

import orjson
from _common import Figures, log  # noqa: E402  (bench scripts run from this folder)
from bench_service import PATH, SITE, TZ, Server, timed_get

ROOT = Path(__file__).resolve().parents[1]
BROKER = urlsplit(os.environ.get("MQTT_TEST_URL", "mqtt://127.0.0.1:1883"))
HOST, PORT = BROKER.hostname or "127.0.0.1", BROKER.port or 1883
N_READINGS = 5_000
WINDOW = 500
EXPORT_DAYS = 90


def _iso(t: int) -> str:
    return dt.datetime.fromtimestamp(t, dt.UTC).isoformat()


def http_singles(port: int, token: str, t0: int, n: int) -> float:
    """Seconds to post ``n`` single readings back to back on one connection."""
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    h = {"Authorization": f"Bearer {token}", "Content-Type": "application/json"}
    start = time.perf_counter()
    for k in range(n):
        body = orjson.dumps({"readings": [{"ts": _iso(t0 + 60 * k), "array": "fixed",
                                           "voltage_v": 25.0, "current_a": 10.0}]})
        c.request("POST", PATH, body=body, headers=h)
        r = c.getresponse()
        r.read()
        if r.status != 200:
            raise RuntimeError(f"POST answered {r.status}")
    return time.perf_counter() - start


def stored_count(port: int) -> int:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    c.request("GET", "/api/v1/meta")
    return int(orjson.loads(c.getresponse().read())["mqtt_status"]["stored"])


def mqtt_publish(port: int, prefix: str, t0: int, n: int) -> float:
    """Seconds from the first QoS 1 publish until the service has stored all ``n``."""
    import paho.mqtt.client as mqtt

    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"bench-{uuid.uuid4().hex[:8]}")
    c.connect(HOST, PORT)
    c.loop_start()
    payloads = [orjson.dumps({"ts": _iso(t0 + 60 * k), "voltage_v": 25.0, "current_a": 10.0})
                for k in range(n)]
    before = stored_count(port)
    topic = f"{prefix}/{SITE}/tracker/state"
    start = time.perf_counter()
    # in windows of WINDOW readings, each stored before the next is sent: a burst
    # beyond the broker's per-client queue (Mosquitto max_queued_messages, 1000)
    # would be dropped by the broker, not measured
    for k in range(0, n, WINDOW):
        infos = [c.publish(topic, p, qos=1) for p in payloads[k:k + WINDOW]]
        for info in infos:
            info.wait_for_publish(60)
        while stored_count(port) < before + min(n, k + WINDOW):
            if time.perf_counter() - start > 600:
                raise RuntimeError("the service did not store every MQTT reading in 600 s")
            time.sleep(0.01)
    secs = time.perf_counter() - start
    c.disconnect()  # first: the network thread ends with it, not on its 1 s poll
    c.loop_stop()
    return secs


def clear_retained(prefix: str) -> None:
    """Remove the retained discovery configs and states the run left on the broker."""
    import paho.mqtt.client as mqtt

    topics: set[str] = set()
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"bench-{uuid.uuid4().hex[:8]}")
    c.on_message = lambda _c, _u, m: topics.add(m.topic) if m.retain and m.payload else None
    c.connect(HOST, PORT)
    c.loop_start()
    c.subscribe([(f"{prefix}/#", 1), (f"{prefix}_ha/#", 1)])
    time.sleep(2.0)  # retained messages come right after the subscription
    for t in sorted(topics):
        c.publish(t, b"", qos=1, retain=True).wait_for_publish(30)
    c.disconnect()
    c.loop_stop()


def backfill(port: int, token: str, t0: int, days: int) -> int:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
    h = {"Authorization": f"Bearer {token}", "Content-Type": "application/json"}
    n = days * 1440
    for k in range(0, n, 5000):
        rows = [{"ts": _iso(t0 + 60 * j), "array": "tracker", "voltage_v": 25.0 + (j % 7) / 10,
                 "current_a": 10.0 + (j % 11) / 100} for j in range(k, min(n, k + 5000))]
        c.request("POST", PATH, body=orjson.dumps({"readings": rows}), headers=h)
        r = c.getresponse()
        r.read()
        if r.status != 200:
            raise RuntimeError(f"back-fill POST answered {r.status}")
    return n


def main() -> int:
    try:
        socket.create_connection((HOST, PORT), timeout=2).close()
    except OSError:
        log(f"no MQTT broker at {HOST}:{PORT}: start Mosquitto (docs/service.md)")
        return 1
    prefix = f"htbench{uuid.uuid4().hex[:8]}"
    env = {"HELIOTWIN_MQTT_URL": f"mqtt://{HOST}:{PORT}",
           "HELIOTWIN_MQTT_STATE_TOPIC": prefix + "/{site_id}/{array}/state",
           "HELIOTWIN_MQTT_VALUE_TOPIC": prefix + "/{site_id}/{array}/{quantity}",
           "HELIOTWIN_MQTT_ERRORS_TOPIC": prefix + "/{site_id}/errors",
           "HELIOTWIN_MQTT_HA_STATE_TOPIC": prefix + "/{site_id}/{array}/ha/{sensor}",
           "HELIOTWIN_MQTT_HA_PREFIX": prefix + "_ha",
           "HELIOTWIN_MQTT_PUBLISH_INTERVAL_S": "3600"}
    t_live = int(dt.datetime(2024, 1, 1, tzinfo=dt.UTC).timestamp())
    t_export = int(dt.datetime(2023, 1, 1, tzinfo=TZ).timestamp())  # the site's midnight
    with tempfile.TemporaryDirectory() as d:
        server = Server(Path(d), **env)
        try:
            while True:  # connected to the broker?
                c = http.client.HTTPConnection("127.0.0.1", server.port, timeout=30)
                c.request("GET", "/api/v1/meta")
                if orjson.loads(c.getresponse().read())["mqtt"] == "connected":
                    break
                time.sleep(0.2)
            log(f"baseline: {N_READINGS} single readings over HTTP")
            http_s = http_singles(server.port, server.token, t_live, N_READINGS)
            log(f"MQTT: {N_READINGS} readings published with QoS 1")
            mqtt_s = mqtt_publish(server.port, prefix, t_live, N_READINGS)
            log(f"export: back-fill {EXPORT_DAYS} days")
            n_export = backfill(server.port, server.token, t_export, EXPORT_DAYS)
            end = dt.date(2023, 1, 1) + dt.timedelta(days=EXPORT_DAYS)
            q = f"{PATH}?array=tracker&start=2023-01-01&end={end}"
            _, csv_times, csv_body = timed_get(server.port, q + "&format=csv", n=3)
            _, lp_times, lp_body = timed_get(server.port, q + "&format=influx", n=3)
        finally:
            server.stop()
            clear_retained(prefix)
    if lp_body.count(b"\n") != n_export or csv_body.count(b"\n") != n_export + 1:
        raise RuntimeError("export line counts do not match the readings stored")
    http_rate, mqtt_rate = N_READINGS / http_s, N_READINGS / mqtt_s
    csv_s, lp_s = statistics.median(csv_times), statistics.median(lp_times)
    fig = Figures("mqtt")
    rows = [
        (f"baseline: {N_READINGS:,} single readings over HTTP, one keep-alive connection",
         fig.add("http_single_readings_per_s", http_rate, "readings/s",
                 f"{http_rate:,.0f} readings/s")),
        (f"{N_READINGS:,} readings published over MQTT (QoS 1, one client, windows of "
         f"{WINDOW}), until stored",
         fig.add("mqtt_readings_per_s", mqtt_rate, "readings/s",
                 f"{mqtt_rate:,.0f} readings/s") + " = "
         + fig.add("mqtt_vs_http_single", mqtt_rate / http_rate, "×",
                   f"{mqtt_rate / http_rate:.1f}×") + " the baseline"),
        (f"baseline: CSV export of {n_export:,} readings (median of 3)",
         fig.add("csv_export_s", csv_s, "s", f"{csv_s:.2f} s")
         + f" ({len(csv_body) / 1e6:.1f} MB)"),
        ("InfluxDB line-protocol export of the same readings (median of 3)",
         fig.add("influx_export_s", lp_s, "s", f"{lp_s:.2f} s")
         + f" ({len(lp_body) / 1e6:.1f} MB) = "
         + fig.add("influx_vs_csv", lp_s / csv_s, "×", f"{lp_s / csv_s:.2f}×")
         + " the CSV time"),
    ]
    print("## mqtt\n")
    print("| what | measured |\n|---|---|")
    for what, value in rows:
        print(f"| {what} | {value} |")
    print("\nOne `heliotwin serve` process (SQLite) and the Mosquitto at "
          f"{HOST}:{PORT}; client, broker and server share the machine. No targets were "
          "set for these figures; they show what MQTT and the export cost next to the "
          "HTTP paths they sit beside.")
    fig.write()
    return 0


if __name__ == "__main__":
    sys.exit(main())
