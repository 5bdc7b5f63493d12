"""Home Assistant MQTT discovery: retained sensor configs and their states.

For every array of every site with arrays, five sensors under one device per
site (``homeassistant/sensor/heliotwin_{site_id}_{array}_{sensor}/config``,
retained, so Home Assistant finds them whenever it connects):

===================== ====== ============ ================= =========================
sensor                unit   device_class state_class       value
===================== ====== ============ ================= =========================
``energy``            kWh    energy       total_increasing  measured energy, all time
``energy_today``      kWh    energy       total_increasing  measured, since local midnight
``power``             W      power        measurement       last reading (≤ 5 min old)
``twin_energy_today`` kWh    energy       total_increasing  the twin's, since midnight
``twin_power``        W      power        measurement       the twin's now
===================== ====== ============ ================= =========================

Energies come from the hourly rollups (:mod:`backend.measurements.rollups`, the
one energy rule) — all time as the sum of a series' rollups, today from
:func:`backend.measurements.status.status`, which the dashboard's tiles use too.
Each state is a bare number on its own topic (``Settings.mqtt.ha_state_topic``),
retained; a value that is unknown is not published — except ``energy_today`` of an array
that has readings but none since local midnight: 0, so that the day's total resets at
midnight (Home Assistant's ``total_increasing``) and yesterday's value is not shown as
today's.

Availability (Home Assistant's ``availability``, ``availability_mode: all``): every
sensor follows the service's topic :func:`service_availability` — ``online`` retained
at each connection, ``offline`` at a graceful stop and as the connection's Last Will,
so a killed service goes unavailable too. The ``power`` sensor also follows its own
``…/power/availability`` (:func:`power_availability`): ``online`` while the logger's
last reading is at most :func:`power_max_age_s` old, then ``offline`` (retained, so a
Home Assistant that restarts later does not show the last value as current); its
last value stays retained but is not shown.
"""

from __future__ import annotations

import re
import time
from typing import TYPE_CHECKING, Any

import orjson

from backend.measurements.status import FRESH_S, LATEST, cadence_s, status
from backend.mqtt.topics import Topics
from backend.sites import SiteInfo
from backend.storage.sqlraw import fetch
from backend.storage.tables import SOURCE_CODES

if TYPE_CHECKING:
    from backend.context import ServiceContext

#: sensor → (name, unit, device_class, state_class)
SENSORS: dict[str, tuple[str, str, str, str]] = {
    "energy": ("energy", "kWh", "energy", "total_increasing"),
    "energy_today": ("energy today", "kWh", "energy", "total_increasing"),
    "power": ("power", "W", "power", "measurement"),
    "twin_energy_today": ("twin energy today", "kWh", "energy", "total_increasing"),
    "twin_power": ("twin power", "W", "power", "measurement"),
}
ONLINE, OFFLINE = b"online", b"offline"
_TOTAL = ("SELECT COALESCE(SUM(energy_wh), 0), COALESCE(SUM(n), 0) FROM measurement_rollups "
          "WHERE array_id = ? AND source = ?")


def object_id(site_id: str, array: str, sensor: str) -> str:
    """``heliotwin_{site_id}_{array}_{sensor}``, in the characters discovery allows."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", f"heliotwin_{site_id}_{array}_{sensor}")


def service_availability(topics: Topics) -> str:
    """The service's availability topic (``online``/``offline``, retained; its Last Will)."""
    return f"{topics.ha_prefix}/heliotwin/availability"


def power_availability(topics: Topics, site_id: str, array: str) -> str:
    """The availability topic of an array's ``power`` sensor."""
    return topics.ha_state.format(site_id=site_id, array=array, sensor="power") + "/availability"


def power_max_age_s(ts_desc_s: list[float]) -> float:
    """How old [s] the last reading may be for ``power`` to be shown: :data:`FRESH_S`
    (5 min), or one cadence of the logger plus a minute when it reports less often
    (the median interval of its latest readings ``ts_desc_s``, newest first) — a
    15-minute logger is not unavailable between two readings, and a stopped one is
    within a minute of its next reading being due."""
    return max(float(FRESH_S), cadence_s(ts_desc_s) + 60.0)


def discovery(topics: Topics, info: SiteInfo, version: str) -> list[tuple[str, bytes]]:
    """``(config topic, JSON config)`` of every sensor of ``info``'s arrays."""
    site_id = info.site_id
    device = {
        "identifiers": [object_id(site_id, "site", "device")],
        "name": f"heliotwin {info.site.name}",
        "manufacturer": "heliotwin", "model": "dual-axis tracker digital twin",
        "sw_version": version,
    }
    out = []
    for array in info.arrays:
        for sensor, (name, unit, device_class, state_class) in SENSORS.items():
            oid = object_id(site_id, array, sensor)
            config: dict[str, Any] = {
                # the entity id: default_entity_id for Home Assistant 2025.10 and later
                # (object_id, deprecated then, is no longer honoured from 2026.4), object_id
                # for the older ones
                "name": f"{array} {name}", "unique_id": oid, "object_id": oid,
                "default_entity_id": f"sensor.{oid}",
                "state_topic": topics.ha_state.format(site_id=site_id, array=array,
                                                      sensor=sensor),
                "unit_of_measurement": unit, "device_class": device_class,
                "state_class": state_class, "device": device,
                "suggested_display_precision": 3 if unit == "kWh" else 0,
            }
            availability = [{"topic": service_availability(topics)}]
            if sensor == "power":
                availability.append({"topic": power_availability(topics, site_id, array)})
            config.update(availability=availability, availability_mode="all")
            out.append((f"{topics.ha_prefix}/sensor/{oid}/config", orjson.dumps(config)))
    return out


def states(ctx: ServiceContext, info: SiteInfo, topics: Topics,
           now_s: float | None = None) -> list[tuple[str, bytes]]:
    """``(state topic, number)`` of every sensor of ``info`` with a known value now, and
    each array's ``(power availability topic, online | offline)``."""
    now = time.time() if now_s is None else now_s
    tiles = status(ctx, info, now)
    values: dict[str, dict[str, float | None]] = {}
    out = []
    with ctx.engine.connect() as conn:
        for name, arr in info.arrays.items():
            tile = tiles["arrays"][name]
            total_wh, n = fetch(conn, _TOTAL, (arr.array_id, SOURCE_CODES["measured"]))[0]
            recent = [float(r[0]) for r in fetch(conn, LATEST, (arr.array_id,))]
            live = bool(recent) and tile["power_w"] is not None and (
                now - recent[0] <= power_max_age_s(recent))
            out.append((power_availability(topics, info.site_id, name),
                        ONLINE if live else OFFLINE))
            values[name] = {
                "energy": float(total_wh) / 1000.0 if n else None,
                # measured since local midnight: none yet today is 0 for a logger that has
                # reported before (left unpublished, the retained value of yesterday stayed
                # "today" after midnight until the first reading; a tester's finding)
                "energy_today": _kwh(tile["energy_today_wh"]) if tile["energy_today_wh"]
                is not None or not n else 0.0,
                "power": tile["power_w"] if live else None,
                "twin_energy_today": _kwh(tile["twin_energy_today_wh"]),
                "twin_power": tile["twin_power_w"],
            }
    for name, sensors in values.items():
        for sensor, value in sensors.items():
            if value is not None:
                topic = topics.ha_state.format(site_id=info.site_id, array=name, sensor=sensor)
                digits = 4 if SENSORS[sensor][1] == "kWh" else 1
                out.append((topic, f"{float(value):.{digits}f}".encode()))
    return out


def _kwh(wh: float | None) -> float | None:
    return None if wh is None else wh / 1000.0
