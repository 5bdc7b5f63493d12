"""A huge MQTT message is never read by the service (issue 23, item 8): the client tells
the broker its Maximum Packet Size (MQTT 5), so the broker drops a larger message for
it; a message under that bound but over the payload limit is still rejected with its
reason. Against the shared Mosquitto (skipped without it, as ``test_mqtt.py``).
"""

from __future__ import annotations

import json

from test_mqtt import SITE, Watcher, publish, service  # noqa: F401 - ``service`` is a fixture

from backend.mqtt.ingest import MAX_PAYLOAD_BYTES
from backend.mqtt.service import MAX_PACKET_BYTES, connect_properties


def test_the_connect_properties_bound_the_packet_size() -> None:
    props = connect_properties(persistent=True)
    assert props.MaximumPacketSize == MAX_PACKET_BYTES > MAX_PAYLOAD_BYTES
    assert props.SessionExpiryInterval > 0  # a client id's session outlives a disconnect
    assert not hasattr(connect_properties(persistent=False), "SessionExpiryInterval")


def test_a_message_over_the_packet_size_never_reaches_the_service(
        service: tuple[object, str]) -> None:  # noqa: F811 - the imported fixture
    _, prefix = service
    topic = f"{prefix}/{SITE}/tracker/state"
    errors = Watcher(f"{prefix}/{SITE}/errors")
    big = b"x" * (8 * 1024 * 1024)  # would be read whole, then refused by its size
    over = "y" * (MAX_PAYLOAD_BYTES + 1)  # within the packet bound: refused by the service
    try:
        publish(topic, big)
        publish(topic, over)  # same publisher, same topic: delivered after `big`
        errors.wait(lambda m: json.loads(m.payload)["payload"].startswith("yyy"),
                    "the rejection of the message over the payload limit")
    finally:
        errors.close()
    reasons = [json.loads(m.payload) for m in errors.messages]
    assert [r["payload"][:3] for r in reasons] == ["yyy"]  # nothing about `big`: not read
    assert f"the limit is {MAX_PAYLOAD_BYTES}" in reasons[0]["reason"]
