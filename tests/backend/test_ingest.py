"""Logger ingest without HTTP: bulk validation (``backend/measurements/parse.py``: timestamps,
ADC, row/field errors) and the service around it (``backend/measurements/ingest.py``)."""

from __future__ import annotations

import asyncio
import concurrent.futures
import datetime as dt
from concurrent.futures import Future
from typing import Any

import numpy as np
import orjson
import pytest

from backend.measurements.ingest import THREAD_FROM_BYTES, StorageUnavailable, ingest, parser_for
from backend.measurements.parse import (
    Calibration,
    IngestArray,
    IngestError,
    Limits,
    adc_to_volts_amps,
    parse_csv_batch,
    parse_json_batch,
)
from backend.measurements.writer import PartlyStored

ARRAYS = {"tracker": IngestArray(1, Calibration(), 820.0),
          "fixed": IngestArray(2, Calibration(divider_ratio=8.0))}


def _run(coro: Any) -> Any:
    """``asyncio.run`` on a thread of its own: a test that ran before in this process (the
    browser tests' Playwright, under xdist) may have left this thread's event loop running."""
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, coro).result()


def test_bulk_timestamps_agree_with_fromisoformat() -> None:
    """pandas (one offset per batch) and the standard library give the same seconds."""
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


@pytest.mark.parametrize("rows", [5, 40])
def test_a_batch_of_any_length_reads_a_stamp_alike(rows: int) -> None:
    """Short batches go row by row, long ones through pandas: the same stamps are taken
    either way (``2026-1-5T12:00:00Z`` was refused in 31 rows and taken in 32), RFC 3339's
    lower-case ``z`` included; a stamp without offset is refused either way."""
    good = {"ts": "2026-01-05T11:00:00Z", "array": "tracker", "voltage_v": 1, "current_a": 1}
    odd = ["2026-1-5T12:00:00Z", "2026-01-05t12:01:00z", "2026-01-05T12:02:00,5+00:00"]
    readings = [good] * (rows - len(odd)) + [dict(good, ts=t) for t in odd]
    batch = parse_json_batch(orjson.dumps({"readings": readings}), ARRAYS,
                             Limits(future_tolerance_s=10**10))
    noon = int(dt.datetime(2026, 1, 5, 12, tzinfo=dt.UTC).timestamp())
    assert batch.ts_s[-3:].tolist() == [noon, noon + 60, noon + 120]
    naive = readings[:-1] + [dict(good, ts="2026-1-5T12:00:00")]
    with pytest.raises(IngestError) as err:
        parse_json_batch(orjson.dumps({"readings": naive}), ARRAYS, Limits())
    assert err.value.errors[0]["row"] == rows - 1 and "offset" in err.value.errors[0]["msg"]


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
    listed = err.value.errors
    assert [e["row"] for e in listed[:-1]] == list(range(10))  # 10 per field ...
    assert listed[-1]["type"] == "too_many_errors"  # ... and the rest counted
    assert listed[-1]["msg"] == "40 more problems not listed (ts: 40)"


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


@pytest.mark.parametrize(("reading", "words"), [
    ({"power_w": 50_000.0}, "over 2 × array 'tracker''s rating (820 W at STC)"),
    ({"power_w": 1.7}, None),  # kW on a power-only logger: plausible alone (the diagnosis
    # names it: sky_unusable); 1,650 W, twice the rating and the tolerance, passes too
    ({"power_w": 1645.0}, None),
    ({"voltage_v": 40.0, "current_a": 45.0}, "over 2 × array 'tracker''s rating"),
    ({"power_w": -810.0}, "below -46 W (-5 % of array 'tracker''s rating"),
    ({"power_w": -40.0}, None),  # an inverter's night draw
    ({"voltage_v": 26.0, "current_a": -1.0}, None),  # the current's own bound holds it
])
def test_power_is_bounded_by_the_arrays_rating(reading: dict, words: str | None) -> None:
    """A tester's finding: 50 kW on an 820 W array and a tracker at −P all day were stored
    and counted (+9 % of a day's energy, PR −1.006) while −31 A as current was refused.
    Over twice the array's STC rating (any reading) or under −5 % of it (power alone) is a
    422 naming the array's rating; an array without a known rating keeps the service's
    voltage × current bounds only."""
    one = {"ts": "2024-05-01T10:00:00Z", "array": "tracker", **reading}
    body = orjson.dumps({"readings": [one]})
    if words is None:
        assert len(parse_json_batch(body, ARRAYS, Limits())) == 1
    else:
        with pytest.raises(IngestError) as err:
            parse_json_batch(body, ARRAYS, Limits())
        assert [e["field"] for e in err.value.errors] == ["power_w"], err.value.errors
        assert words in err.value.errors[0]["msg"], err.value.errors
    unrated = orjson.dumps({"readings": [{**one, "array": "fixed"}]})
    if "current_a" not in reading:  # the fixed array here has no rating: no bound from it
        assert len(parse_json_batch(unrated, ARRAYS, Limits())) == 1


