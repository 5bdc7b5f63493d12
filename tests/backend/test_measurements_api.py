"""Ingestion and read-back over real HTTP (``backend/api/routes/measurements.py``).

Each test uses its own days, since the server and its database are shared.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import math
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest

if TYPE_CHECKING:
    from live_service import LiveServer

TZ = dt.timezone(dt.timedelta(hours=-6))  # Tehuantepec: UTC-6, no DST
PATH = "/api/v1/sites/tehuantepec/measurements"


def day_readings(day: dt.date, array: str, scale: float = 1.0, every_min: int = 1) -> list[dict]:
    """Minute readings of one local day: a bell from 06:30 to 18:30, distinct values."""
    out = []
    t0 = dt.datetime(day.year, day.month, day.day, tzinfo=TZ)
    for m in range(0, 24 * 60, every_min):
        h = m / 60.0
        s = math.sin(math.pi * (h - 6.5) / 12.0) if 6.5 < h < 18.5 else 0.0
        p = scale * 720.0 * s**1.2 + 0.001 * (m % 97)
        v = 24.0 + 2.0 * s if p > 0.01 else 0.0
        i = p / v if v else 0.0
        out.append({"ts": (t0 + dt.timedelta(minutes=m)).isoformat(), "array": array,
                    "voltage_v": round(v, 4), "current_a": round(i, 6),
                    "power_w": round(v * i, 4)})
    return out


def post(client: httpx.Client, token: str | None, body: object, **kw: Any) -> httpx.Response:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    if isinstance(body, str):
        return client.post(PATH, content=body, headers={**headers, "Content-Type": "text/csv"})
    return client.post(PATH, json=body, headers=headers, **kw)


def test_tokens_401_and_403(client: httpx.Client, live_server: LiveServer) -> None:
    rd = day_readings(dt.date(2023, 1, 2), "tracker")[:3]
    r = post(client, None, {"readings": rd})
    assert r.status_code == 401 and "token" in r.json()["detail"]
    assert post(client, "ht_not-a-real-token", {"readings": rd}).status_code == 401
    other = live_server.token("guadalajara_fisheye")
    r = post(client, other, {"readings": rd})
    assert r.status_code == 403 and "guadalajara_fisheye" in r.json()["detail"]
    assert post(client, live_server.write_token, {"readings": rd}).status_code == 200


@pytest.mark.parametrize(("change", "field", "words"), [
    ({"ts": "2023-01-03T12:00:00"}, "ts", "no UTC offset"),
    ({"ts": "yesterday"}, "ts", "not an ISO 8601"),
    ({"voltage_v": "NaN"}, "voltage_v", "send a JSON number"),  # a string is not a number
    ({"voltage_v": "twelve"}, "voltage_v", "not a number"),
    ({"voltage_v": -3.0}, "voltage_v", "outside"),
    ({"current_a": 5000.0}, "current_a", "outside"),
    ({"array": "roof"}, "array", "unknown array 'roof'"),
    ({"power_w": 99999.0}, "power_w", "disagrees"),
    ({"ts": "2099-01-01T00:00:00+00:00"}, "ts", "after the server clock"),
])
def test_422_names_row_and_field(client: httpx.Client, live_server: LiveServer,
                                 change: dict, field: str, words: str) -> None:
    rd = day_readings(dt.date(2023, 1, 3), "tracker")[700:705]
    rd[3] = {**rd[3], **change}
    r = post(client, live_server.write_token, {"readings": rd})
    assert r.status_code == 422, r.text
    err = r.json()["detail"][0]
    assert (err["row"], err["field"]) == (3, field)
    assert words in err["msg"]
    # all-or-nothing: the four good rows were not stored either
    got = client.get(PATH, params={"array": "tracker", "start": "2023-01-03",
                                   "end": "2023-01-04"}).json()
    assert got["points"] == []


def test_missing_fields_and_bad_shapes(client: httpx.Client, live_server: LiveServer) -> None:
    tok = live_server.write_token
    r = post(client, tok, {"readings": [{"ts": "2023-01-04T12:00:00Z", "array": "fixed"}]})
    first = r.json()["detail"][0]
    assert r.status_code == 422 and first["field"] == "power_w"
    assert "voltage_v and current_a, or power_w alone" in first["msg"]
    r = post(client, tok, {"readings": [1, 2]})
    assert r.status_code == 422 and "object" in r.json()["detail"][0]["msg"]
    r = post(client, tok, {"rows": []})
    assert r.status_code == 422 and "readings" in r.json()["detail"][0]["msg"]
    r = client.post(PATH, content=b"{not json", headers={"Authorization": f"Bearer {tok}",
                                                          "Content-Type": "application/json"})
    assert r.status_code == 422 and "JSON" in r.json()["detail"][0]["msg"]


def counts(r: httpx.Response) -> dict[str, int]:
    """``accepted`` and ``duplicates`` of an ingest answer."""
    return {k: r.json()[k] for k in ("accepted", "duplicates")}


def test_idempotent_resend_and_partial_overlap(client: httpx.Client,
                                               live_server: LiveServer) -> None:
    rd = day_readings(dt.date(2023, 1, 5), "tracker")
    tok = live_server.write_token
    assert counts(post(client, tok, {"readings": rd[:1000]})) == {"accepted": 1000,
                                                                 "duplicates": 0}
    assert counts(post(client, tok, {"readings": rd[:1000]})) == {"accepted": 0,
                                                                 "duplicates": 1000}
    assert counts(post(client, tok, {"readings": rd[900:]})) == {"accepted": 440,
                                                                "duplicates": 100}
    # a logger resumes after stored_through: the batch's latest reading, in UTC
    last = dt.datetime.fromisoformat(rd[999]["ts"]).astimezone(dt.UTC)
    r = post(client, tok, {"readings": rd[:1000]})
    assert r.json()["stored_through"] == last.strftime("%Y-%m-%dT%H:%M:%SZ")
    assert r.json()["stored_through_unix_s"] == int(last.timestamp())
    # the same minute twice in one batch counts once
    dup = [rd[0], rd[0], rd[1]]
    assert counts(post(client, tok, {"readings": dup})) == {"accepted": 0, "duplicates": 3}
    got = client.get(PATH, params={"array": "tracker", "start": "2023-01-05",
                                   "end": "2023-01-06", "max_points": 5000}).json()
    assert got["bucket_s"] == 0 and len(got["points"]) == 1440
    # a new second twice in one batch with other values: the first is stored, once
    one = {"ts": "2023-01-07T12:00:00-06:00", "array": "tracker", "voltage_v": 25.0,
           "current_a": 4.0}
    assert counts(post(client, tok, {"readings": [one, dict(one, current_a=8.0)]})) == {
        "accepted": 1, "duplicates": 1}
    got = client.get(PATH, params={"array": "tracker", "start": "2023-01-07",
                                   "end": "2023-01-08"}).json()
    assert [(p["current_a"], p["power_w"]) for p in got["points"]] == [(4.0, 100.0)]


def test_csv_ingest_and_csv_errors_name_the_line(client: httpx.Client,
                                                 live_server: LiveServer) -> None:
    rd = day_readings(dt.date(2023, 1, 6), "fixed", every_min=10)
    text = "ts,array,voltage_v,current_a,power_w\n" + "".join(
        f"{x['ts']},{x['array']},{x['voltage_v']},{x['current_a']},{x['power_w']}\n" for x in rd)
    r = post(client, live_server.write_token, text)
    assert counts(r) == {"accepted": len(rd), "duplicates": 0}
    bad = "ts,array,voltage_v,current_a\n2023-01-07T10:00:00Z,fixed,25,3\n" \
          "2023-01-07T10:01:00Z,fixed,,3\n"
    r = post(client, live_server.write_token, bad)
    err = r.json()["detail"][0]
    assert r.status_code == 422 and (err["row"], err["line"], err["field"]) == (1, 3, "voltage_v")
    r = post(client, live_server.write_token, "time,array,volts\n1,2,3\n")
    assert r.status_code == 422 and "header" in r.json()["detail"][0]["msg"]


def test_adc_readings_use_stored_calibration(client: httpx.Client,
                                             live_server: LiveServer) -> None:
    """Seed 000 eqs. 16–19: V_pin = n·5/1023; I = (V_pin − 2.5)/0.1; V = V_pin·ratio."""
    tok = live_server.write_token
    cal = {"adc_bits": 10, "adc_vref_v": 5.0, "current_zero_v": 2.5,
           "current_sensitivity_mv_per_a": 100.0, "divider_ratio": 8.0}
    url = "/api/v1/sites/tehuantepec/arrays/fixed/calibration"
    assert client.put(url, json=cal).status_code == 401
    r = client.put(url, json=cal, headers={"Authorization": f"Bearer {tok}"})
    assert r.status_code == 403  # a logger's ingest token writes readings, not calibrations
    site_tok = live_server.token("tehuantepec", scope="site")
    r = client.put(url, json=cal, headers={"Authorization": f"Bearer {site_tok}"})
    assert r.status_code == 200
    assert client.get(url).json()["divider_ratio"] == 8.0
    reading = {"ts": "2023-01-08T12:00:00-06:00", "array": "fixed",
               "voltage_adc": 640, "current_adc": 1000}
    assert post(client, tok, {"readings": [reading]}).json()["accepted"] == 1
    p = client.get(PATH, params={"array": "fixed", "start": "2023-01-08",
                                 "end": "2023-01-09"}).json()["points"][0]
    v_expected = 640 * 5.0 / 1023 * 8.0  # 25.024 V
    i_expected = (1000 * 5.0 / 1023 - 2.5) / 0.100  # 23.876 A
    assert p["voltage_v"] == pytest.approx(v_expected, rel=1e-12)
    assert p["current_a"] == pytest.approx(i_expected, rel=1e-12)
    assert p["power_w"] == pytest.approx(v_expected * i_expected, rel=1e-12)
    # NaN/Infinity literals (Python's JSON reads them) and absurd values: 422, nothing stored
    auth = {"Authorization": f"Bearer {site_tok}", "Content-Type": "application/json"}
    for bad in ('{"current_zero_v": NaN}', '{"adc_vref_v": Infinity}',
                '{"divider_ratio": 1e308}',
                # zero current above the ADC's full scale: every reading refused after
                '{"current_zero_v": 6.0, "adc_vref_v": 5.0}'):
        r = client.put(url, content=bad, headers=auth)
        assert r.status_code == 422, (bad, r.text)
    r = client.put(url, content='{"current_zero_v": 6.0, "adc_vref_v": 5.0}', headers=auth)
    assert "current_zero_v" in r.text and "adc_vref_v" in r.text, r.text
    assert client.get(url).json() == cal
    raw = {**reading, "ts": "2023-01-08T12:01:00-06:00", "current_adc": 1024}
    r = post(client, tok, {"readings": [raw]})
    assert r.status_code == 422 and r.json()["detail"][0]["field"] == "current_adc"


def test_size_limits_413(client: httpx.Client, live_server: LiveServer) -> None:
    tok = live_server.write_token
    one = day_readings(dt.date(2023, 1, 9), "tracker")[0]
    r = post(client, tok, {"readings": [one] * 100_001})
    assert r.status_code == 413
    big = b'{"readings": [' + b" " * (11 * 1024 * 1024) + b"]}"
    r = client.post(PATH, content=big, headers={"Authorization": f"Bearer {tok}",
                                                 "Content-Type": "application/json"})
    assert r.status_code == 413 and "limit" in r.json()["detail"][0]["msg"]


def test_downsampled_buckets_keep_peaks_and_csv_export(client: httpx.Client,
                                                       live_server: LiveServer) -> None:
    tok = live_server.write_token
    days = [dt.date(2023, 2, 1) + dt.timedelta(days=k) for k in range(3)]
    rd = [x for d in days for x in day_readings(d, "tracker")]
    # a peak the array can make (under twice its 820 W rating: parse.MAX_STC_MULTIPLE)
    rd[2000] = {**rd[2000], "power_w": 1500.0, "voltage_v": 40.0, "current_a": 37.5}
    assert post(client, tok, {"readings": rd})
    params = {"array": "tracker", "start": "2023-02-01", "end": "2023-02-04"}
    full = client.get(PATH, params={**params, "max_points": 10_000}).json()
    assert full["bucket_s"] == 0 and len(full["points"]) == len(rd)
    powers = np.array([p["power_w"] for p in full["points"]])
    for max_points in (50, 500):  # rollup buckets (≥ 1 h) and raw buckets (< 1 h)
        got = client.get(PATH, params={**params, "max_points": max_points}).json()
        pts = got["points"]
        assert 0 < len(pts) <= max_points and got["bucket_s"] > 0
        assert max(p["power_w_max"] for p in pts) == 1500.0
        assert sum(p["n"] for p in pts) == len(rd)
        assert sum(p["power_w"] * p["n"] for p in pts) == pytest.approx(powers.sum(), rel=1e-9)
        assert min(p["power_w_min"] for p in pts) == powers.min()
    r = client.get(PATH, params={**params, "format": "csv"})
    rows = list(csv.DictReader(io.StringIO(r.text)))
    assert r.headers["content-type"].startswith("text/csv") and len(rows) == len(rd)
    assert float(rows[2000]["power_w"]) == 1500.0
    r = client.get(PATH, params={**params, "max_points": 10}, headers={"Accept": "text/csv"})
    assert r.text.splitlines()[0].startswith("ts,n,voltage_v")


def test_read_errors(client: httpx.Client) -> None:
    assert client.get(PATH, params={"start": "2023-01-01", "end": "2023-01-02"}).status_code == 422
    r = client.get(PATH, params={"array": "tracker", "start": "2023-01-02T00:00:00",
                                 "end": "2023-01-03"})
    assert r.status_code == 422 and "offset" in r.json()["detail"]
    r = client.get(PATH, params={"array": "tracker", "start": "2023-01-03", "end": "2023-01-02"})
    assert r.status_code == 422
    r = client.get("/api/v1/sites/atlantis/measurements",
                   params={"array": "tracker", "start": "2023-01-01", "end": "2023-01-02"})
    assert r.status_code == 404 and "tehuantepec" in r.json()["detail"]
    # required and non-empty by the schema itself (the OpenAPI says so): each one named
    r = client.get(PATH, params={"array": "", "start": "", "end": ""})
    assert r.status_code == 422
    assert [e["loc"] for e in r.json()["detail"]] == [["query", "array"], ["query", "start"],
                                                      ["query", "end"]]
    r = client.get(PATH, params={"array": "tracker", "start": "0001-01-01", "end": "2023-01-02"})
    assert r.status_code == 422 and "start" in r.json()["detail"]


def test_large_answers_are_gzipped(client: httpx.Client, live_server: LiveServer) -> None:
    rows = [{"ts": f"2021-06-01T{h:02d}:{m:02d}:00Z", "array": "fixed", "voltage_v": 25.0,
             "current_a": 4.0} for h in range(3) for m in range(60)]
    auth = {"Authorization": f"Bearer {live_server.write_token}"}
    assert client.post(PATH, json={"readings": rows}, headers=auth).status_code == 200
    params = {"array": "fixed", "start": "2021-06-01T00:00:00Z", "end": "2021-06-01T03:00:00Z"}
    for extra in ({}, {"format": "csv"}):
        r = client.get(PATH, params={**params, **extra}, headers={"Accept-Encoding": "gzip"})
        assert r.headers.get("content-encoding") == "gzip"
        assert r.text.count("25.0") == 180  # httpx decoded the one gzip layer


def test_the_token_is_checked_before_the_body_is_read(client: httpx.Client,
                                                      live_server: LiveServer) -> None:
    """Without a valid token neither a corrupt gzip stream nor an oversized body is
    looked at: the answer is the 401/403, never the body's 400/413."""
    gz = {"Content-Type": "application/json", "Content-Encoding": "gzip"}
    assert client.post(PATH, content=b"not gzip", headers=gz).status_code == 401
    other = live_server.token("guadalajara_fisheye")
    r = client.post(PATH, content=b"not gzip", headers={**gz, "Authorization": f"Bearer {other}"})
    assert r.status_code == 403
    r = client.post(PATH, content=b"not gzip",
                    headers={**gz, "Authorization": f"Bearer {live_server.write_token}"})
    assert r.status_code == 400 and "not gzip data" in r.json()["detail"][0]["msg"]


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the OpenAPI, not storage
def test_openapi_declares_the_ingest_body_and_answer(client: httpx.Client) -> None:
    """The plain route's OpenAPI: JSON readings (their fields those parse.py validates),
    emonCMS rows or CSV in; IngestResult out; the GET's answer typed as well."""
    from backend.measurements.parse import FIELDS

    doc = client.get("/openapi.json").json()
    ops = doc["paths"]["/api/v1/sites/{site_id}/measurements"]
    body = ops["post"]["requestBody"]["content"]
    assert set(body) == {"application/json", "text/csv"}
    readings, rows = body["application/json"]["schema"]["oneOf"]
    reading = readings["properties"]["readings"]["items"]
    assert set(reading["properties"]) == set(FIELDS)
    assert reading["additionalProperties"] is False and rows["type"] == "array"
    answer = ops["post"]["responses"]["200"]["content"]["application/json"]["schema"]
    assert answer == {"$ref": "#/components/schemas/IngestResult"}
    assert set(doc["components"]["schemas"]["IngestResult"]["required"]) == {
        "accepted", "duplicates", "stored_through", "stored_through_unix_s"}
    got = ops["get"]["responses"]["200"]["content"]
    assert got["application/json"]["schema"] == {"$ref": "#/components/schemas/MeasurementsRead"}
    assert {"text/csv", "text/plain"} <= set(got)


