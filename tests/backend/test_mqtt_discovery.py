"""Home Assistant discovery configs (``backend/mqtt/homeassistant.py``), without a broker."""

from __future__ import annotations

import json
from types import SimpleNamespace
from typing import Any, cast

from backend.mqtt import homeassistant
from backend.mqtt.topics import Topics


def test_each_config_names_its_entity_id_the_way_home_assistant_2026_reads_it() -> None:
    """Home Assistant 2025.10 deprecated ``object_id`` for ``default_entity_id`` (the
    domain and the id, ``sensor.…``) and stopped honouring ``object_id`` in 2026.4, so a
    config with ``object_id`` alone lets HA name the entity from the device and sensor
    names. Both are sent: older HA reads ``object_id``, newer ``default_entity_id``."""
    topics = Topics.from_settings("ops/{site_id}/{array}/state", "ops/{site_id}/{array}/{quantity}",
                                  "ops/{site_id}/errors", "ops/{site_id}/{array}/ha/{sensor}",
                                  "ops/homeassistant")
    info = cast(Any, SimpleNamespace(site_id="opsmadrid", site=SimpleNamespace(name="Ops"),
                                     arrays={"tracker": None, "fixed": None}))
    configs = dict(homeassistant.discovery(topics, info, "1.0"))
    assert len(configs) == 2 * len(homeassistant.SENSORS)
    for topic, raw in configs.items():
        config = json.loads(raw)
        oid = config["unique_id"]
        assert topic == f"ops/homeassistant/sensor/{oid}/config"
        assert config["default_entity_id"] == f"sensor.{oid}"
        assert config["object_id"] == oid