@pytest.mark.parametrize(("body", "needle"), [
    ('ts,array,voltage_v,current_a\n2024-05-01T10:00:00Z,"' + "a" * 200_000 + '",1,1\n',
     "line 2"),
    ("ts,ts,array,voltage_v,current_a\n2024-05-01T10:00:00Z,x,tracker,1,1\n", "twice"),
])
def test_malformed_csv_is_422(body: str, needle: str) -> None:
    with pytest.raises(IngestError) as err:
        parse_csv_batch(body.encode(), ARRAYS, Limits())
    assert err.value.status == 422 and needle in err.value.errors[0]["msg"]


GOOD = {"ts": "2024-05-01T10:00:00Z", "array": "tracker", "voltage_v": 26.0, "current_a": 7.0}


def _errors(body: bytes, csv: bool = False) -> list[dict]:
    with pytest.raises(IngestError) as err:
        (parse_csv_batch if csv else parse_json_batch)(body, ARRAYS, Limits())
    assert err.value.status == 422
    return err.value.errors


def test_every_kind_of_problem_is_reported_at_once() -> None:
    """Issue 14: a power mismatch is not held back until the other errors are fixed."""
    rows = [dict(GOOD, ts="2024-05-01T10:00:00"), dict(GOOD, array="roof"),
            dict(GOOD, power_w=999.0), dict(GOOD, voltage_v="x"), dict(GOOD, current_a=500.0)]
    got = {(e["row"], e["field"]) for e in _errors(orjson.dumps({"readings": rows}))}
    assert got == {(0, "ts"), (1, "array"), (2, "power_w"), (3, "voltage_v"), (4, "current_a")}


def test_a_list_as_one_timestamp_in_a_long_batch_is_named() -> None:
    """Issue 9: ≥ 32 rows go to pandas; a ragged value once emptied the column."""
    rows = [GOOD] * 40 + [dict(GOOD, ts=["2024-05-01T10:00:00Z"])]
    assert [(e["row"], e["field"]) for e in _errors(orjson.dumps({"readings": rows}))] == [
        (40, "ts")]


@pytest.mark.parametrize("cell", ["1_0", "١٢", "nan", "Infinity", "0x10", "1e", "--1"])
def test_csv_numbers_are_plain_decimals_only(cell: str) -> None:
    body = f"ts,array,voltage_v,current_a\n2024-05-01T10:00:00Z,tracker,{cell},1\n".encode()
    (e,) = _errors(body, csv=True)
    assert (e["row"], e["field"], e["line"]) == (0, "voltage_v", 2) and cell in e["msg"]


def test_csv_accepts_every_plain_decimal_form() -> None:
    cells = ["26", "26.", ".5", "+26.5", "-0.25", "2.65e1", "2650E-2"]
    body = ("ts,array,voltage_v,current_a\n" + "".join(
        f"2024-05-01T10:{m:02d}:00Z,tracker,1,{c}\n" for m, c in enumerate(cells))).encode()
    batch = parse_csv_batch(body, ARRAYS, Limits())
    assert batch.current_a.tolist() == [float(c) for c in cells]


def test_unterminated_csv_quote_names_the_line_it_opens() -> None:
    body = b'ts,array,voltage_v,current_a\n2024-05-01T10:00:00Z,tracker,1,1\n' \
           b'2024-05-01T10:01:00Z,"tracker,1,1\n2024-05-01T10:02:00Z,tracker,1,1\n'
    (e,) = _errors(body, csv=True)
    assert e["msg"] == "CSV line 3: a quoted cell opened on line 3 is never closed"


