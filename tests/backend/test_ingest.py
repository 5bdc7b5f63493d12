"""Bulk validation (``backend/measurements/parse.py``): timestamps, ADC, row/field errors."""

from __future__ import annotations

import datetime as dt

import numpy as np
import orjson
import pytest

from backend.measurements.parse import (
    Calibration,
    IngestError,
    Limits,
    adc_to_volts_amps,
    parse_csv_batch,
    parse_json_batch,
)

ARRAYS = {"tracker": (1, Calibration()), "fixed": (2, Calibration(divider_ratio=8.0))}


def test_vectorised_timestamps_agree_with_fromisoformat() -> None:
    rng = np.random.default_rng(0)
    secs = rng.integers(700_000_000, 1_900_000_000, 400)
    offsets = rng.integers(-14 * 4, 14 * 4, 400) * 15
    texts = [dt.datetime.fromtimestamp(int(s), dt.timezone(dt.timedelta(minutes=int(o))))
             .isoformat() for s, o in zip(secs, offsets, strict=True)]
    texts[7] = texts[7][:19] + "Z"
    texts[8] = texts[8].replace("T", " ")
    texts[9] = "2024-03-15T12:00:00.75+00:00"  # other ISO forms go the slow way
    readings = [{"ts": t, "array": "tracker", "voltage_v": 1.0, "current_a": 1.0}
                for t in texts]
    batch = parse_json_batch(orjson.dumps({"readings": readings}), ARRAYS,
                             Limits(future_tolerance_s=10**10))
    expected = [int(dt.datetime.fromisoformat(t.replace("Z", "+00:00")).timestamp())
                for t in texts]
    assert batch.ts_s.tolist() == expected


@pytest.mark.parametrize("bad", ["2024-02-30T00:00:00Z", "2023-02-29T00:00:00Z",
                                 "2024-13-01T00:00:00Z", "2024-01-01T24:00:00Z",
                                 "2024-01-01T00:00:00+25:00"])
def test_impossible_dates_are_rejected(bad: str) -> None:
    good = {"ts": "2024-01-01T00:00:00Z", "array": "tracker", "voltage_v": 1, "current_a": 1}
    body = orjson.dumps({"readings": [good] * 40 + [dict(good, ts=bad)]})
    with pytest.raises(IngestError) as err:
        parse_json_batch(body, ARRAYS, Limits())
    assert err.value.errors[0]["row"] == 40 and err.value.errors[0]["field"] == "ts"


def test_adc_conversion_seed000_eqs_16_to_19() -> None:
    """ACS712-30A: 2.5 V at 0 A, 100 mV/A; 10-bit ADC on 5 V (seed 000, eqs. 16–17, 19)."""
    cal = Calibration(divider_ratio=11.0)
    v, i = adc_to_volts_amps(np.array([0.0, 512.0, 1023.0]), np.array([512.0, 0.0, 1023.0]),
                             cal)
    # by hand: 512 counts = 2.5024 V on the pin; 1023 counts = 5 V
    assert v.tolist() == pytest.approx([0.0, 512 * 5 / 1023 * 11, 55.0])
    assert i.tolist() == pytest.approx([(512 * 5 / 1023 - 2.5) / 0.1, -25.0, 25.0])


def test_csv_and_json_give_the_same_batch() -> None:
    rows = [("2024-05-01T10:00:00-06:00", "tracker", 26.1, 20.5),
            ("2024-05-01T10:01:00-06:00", "fixed", 25.9, 18.25)]
    js = orjson.dumps({"readings": [dict(zip(("ts", "array", "voltage_v", "current_a"), r,
                                             strict=True)) for r in rows]})
    cs = ("ts,array,voltage_v,current_a\n" + "".join(",".join(map(str, r)) + "\n"
                                                     for r in rows)).encode()
    a = parse_json_batch(js, ARRAYS, Limits())
    b = parse_csv_batch(cs, ARRAYS, Limits())
    for f in ("array_ids", "ts_s", "voltage_v", "current_a", "power_w"):
        assert getattr(a, f).tolist() == getattr(b, f).tolist()
    assert a.power_w.tolist() == pytest.approx([26.1 * 20.5, 25.9 * 18.25])


def test_errors_are_collected_per_row_and_capped() -> None:
    readings = [{"ts": "2024-05-01T10:00:00", "array": "tracker", "voltage_v": 1,
                 "current_a": 1}] * 50
    with pytest.raises(IngestError) as err:
        parse_json_batch(orjson.dumps({"readings": readings}), ARRAYS, Limits())
    assert err.value.status == 422
    assert [e["row"] for e in err.value.errors] == list(range(20))


def test_row_limit_is_413() -> None:
    one = {"ts": "2024-05-01T10:00:00Z", "array": "tracker", "voltage_v": 1, "current_a": 1}
    with pytest.raises(IngestError) as err:
        parse_json_batch(orjson.dumps({"readings": [one] * 11}), ARRAYS, Limits(max_rows=10))
    assert err.value.status == 413 and "limit is 10" in err.value.errors[0]["msg"]


@pytest.mark.parametrize(("value", "field"), [
    (True, "voltage_v"),     # a JSON boolean is not a number (NumPy would read 1.0)
    ([26.0], "voltage_v"),   # a list would become a 2-D column and fail in the database
    ({"v": 1}, "current_a"),
    ("26,1", "current_a"),
])
def test_non_numbers_are_422_naming_the_field(value: object, field: str) -> None:
    one = {"ts": "2024-05-01T10:00:00Z", "array": "tracker", "voltage_v": 26.0,
           "current_a": 7.0}
    body = orjson.dumps({"readings": [one, dict(one, **{field: value})]})
    with pytest.raises(IngestError) as err:
        parse_json_batch(body, ARRAYS, Limits())
    assert err.value.status == 422
    assert (err.value.errors[0]["row"], err.value.errors[0]["field"]) == (1, field)


def test_1970_epoch_is_before_1990() -> None:
    one = {"ts": "1970-01-01T00:00:00Z", "array": "tracker", "voltage_v": 1, "current_a": 1}
    with pytest.raises(IngestError) as err:
        parse_json_batch(orjson.dumps({"readings": [one]}), ARRAYS, Limits())
    assert err.value.errors[0]["field"] == "ts" and "1990" in err.value.errors[0]["msg"]


@pytest.mark.parametrize(("body", "needle"), [
    ('ts,array,voltage_v,current_a\n2024-05-01T10:00:00Z,"' + "a" * 200_000 + '",1,1\n',
     "line 2"),
    ("ts,ts,array,voltage_v,current_a\n2024-05-01T10:00:00Z,x,tracker,1,1\n", "twice"),
])
def test_malformed_csv_is_422(body: str, needle: str) -> None:
    with pytest.raises(IngestError) as err:
        parse_csv_batch(body.encode(), ARRAYS, Limits())
    assert err.value.status == 422 and needle in err.value.errors[0]["msg"]