#: Bound on the peak Python allocation of streaming 8,640 readings as CSV in pages of
#: 1,000 (measured 1.1–1.2 MB on SQLite and PostgreSQL; 5.0–5.1 MB when the range was read
#: whole).
EXPORT_PEAK_BYTES = 2_000_000


def test_csv_export_is_read_page_by_page(client: httpx.Client, live_server: LiveServer,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """A CSV export holds one page of readings at a time, not the range (16 anonymous
    year-long exports at once took a server from 0.4 to 2.4 GB): no read of the database
    returns more than a page, the peak Python allocation stays near one page's, and the
    text is the readings as posted, with a sensor column only the last reading carries."""
    import tracemalloc

    from backend.api.routes import measurements as route
    from backend.measurements import queries

    days = [dt.date(2023, 3, 10) + dt.timedelta(days=k) for k in range(6)]
    rd = [day_readings(d, "tracker") for d in days]
    rd[-1][-1] = {**rd[-1][-1], "temp_air_c": 21.5}
    for batch in rd:
        assert post(client, live_server.write_token, {"readings": batch}).status_code == 200
    rd = [x for batch in rd for x in batch]
    monkeypatch.setattr(route, "EXPORT_PAGE_ROWS", 1000)
    largest = [0]
    fetch = queries.fetch

    def spy(*args: Any) -> list:
        rows = fetch(*args)
        largest[0] = max(largest[0], len(rows))
        return rows

    monkeypatch.setattr(queries, "fetch", spy)
    params = {"array": "tracker", "start": "2023-03-10", "end": "2023-03-16", "format": "csv"}
    client.get(PATH, params={**params, "end": "2023-03-11"})  # first-call costs out of the way
    largest[0] = 0
    parts = []
    tracemalloc.start()
    with client.stream("GET", PATH, params=params, headers={"Accept-Encoding": "identity"}
                       ) as r:
        for chunk in r.iter_bytes():
            parts.append(len(chunk))
            if len(parts) == 1:
                head = chunk
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert r.status_code == 200 and largest[0] == 1000, largest
    assert peak < EXPORT_PEAK_BYTES, peak
    text = client.get(PATH, params=params).text
    expected = ["ts,voltage_v,current_a,power_w,temp_air_c"] + [
        f"{dt.datetime.fromisoformat(x['ts']).astimezone(dt.UTC):%Y-%m-%dT%H:%M:%SZ},"
        f"{float(x['voltage_v'])!r},{float(x['current_a'])!r},{float(x['power_w'])!r},"
        f"{x.get('temp_air_c', '')}" for x in rd]
    assert text.splitlines() == expected and sum(parts) == len(text)
    assert head.startswith(b"ts,voltage_v,current_a,power_w,temp_air_c\n")
    lines = client.get(PATH, params={**params, "format": "influx"}).text.splitlines()
    assert len(lines) == len(rd) and lines[-1].count("temp_air_c=21.5") == 1