def test_a_huge_csv_header_gets_a_small_answer() -> None:
    """Issue 9: 256k columns once cost O(n²) and echoed 2.5 MB; now one bounded message."""
    header = ",".join(f"c{k}" for k in range(262_144))
    (e,) = _errors(f"ts,array,{header}\n".encode(), csv=True)
    assert "262146 columns" in e["msg"] and len(orjson.dumps(e)) < 500
    # unknown columns: five named, the rest counted, so the message does not grow with them
    # (its fixed part, the accepted columns, grows with the product's fields)
    msgs = []
    for cols in ("c0,c1,c2,c3,c4,c5", ",".join(f"c{k}" for k in range(52))):
        (e,) = _errors(f"ts,array,voltage_v,current_a,{cols}\n".encode(), csv=True)
        msgs.append(e["msg"])
    small, big = msgs
    assert "unknown: 'c0', 'c1', 'c2', 'c3', 'c4' and 1 more" in small
    assert big == small.replace("and 1 more", "and 47 more")


def test_unknown_json_fields_are_422_like_unknown_csv_columns() -> None:
    (e,) = _errors(orjson.dumps({"readings": [GOOD, dict(GOOD, volts=26.0)]}))
    assert (e["row"], e["field"], e["type"]) == (1, "volts", "extra_forbidden")
    (e,) = _errors(orjson.dumps({"readings": [GOOD], "site": "tehuantepec"}))
    assert (e["row"], e["field"]) == (None, "site")


def test_repeated_json_keys_are_422() -> None:
    body = b'{"readings": [' + orjson.dumps(GOOD) + b', {"ts": "2024-05-01T10:01:00Z", ' \
           b'"array": "tracker", "voltage_v": 26.0, "voltage_v": 0.0, "current_a": 7.0}]}'
    (e,) = _errors(body)
    assert (e["row"], e["field"], e["type"]) == (1, "voltage_v", "duplicate_key")
    (e,) = _errors(b'{"readings": [' + orjson.dumps(GOOD) + b'], "readings": []}')
    assert (e["row"], e["field"], e["type"]) == (None, "readings", "duplicate_key")


def test_escaped_colons_are_not_taken_for_repeated_keys() -> None:
    """The cheap colon count is inconclusive here; the pair-keeping parse clears it."""
    body = b'{"readings": [{"ts": "2024-05-01T10\\u003a00\\u003a00Z", "array": "tracker", ' \
           b'"voltage_v": 26.0, "current_a": 7.0}]}'
    assert parse_json_batch(body, ARRAYS, Limits()).ts_s.tolist() == [1714557600]


def test_emoncms_rows_give_the_same_batch_as_objects() -> None:
    objs = [dict(GOOD, power_w=182.0), dict(GOOD, ts="2024-05-01T10:01:00Z", array="fixed")]
    rows = [[1714557600, "tracker", 26.0, 7.0, 182.0], [1714557660.9, "fixed", 26.0, 7.0]]
    a = parse_json_batch(orjson.dumps({"readings": objs}), ARRAYS, Limits())
    b = parse_json_batch(orjson.dumps(rows), ARRAYS, Limits())
    for f in ("array_ids", "ts_s", "voltage_v", "current_a", "power_w"):
        assert getattr(a, f).tolist() == getattr(b, f).tolist()


@pytest.mark.parametrize(("row", "field", "words"), [
    ([1714557600, "tracker", 26.0], None, "got 3 values"),
    ({"ts": 1714557600}, None, "got dict"),
    (["2024-05-01T10:00:00Z", "tracker", 26.0, 7.0], "ts", "send a JSON number"),
    ([None, "tracker", 26.0, 7.0], "ts", "unix_s is missing"),
    ([1714557600, "roof", 26.0, 7.0], "array", "unknown array"),
    # seconds as sent, never a clipped echo ("4611686016631082496 s after the server clock")
    ([2**63, "tracker", 26.0, 7.0], "ts", "unix_s 9223372036854775808 is not in 1990–2199"),
    ([1714557600000, "tracker", 26.0, 7.0], "ts", "milliseconds sent as seconds?"),
    ([599_616_000, "tracker", 26.0, 7.0], "ts", "unix_s 599616000 is not in 1990–2199"),
])
def test_bad_emoncms_rows_are_named(row: object, field: str | None, words: str) -> None:
    errors = _errors(orjson.dumps([[1714557600, "tracker", 26.0, 7.0], row]))
    assert (errors[0]["row"], errors[0]["field"]) == (1, field) and words in errors[0]["msg"]


