"""The per-period comparison (:func:`backend.measurements.energy.compare`) and the report's
CSV and title, without a service: the numbers are a tester's (tehuantepec, Dec 3 with
tracker readings and no fixed ones, Dec 4 with both)."""

from __future__ import annotations

import pytest

from backend.measurements.energy import COVERED, SHARED, compare


def arr(measured: float | None, twin: float, matched: float | None, readings: int,
        covered: float, shared: float) -> dict:
    return {"measured_wh": measured, "twin_wh": twin, "twin_matched_wh": matched,
            "readings": readings, COVERED: covered, SHARED: shared}


def test_the_twin_gain_over_the_same_minutes_is_over_the_minutes_both_loggers_cover() -> None:
    # two days summed: the tracker read both, the fixed logger only the second
    total = compare({"tracker": arr(11568.8, 12132.3, 12132.3, 2880, 12132.3, 6062.6),
                     "fixed": arr(4538.4, 9083.9, 4538.4, 288, 4538.4, 4538.4)},
                    "tracker", "fixed")
    assert total["twin_matched_gain_pct"] == pytest.approx(100 * (6062.6 / 4538.4 - 1))
    assert total["gain_pct"] is None and "different minutes" in total["gain_note"]


def test_a_day_without_fixed_readings_has_no_same_minutes_gain_and_says_why() -> None:
    day = compare({"tracker": arr(6069.7, 6069.7, 6069.7, 1440, 6069.7, 0.0),
                   "fixed": arr(None, 4545.5, None, 0, 0.0, 0.0)}, "tracker", "fixed")
    assert day["twin_matched_gain_pct"] is None and day["gain_pct"] is None
    assert day["gain_note"] == "the fixed array has no readings: the loggers share no minutes"
    assert day["twin_gain_pct"] == pytest.approx(100 * (6069.7 / 4545.5 - 1))


def test_readings_too_far_apart_to_bridge_say_so() -> None:
    """A tester's finding: a 30-minute logger at the default gap (1,200 s) read
    ``measured_wh`` 0.0 for both arrays and the note "the fixed array measured no energy";
    its readings were there, none within the gap of the next. (The tester's day: 48
    readings each, 8.9 kWh true, 0.0 counted.)"""
    day = compare({"tracker": arr(0.0, 9210.0, 0.0, 48, 0.0, 0.0),
                   "fixed": arr(0.0, 6530.0, 0.0, 48, 0.0, 0.0)}, "tracker", "fixed")
    assert day["gain_pct"] is None and day["partial"] is True
    assert day["gain_note"].startswith("the tracker and the fixed array have readings but "
                                       "none within max_gap_s of the next"), day["gain_note"]
    assert "HELIOTWIN_ENERGY_MAX_GAP_S" in day["gain_note"]
    one = compare({"tracker": arr(5000.0, 9210.0, 5000.0, 1440, 9210.0, 0.0),
                   "fixed": arr(0.0, 6530.0, 0.0, 48, 0.0, 0.0)}, "tracker", "fixed")
    assert one["gain_note"].startswith("the fixed array has readings but none"), one


def _silent_fixed_day() -> dict:
    arrays = {"tracker": arr(6069.7, 6069.7, 6069.7, 1440, 6069.7, 0.0),
              "fixed": arr(None, 4545.5, None, 0, 0.0, 0.0)}
    return {"period_start": "2026-12-03T00:00:00-06:00",
            "period_end": "2026-12-04T00:00:00-06:00", "arrays": arrays,
            **compare(arrays, "tracker", "fixed"), "twin_note": None}


def test_a_day_without_fixed_readings_is_partial() -> None:
    assert _silent_fixed_day()["partial"] is True
    night = compare({"tracker": arr(None, 0.0, None, 0, 0.0, 0.0),
                     "fixed": arr(None, 0.0, None, 0, 0.0, 0.0)}, "tracker", "fixed")
    assert night["partial"] is None  # nothing read, nothing expected


def test_the_report_csv_says_why_a_gain_is_empty_and_flags_the_partial_day() -> None:
    import csv
    import io

    from backend.reports import report_csv

    day = _silent_fixed_day()
    rep = {"arrays": ["tracker", "fixed"], "days": [day], "months": [], "years": [],
           "totals": {k: v for k, v in day.items() if k not in ("period_start", "period_end")},
           "start": day["period_start"], "end": day["period_end"]}
    rows = list(csv.DictReader(io.StringIO(report_csv(rep))))
    for row in rows:
        assert row["partial"] == "True" and row["gain_pct"] == ""
        assert row["gain_note"] == "the fixed array has no readings: the loggers share no minutes"
