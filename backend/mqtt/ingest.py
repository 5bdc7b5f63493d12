"""MQTT messages → validated batches, by the same rules as HTTP ingest.

Every reading that arrives over MQTT goes through
:func:`backend.measurements.parse.parse_json_batch`, the validator of
``POST /api/v1/sites/{site_id}/measurements``, as a one-reading body
``{"readings": [{..., "array": <the topic's array>}]}``; the writer then stores
it ``ON CONFLICT DO NOTHING``, so a reading sent twice (over MQTT, HTTP or
both) is stored once. The topic decides the site and the array (the broker's
ACL is the authority on who may publish there): a payload naming another
array is rejected, never redirected.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field, replace
from typing import Any

import orjson

from backend.measurements.parse import (
    BOM,
    Batch,
    IngestError,
    Limits,
    load_json,
    parse_json_batch,
)
from backend.mqtt.assemble import Closed, parse_value
from backend.settings import Settings
from backend.sites import SiteInfo

#: Largest payload accepted on a reading topic [bytes] (one reading is ~100).
MAX_PAYLOAD_BYTES = 16 * 1024
#: Bytes of a rejected payload echoed on the errors topic.
ECHO_BYTES = 256


@dataclass
class Rejection:
    """A message (or an assembled minute) that was not stored, and why."""

    topic: str
    reason: str
    payload: bytes = b""
    errors: list[dict[str, Any]] = field(default_factory=list)

    def message(self, now_s: float) -> bytes:
        """The JSON published on the errors topic."""
        return orjson.dumps({
            "topic": self.topic, "reason": self.reason, "errors": self.errors[:20],
            "payload": self.payload[:ECHO_BYTES].decode("utf-8", "replace"),
            "received_at": dt.datetime.fromtimestamp(now_s, dt.UTC).isoformat(),
        })


def limits(settings: Settings) -> Limits:
    """The plausibility limits of HTTP ingest, for one reading a message."""
    return replace(Limits.from_settings(settings), max_rows=1)


def _rejected(topic: str, payload: bytes, exc: IngestError) -> Rejection:
    msgs = [f"{e['field']}: {e.get('msg', '')}" if e.get("field") else e.get("msg", "")
            for e in exc.errors]  # the field named first, as HTTP's entries name it
    reason = "; ".join(m for m in msgs[:3] if m) or "invalid reading"
    return Rejection(topic, reason, payload, exc.errors)


def state_batch(info: SiteInfo, array: str, topic: str, payload: bytes,
                lim: Limits) -> Batch | Rejection:
    """Validate a JSON reading ``{"ts", "voltage_v", "current_a"[, "power_w"]}`` of ``array``."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        return Rejection(topic, f"payload of {len(payload)} bytes; the limit is "
                                f"{MAX_PAYLOAD_BYTES}", payload)
    body = payload.removeprefix(BOM).strip()  # the payload's own bytes, below
    try:
        doc = load_json(body)
    except IngestError as exc:
        return _rejected(topic, payload, exc)
    if not isinstance(doc, dict):
        return Rejection(topic, "payload must be one JSON object {\"ts\", \"voltage_v\", "
                                f"\"current_a\"[, \"power_w\"]}}, got {type(doc).__name__}",
                         payload)
    if "array" in doc and doc["array"] != array:
        return Rejection(topic, f"array {str(doc['array'])[:40]!r} in the payload is not "
                                f"the topic's array {array!r}", payload)
    # the payload's own bytes, so parse.py judges exactly what was sent (one object: checked)
    if "array" not in doc:
        inner = body[:-1].rstrip()
        sep = b"" if inner.endswith(b"{") else b","
        body = inner + sep + b'"array":' + orjson.dumps(array) + b"}"
    try:
        return parse_json_batch(b'{"readings":[' + body + b"]}", info.ingest_arrays(), lim)
    except IngestError as exc:
        return _rejected(topic, payload, exc)


def single_value(topic: str, payload: bytes, quantity: str) -> float | Rejection:
    """The number of a single-value message (``…/{array}/power``), or its rejection naming
    the field."""
    try:
        return parse_value(payload, quantity)
    except IngestError as exc:
        return _rejected(topic, payload, exc)


def minute_batch(info: SiteInfo, closed: Closed, lim: Limits) -> Batch | Rejection:
    """Validate a minute assembled from single values (see :mod:`backend.mqtt.assemble`)."""
    topic = ", ".join(sorted(set(closed.topics)))
    when = dt.datetime.fromtimestamp(closed.minute_s, dt.UTC).isoformat()
    if closed.missing:
        got = ", ".join(sorted(closed.values)) or "nothing"
        return Rejection(topic, f"minute {when} of array {closed.array!r} closed without "
                                f"{' and '.join(closed.missing)} (got {got})")
    reading = {"ts": when, "array": closed.array, **closed.values}
    body = orjson.dumps({"readings": [reading]})
    try:
        return parse_json_batch(body, info.ingest_arrays(), lim)
    except IngestError as exc:
        return _rejected(topic, orjson.dumps(reading), exc)