@pytest.mark.parametrize("body", [
    [{"ts": "2026-11-20T18:36:00Z", "array": "tracker", "power_w": 1}],   # an object as a row
    {"readings": [[1714557600, "tracker", 26.0, 7.0]]},                   # a row as a reading
])
def test_a_row_of_the_wrong_shape_is_refused_once(body: object) -> None:
    """Its shape is the one problem: not also 'unix_s is missing', 'array: missing' and 'no
    electrical value' for what it did send (a tester's finding)."""
    (e,) = _errors(orjson.dumps(body))
    assert (e["row"], e["field"], e["type"]) == (0, None, "type_error"), e


def test_an_escape_cannot_hide_a_repeated_key() -> None:
    """One escaped colon in ``ts`` would balance one repeated key in a bare colon count."""
    body = b'{"readings": [{"ts": "2024-05-01T10\\u003a00:00Z", "array": "tracker", ' \
           b'"voltage_v": 26.0, "voltage_v": 0.0, "current_a": 7.0}]}'
    (e,) = _errors(body)
    assert (e["row"], e["field"], e["type"]) == (0, "voltage_v", "duplicate_key")


def test_a_batch_across_a_dst_change_is_parsed_row_by_row() -> None:
    """Two offsets in one batch (a logger on local time across a DST change): pandas
    refuses the mix, the standard library takes each row; the instants are the same."""
    texts = [f"2024-03-10T01:{m:02d}:00-06:00" for m in range(40)] + [
        f"2024-03-10T03:{m:02d}:00-05:00" for m in range(40)]
    readings = [{"ts": t, "array": "tracker", "voltage_v": 1.0, "current_a": 1.0}
                for t in texts]
    batch = parse_json_batch(orjson.dumps({"readings": readings}), ARRAYS, Limits())
    assert batch.ts_s.tolist() == [int(dt.datetime.fromisoformat(t).timestamp()) for t in texts]


def test_a_naive_stamp_in_a_long_batch_is_named() -> None:
    """A naive stamp among 40 with offsets: the one row, the field and why."""
    rows = [GOOD] * 40 + [dict(GOOD, ts="2024-05-01T10:00:00")] + [GOOD] * 5
    (e,) = _errors(orjson.dumps({"readings": rows}))
    assert (e["row"], e["field"], e["type"]) == (40, "ts", "timezone_naive")
    assert "no UTC offset" in e["msg"]


def test_a_long_batch_of_naive_stamps_names_each_row() -> None:
    rows = [dict(GOOD, ts=f"2024-05-01T10:{m:02d}:00") for m in range(40)]
    errors = _errors(orjson.dumps({"readings": rows}))
    assert [(e["row"], e["field"]) for e in errors[:10]] == [(r, "ts") for r in range(10)]
    assert errors[-1]["msg"] == "30 more problems not listed (ts: 30)"


# ---------------------------------------------------------------- the service (ingest.py)


class _Writer:
    """A stand-in for the writer: a commit that gives ``result`` or raises ``error``."""

    def __init__(self, result: tuple[int, int] = (0, 0), error: Exception | None = None) -> None:
        self.result, self.error = result, error
        self.jobs: list[Any] = []

    def submit(self, job: Any) -> Future[tuple[int, int]]:
        self.jobs.append(job)
        done: Future[tuple[int, int]] = Future()
        if self.error is not None:
            done.set_exception(self.error)
        else:
            done.set_result(self.result)
        return done


def test_the_media_type_chooses_the_validator() -> None:
    assert parser_for(None) is parse_json_batch
    assert parser_for("application/json; charset=utf-8") is parse_json_batch
    assert parser_for("Text/CSV; header=present") is parse_csv_batch
    with pytest.raises(IngestError) as err:
        parser_for("text/plain")
    (e,) = err.value.errors
    assert err.value.status == 415 and e["loc"] == ["header", "content-type"]
    assert "send application/json or text/csv" in e["msg"]


@pytest.mark.parametrize("rows", [1, 600], ids=["small", "over_32_kib_on_a_thread"])
def test_ingest_answers_what_the_writer_committed(rows: int) -> None:
    readings = [dict(GOOD, ts=f"2024-05-01T{10 + m // 60:02d}:{m % 60:02d}:00Z", power_w=182.0)
                for m in range(rows)]
    for r in readings[1::2]:  # every other one from a power-only logger
        del r["voltage_v"], r["current_a"]
    body = orjson.dumps({"readings": readings})
    assert (len(body) > THREAD_FROM_BYTES) == (rows > 1)
    writer = _Writer(result=(rows - 1, 1))
    stored = _run(ingest(writer, parse_json_batch, body, ARRAYS, Limits()))  # type: ignore[arg-type]
    assert (stored.accepted, stored.duplicates, stored.readings) == (rows - 1, 1, rows)
    assert stored.power_only == rows // 2
    last = dt.datetime.fromisoformat(str(readings[-1]["ts"]))
    assert stored.stored_through_s == int(last.timestamp())
    (job,) = writer.jobs
    assert job.ts_s.tolist() == [int(dt.datetime.fromisoformat(str(r["ts"])).timestamp())
                                 for r in readings]


