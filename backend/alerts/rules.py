"""The alert conditions, as pure functions (no database, no clock of their own).

Each rule looks at one thing the service knows and returns a :class:`Evaluation`: the
conditions that hold now (each with its start, its words and its numbers) and the
*scope* it looked at — the ``(site_id, array, kind)`` triples it could evaluate. The
evaluator (:mod:`backend.alerts.service`) raises a condition not yet active and clears
an active alert of a scope the rule evaluated whose condition no longer holds; an alert
outside every evaluated scope (its rule failed, or could not tell: no readings, no
diagnosis) is left as it is — "unknown" is never "all clear".

Kinds:

- ``logger_silent`` — an array whose logger has reported before has no reading for
  ``Settings.alerts.silent_min`` minutes, or for :data:`SILENT_CADENCES` of its own cadence
  when that is longer (a logger slower than :data:`FRESH_S`: a 30-minute logger's next
  reading is due just as 30 minutes run out); the silence is counted from the service's start
  at the earliest (a logger cannot report to a service that was down), and by default
  only while the sun is up (``Settings.alerts.silent_daylight_only``: many loggers
  sleep at night). ``since``: its last reading.
- ``fault`` (``fault_kind`` = the diagnosis' kind) — a fault of confidence ≥
  ``Settings.alerts.fault_confidence_min`` on the latest diagnosed day (yesterday, local);
  ``since``: the fault's first day (local midnight), or the minute a tracker stopped
  part-way through it (the fault's ``since_time``). Cleared when the latest day no
  longer shows it. This includes ``underperformance``: a day whose measured tracker
  energy is below the lower edge of its expected band, with its size in Wh and %
  (``data["shortfall_wh"]``), even when no multi-day signature names the cause, and
  ``fixed_underperformance``, raised on the fixed array (a day's sky from a sensor).
- ``low_performance_ratio`` — the tracker's performance ratio under the measured sky
  (``diagnosis``: measured / expected, ``sky.source`` ``sensor`` or ``fixed_array``) of the latest
  such day is below ``Settings.alerts.pr_below``; ``since``: the first day of the run of
  low days. Days whose sky fell back to clear sky are not judged (a cloudy day would
  read as a fault).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal
from zoneinfo import ZoneInfo

import numpy as np

from backend.diagnosis.faults import FAULT_WORDS

AlertKind = Literal["logger_silent", "fault", "low_performance_ratio"]
KIND_WORDS: dict[str, str] = {"logger_silent": "Logger silent", "fault": "Fault",
                                    "low_performance_ratio": "Low performance ratio"}


#: A logger is late after this many of its own cadences (the median interval of its latest
#: readings, :func:`cadence_s`): the overview's stale logger and the ``logger_silent`` alert
SILENT_CADENCES = 2.5
#: Readings at most this far apart [s] are a minute logger's: the overview calls it stale
#: after this at the least, and the alert's threshold alone judges its silence
FRESH_S = 300
#: the latest readings a logger's cadence is read from
CADENCE_READINGS = 11


def cadence_s(ts_desc_s: list[float]) -> float:
    """A logger's cadence [s]: the median interval of its latest readings ``ts_desc_s``
    (newest first); 0 with fewer than two."""
    steps = -np.diff(np.asarray(ts_desc_s, np.float64))
    return float(np.median(steps)) if steps.size else 0.0


Key = tuple[str, str, str, str]
Scope = tuple[str, str, str]


@dataclass(frozen=True)
class Condition:
    """A condition that holds now."""

    site_id: str
    array: str
    kind: str
    since_s: int
    detail: str
    data: dict[str, Any] = field(default_factory=dict, compare=False)
    fault_kind: str | None = None

    @property
    def key(self) -> Key:
        """Identity of the condition: one active alert per key."""
        return (self.site_id, self.array, self.kind, self.fault_kind or "")

    @property
    def scope(self) -> Scope:
        return (self.site_id, self.array, self.kind)


@dataclass
class Evaluation:
    """What a rule found: conditions, the scopes it evaluated, words for clearing."""

    conditions: list[Condition] = field(default_factory=list)
    scopes: set[Scope] = field(default_factory=set)
    #: per scope, what is true now, for the ``cleared_detail`` of an alert that ends
    clear_notes: dict[Key | Scope, str] = field(default_factory=dict)

    def extend(self, other: Evaluation) -> None:
        self.conditions += other.conditions
        self.scopes |= other.scopes
        self.clear_notes.update(other.clear_notes)


def local_text(ts_s: float, zone: ZoneInfo) -> str:
    """``2026-12-02 14:03 UTC−06:00``: an instant in the site's zone, with its offset."""
    t = dt.datetime.fromtimestamp(ts_s, zone)
    off = t.utcoffset() or dt.timedelta(0)
    minutes = int(off.total_seconds() // 60)
    sign = "−" if minutes < 0 else "+"
    return f"{t:%Y-%m-%d %H:%M} UTC{sign}{abs(minutes) // 60:02d}:{abs(minutes) % 60:02d}"


def duration_text(seconds: float) -> str:
    """``47 min``, ``3.2 h``, ``2.1 days``."""
    minutes = max(0.0, seconds) / 60.0
    if minutes < 90:
        return f"{minutes:.0f} min" if minutes >= 1 else f"{seconds:.0f} s"
    if minutes < 48 * 60:
        return f"{minutes / 60:.1f} h"
    return f"{minutes / 1440:.1f} days"


def day_start_s(date: str, zone: ZoneInfo) -> int:
    """Local midnight of a ``YYYY-MM-DD`` day [Unix s]."""
    d = dt.date.fromisoformat(date)
    return int(dt.datetime(d.year, d.month, d.day, tzinfo=zone).timestamp())


def silent_loggers(site_id: str, zone: ZoneInfo, last_ts: dict[str, int | None], now_s: float,
                   started_s: float, silent_min: float,
                   counted_s: Callable[[float, float], float] | None = None,
                   cadence_s: dict[str, float] | None = None) -> Evaluation:
    """``logger_silent`` for each array of ``last_ts`` (its last measured reading [Unix s],
    None when it never reported: no alert, nothing to be silent about).

    ``counted_s(a, b)``: the seconds of ``[a, b]`` that count as silence (the daylight
    seconds, by default of the service); None: all of them. ``cadence_s``: each array's
    logger cadence [s] (:func:`cadence_s`); a logger slower than :data:`FRESH_S` is silent
    after :data:`SILENT_CADENCES` of it when that is longer than ``silent_min`` — a
    30-minute logger was raised and cleared every half hour. The service's start is
    waited for ``silent_min`` alone."""
    out = Evaluation()
    counted = counted_s or (lambda a, b: b - a)
    daylight = counted_s is not None
    for array, last in last_ts.items():
        cadence = (cadence_s or {}).get(array, 0.0)
        slow = cadence if cadence > FRESH_S else 0.0
        limit_s = max(silent_min * 60.0, SILENT_CADENCES * slow)
        scope = (site_id, array, "logger_silent")
        if last is None:
            out.scopes.add(scope)
            out.clear_notes[scope] = f"the {array} logger has no readings at all"
            continue
        silent_s = counted(last, now_s)
        if silent_s >= limit_s and counted(started_s, now_s) < silent_min * 60.0:
            continue  # silent, but the service has not listened long enough to say so
        out.scopes.add(scope)
        if silent_s >= limit_s:
            of = " of daylight" if daylight else ""
            out.conditions.append(Condition(
                site_id, array, "logger_silent", int(last),
                f"no reading from the {array} logger for {duration_text(silent_s)}{of} "
                f"(last one {local_text(last, zone)}); alert after "
                f"{duration_text(limit_s)}{of} without one"
                + (f" ({SILENT_CADENCES:g} × its cadence {duration_text(cadence)})"
                   if limit_s > silent_min * 60.0 else ""),
                {"last_reading_ts": _iso(last), "silent_min": round(silent_s / 60, 1),
                 "threshold_min": round(limit_s / 60.0, 2), "daylight_only": daylight}))
        else:
            out.clear_notes[scope] = (f"the {array} logger reports again: last reading "
                                      f"{local_text(last, zone)}")
    return out


def _iso(ts_s: float) -> str:
    return dt.datetime.fromtimestamp(int(ts_s), dt.UTC).isoformat().replace("+00:00", "Z")


def diagnosed(site_id: str, zone: ZoneInfo, tracker: str, days: list[dict[str, Any]],
              pr_below: float, confidence_min: float) -> Evaluation:
    """``fault`` and ``low_performance_ratio`` from a diagnosis answer's ``days`` (oldest
    first, the latest complete day last; ``backend.diagnosis.service.diagnosis``)."""
    out = Evaluation()
    if not days:
        return out
    latest = days[-1]
    note = f"not found in the diagnosis of {latest['date']}"
    # each array's findings are judged where it has readings or a finding: the tracker's,
    # and the fixed array's own (fixed_underperformance, under a sensor's sky)
    for array, name in (("tracker", tracker), ("fixed", "fixed")):
        found = [f for f in latest["faults"] if f.get("array", "tracker") == array]
        if (latest.get(array) or {}).get("measured_wh") is None and not found:
            continue
        out.scopes.add((site_id, name, "fault"))
        out.clear_notes[(site_id, name, "fault")] = note
        for f in found:
            if f["confidence"] < confidence_min:
                continue
            # the fault's kind in words is the alert's title (summary(), the dashboard's
            # alertTitle): the detail does not say it again
            # a tracker that stopped part-way through a day: since that minute
            since_s = (int(dt.datetime.fromisoformat(f["since_time"]).timestamp())
                       if f.get("since_time") else day_start_s(f["since"], zone))
            out.conditions.append(Condition(
                site_id, name, "fault", since_s,
                f"{f['detail']} (since {f['since']}, confidence {f['confidence']:.2f}, "
                f"diagnosis of {latest['date']})",
                {"fault_kind": f["kind"], "confidence": f["confidence"],
                 "magnitude": f["magnitude"], "unit": f["unit"], "since_date": f["since"],
                 "day": latest["date"],
                 **({"shortfall_wh": f["shortfall_wh"]} if "shortfall_wh" in f else {}),
                 **({"since_time": f["since_time"]} if f.get("since_time") else {})},
                fault_kind=f["kind"]))
    judged = [d for d in days if d["sky"].get("source") in ("sensor", "fixed_array")
              and d["tracker"].get("performance_ratio") is not None]
    if judged:
        scope = (site_id, tracker, "low_performance_ratio")
        out.scopes.add(scope)
        last = judged[-1]
        pr = float(last["tracker"]["performance_ratio"])
        if pr < pr_below:
            first = last
            for d in reversed(judged):
                if float(d["tracker"]["performance_ratio"]) >= pr_below:
                    break
                first = d
            t = last["tracker"]
            out.conditions.append(Condition(
                site_id, tracker, "low_performance_ratio", day_start_s(first["date"], zone),
                f"the {tracker} made {100 * pr:.0f} % of what the twin expected under the "
                f"measured sky on {last['date']} ({_kwh(t.get('measured_wh'))} of "
                f"{_kwh(t.get('expected_wh'))}); alert below {100 * pr_below:.0f} %"
                + (f", low since {first['date']}" if first is not last else ""),
                {"performance_ratio": round(pr, 4), "threshold": pr_below,
                 "day": last["date"], "first_low_day": first["date"],
                 "measured_wh": t.get("measured_wh"), "expected_wh": t.get("expected_wh")}))
        else:
            out.clear_notes[scope] = (f"performance ratio {pr:.2f} on {last['date']}, at or "
                                      f"above {pr_below:.2f}")
    return out


def _kwh(wh: float | None) -> str:
    return "—" if wh is None else f"{wh / 1000:.2f} kWh"


def summary(site_id: str, kind: str, array: str, fault_kind: str | None, state: str,
            detail: str) -> str:
    """One line for chat webhooks (the body's ``text``); ``state``: ``active`` (raised),
    ``acknowledged`` or ``cleared``."""
    head = {"cleared": "cleared", "acknowledged": "acknowledged"}.get(state, "ALERT")
    return f"heliotwin {site_id} / {array}: {head} — {title(kind, fault_kind)}: {detail}"


def title(kind: str, fault_kind: str | None) -> str:
    """``Fault: tracker stuck`` — an alert's kind (and its fault's) in words: the
    dashboard's alerts card and the webhook's text."""
    words = KIND_WORDS.get(kind, kind)
    return words if fault_kind is None else f"{words}: {FAULT_WORDS.get(fault_kind, fault_kind)}"


def acknowledged_text(alert: dict[str, Any]) -> str:
    """``by Ana (night shift): sent Luis to the drive`` — who took an alert, and their note."""
    note = alert["acknowledged_note"]
    return f"by {alert['acknowledged_by']}" + (f": {note}" if note else "")
