"""OpenDTU-style single values (``…/{array}/voltage``, ``…/current``, ``…/power``) → readings.

Loggers like OpenDTU, AhoyDTU, Tasmota or ESPHome publish each quantity on a
topic of its own, as a bare number, without a timestamp, every few seconds.
:class:`MinuteAssembler` turns them into one reading per array per minute:

- a value belongs to the UTC minute in which the service receives it, and the
  reading is stamped at that minute's start;
- a minute's reading holds the first value of each quantity received in it (the
  samples nearest its stamp); a quantity's later values in the same minute are
  superseded samples (counted, not stored, not errors), whether the minute is still
  open or already closed;
- a minute closes as soon as it holds voltage, current *and* power;
- a minute still open ``grace_s`` after it ended closes then: with voltage and
  current it is a reading (``power_w`` left out, so the ingest rule makes it
  voltage·current); with power alone it is a power-only reading (a meter or an
  inverter that publishes only power); with one of voltage and current but not
  the other it is rejected with the name of the missing quantity;
- :meth:`MinuteAssembler.flush` closes everything still open (at shutdown).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from backend.measurements.parse import decimal_value

#: topic quantity → reading field
QUANTITIES = {"voltage": "voltage_v", "current": "current_a", "power": "power_w"}


def parse_value(payload: bytes, quantity: str) -> float:
    """A bare decimal number (``26.1``, ``-0.02``, ``1e3``) → float, by the rule of a
    number in HTTP's CSV (:func:`backend.measurements.parse.decimal_value`); else an
    ``IngestError`` naming the quantity's field (``power_w``), as HTTP's do."""
    return decimal_value(payload.decode("utf-8-sig", "replace"), QUANTITIES[quantity])


@dataclass
class Closed:
    """A closed minute: a reading (``values`` has voltage_v and current_a, or power_w
    alone) or a rejection (``missing`` names what it lacks)."""

    site_id: str
    array: str
    minute_s: int
    values: dict[str, float]
    missing: list[str]
    topics: list[str]


@dataclass
class _Open:
    minute_s: int
    values: dict[str, float] = field(default_factory=dict)
    topics: list[str] = field(default_factory=list)


class MinuteAssembler:
    """Open minutes per (site, array); see the module docstring for the rule."""

    def __init__(self, grace_s: float) -> None:
        self.grace_s = grace_s
        self._open: dict[tuple[str, str], _Open] = {}
        self._done: dict[tuple[str, str], int] = {}  # last minute closed complete
        self.superseded = 0

    def add(self, site_id: str, array: str, quantity: str, value: float, topic: str,
            now_s: float) -> list[Closed]:
        """Take one value received at ``now_s``; the minutes this closes."""
        key = (site_id, array)
        minute = int(now_s // 60 * 60)
        out: list[Closed] = []
        cur = self._open.get(key)
        if cur is not None and cur.minute_s != minute:
            out.append(self._close(key))
            cur = None
        if cur is None:
            if self._done.get(key) == minute:
                self.superseded += 1
                return out
            cur = self._open[key] = _Open(minute)
        if QUANTITIES[quantity] in cur.values:
            self.superseded += 1
            return out
        cur.values[QUANTITIES[quantity]] = value
        cur.topics.append(topic)
        if len(cur.values) == len(QUANTITIES):
            out.append(self._close(key))
        return out

    def due(self, now_s: float) -> list[Closed]:
        """Close the minutes that ended more than ``grace_s`` before ``now_s``."""
        late = [k for k, o in self._open.items() if o.minute_s + 60 + self.grace_s <= now_s]
        return [self._close(k) for k in late]

    def flush(self) -> list[Closed]:
        """Close every open minute."""
        return [self._close(k) for k in list(self._open)]

    def _close(self, key: tuple[str, str]) -> Closed:
        o = self._open.pop(key)
        if set(o.values) == {"power_w"}:
            missing = []  # power-only
        else:
            missing = [q for q, f in QUANTITIES.items() if f not in o.values and f != "power_w"]
        if not missing:
            self._done[key] = o.minute_s
        return Closed(key[0], key[1], o.minute_s, o.values, missing, o.topics)