def test_a_failed_commit_is_storage_unavailable() -> None:
    writer = _Writer(error=OSError("disk full"))
    body = orjson.dumps({"readings": [GOOD]})
    with pytest.raises(StorageUnavailable, match="OSError.*nothing was stored"):
        _run(ingest(writer, parse_json_batch, body, ARRAYS, Limits()))  # type: ignore[arg-type]


def test_a_batch_failing_part_way_says_how_much_is_stored() -> None:
    """A batch committed in pieces that fails at one: the 503 says how many readings are
    stored and that sending it again is safe (the writer's test checks that it is)."""
    failed = PartlyStored(3000, 3510)
    failed.__cause__ = OSError("disk full")
    body = orjson.dumps({"readings": [GOOD]})
    with pytest.raises(StorageUnavailable, match=r"OSError.*3000 of 3510 readings were stored"
                                                 r".*send the batch again"):
        _run(ingest(_Writer(error=failed), parse_json_batch, body, ARRAYS, Limits()))  # type: ignore[arg-type]


def test_a_bad_batch_never_reaches_the_writer() -> None:
    writer = _Writer()
    body = orjson.dumps({"readings": [dict(GOOD, ts="2024-05-01T10:00:00")]})
    with pytest.raises(IngestError):
        _run(ingest(writer, parse_json_batch, body, ARRAYS, Limits()))  # type: ignore[arg-type]
    assert writer.jobs == []


def test_classic_mac_line_ends_and_a_json_byte_order_mark_are_read() -> None:
    """CR-only line ends gave Python's own "universal-newline mode" message; a JSON body
    with a byte order mark a 422, while a CSV with one was read."""
    limits = Limits(future_tolerance_s=10**10)
    cr = (b"ts,array,voltage_v,current_a\r2026-01-05T12:00:00Z,tracker,26,4\r"
          b"2026-01-05T12:01:00Z,tracker,26,5\r")
    assert parse_csv_batch(cr, ARRAYS, limits).ts_s.size == 2
    body = orjson.dumps({"readings": [{"ts": "2026-01-05T12:00:00Z", "array": "tracker",
                                       "voltage_v": 26, "current_a": 4}]})
    assert parse_json_batch(b"\xef\xbb\xbf" + body, ARRAYS, limits).ts_s.size == 1


def test_an_empty_line_between_readings_is_named_as_such() -> None:
    body = (b"ts,array,voltage_v,current_a\n2026-01-05T12:00:00Z,tracker,26,4\n\n"
            b"2026-01-05T12:01:00Z,tracker,26,5\n\n")
    with pytest.raises(IngestError) as err:
        parse_csv_batch(body, ARRAYS, Limits(future_tolerance_s=10**10))
    assert [(e["line"], "empty line" in e["msg"]) for e in err.value.errors] == [(3, True)]


@pytest.mark.parametrize("sent,missing", [("voltage_adc", "current_adc"),
                                          ("current_adc", "voltage_adc")])
def test_a_raw_reading_names_the_adc_value_it_lacks(sent: str, missing: str) -> None:
    """A row without current_adc was reported on voltage_adc."""
    row = {"ts": "2026-01-05T12:00:00Z", "array": "tracker", sent: 512}
    with pytest.raises(IngestError) as err:
        parse_json_batch(orjson.dumps({"readings": [row]}), ARRAYS,
                         Limits(future_tolerance_s=10**10))
    assert [e["field"] for e in err.value.errors] == [missing]


def test_a_short_emoncms_row_is_not_said_to_lack_what_it_sent() -> None:
    """[unix_s, array, voltage_v]: its length, and the current it lacks — not 'unix_s is
    missing' and 'array missing' beside it (both were sent)."""
    errors = _errors(orjson.dumps([[1714557600, "tracker", 26.0]]))
    assert [(e["field"], e["msg"].split(" (")[0]) for e in errors] == [
        (None, "a row must be [unix_s, array, voltage_v, current_a, power_w]"),
        ("current_a", "current_a is missing")]
