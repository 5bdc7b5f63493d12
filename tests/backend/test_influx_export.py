"""``GET /api/v1/sites/{site_id}/measurements?format=influx``: InfluxDB line protocol.

The output is read back with an independent parser (the ``line-protocol-parser``
package, a C implementation of InfluxDB's grammar) and compared with the JSON
answer of the same query, over HTTP against the service in this process.
Site ids and array names are restricted to ``[a-z0-9_-]`` by the site config, so
escaping is checked on the formatter alone, with the same parser.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from collections.abc import Iterator

import line_protocol_parser
import pytest
from live_service import InProcessServer, new_database

from backend.measurements.export import escape_key, escape_measurement, influx_lines

SITE = "tehuantepec"
ARRAY = "tracker"
ODD_ARRAY = "east roof,1=a"  # a space, a comma and an equals sign: all escaped in a tag


# ---------------------------------------------------------------- the formatter alone


def test_escaping_follows_the_line_protocol_reference() -> None:
    # the reference's "Special characters" table: measurement , and space; keys , = space
    assert escape_measurement("my measurement,x") == r"my\ measurement\,x"
    assert escape_measurement("a=b") == "a=b"  # an equals sign needs no escape there
    assert escape_key("a b,c=d") == r"a\ b\,c\=d"
    assert escape_key("my\\tag") == "my\\\\tag"  # two backslashes read as one
    with pytest.raises(ValueError, match="newline"):
        escape_key("a\nb")


def test_lines_parse_back_with_an_independent_parser() -> None:
    cols: dict[str, list] = {
        "ts": ["2024-03-15T18:00:00Z", "2024-03-15T18:01:00Z", "2024-03-15T18:02:00Z"],
        "n": [60, 59, 1],
        "voltage_v": [26.1, float("nan"), 1e-05],
        "power_w": [712.53, 0.0, float("inf")]}
    text = "".join(influx_lines("site a", ODD_ARRAY, "measured", cols, chunk_rows=2))
    lines = text.splitlines()
    assert len(lines) == 3
    parsed = [line_protocol_parser.parse_line(line) for line in lines]
    assert {p["measurement"] for p in parsed} == {"heliotwin"}
    assert parsed[0]["tags"] == {"array": ODD_ARRAY, "site": "site a", "source": "measured"}
    assert parsed[0]["fields"] == {"n": 60, "voltage_v": 26.1, "power_w": 712.53}
    assert isinstance(parsed[0]["fields"]["n"], int)
    assert parsed[1]["fields"] == {"n": 59, "power_w": 0.0}  # NaN left out
    assert parsed[2]["fields"] == {"n": 1, "voltage_v": 1e-05}  # inf left out
    start = int(dt.datetime(2024, 3, 15, 18, tzinfo=dt.UTC).timestamp()) * 10**9
    assert [p["time"] for p in parsed] == [start, start + 60 * 10**9, start + 120 * 10**9]


# ---------------------------------------------------------------- over HTTP


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[InProcessServer, str]]:
    tmp = tmp_path_factory.mktemp("influx")
    db = new_database("sqlite", tmp)
    proc = InProcessServer(db.url).start()
    try:
        yield proc, proc.token(SITE)
    finally:
        proc.stop()


def _readings(day: dt.date) -> list[dict[str, object]]:
    """A morning of minute readings: half-sine power over 06:00-12:00 UTC, 24-27 V."""
    t0 = dt.datetime(day.year, day.month, day.day, 6, tzinfo=dt.UTC)
    out = []
    for k in range(360):
        p = 800.0 * math.sin(math.pi * (k + 0.5) / 720.0)
        v = 24.0 + 3.0 * math.sin(math.pi * k / 360.0)
        out.append({"ts": (t0 + dt.timedelta(minutes=k)).isoformat(), "array": ARRAY,
                    "voltage_v": round(v, 3), "current_a": round(p / v, 4)})
    return out


def test_influx_matches_the_json_answer(server: tuple[InProcessServer, str]) -> None:
    proc, token = server
    day = dt.date(2024, 3, 15)
    with proc.client(timeout_s=60.0) as c:
        r = c.post(f"/api/v1/sites/{SITE}/measurements", json={"readings": _readings(day)},
                   headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 200, r.text
        query = {"array": ARRAY, "start": "2024-03-15", "end": "2024-03-16"}
        js = c.get(f"/api/v1/sites/{SITE}/measurements", params=query).json()
        r = c.get(f"/api/v1/sites/{SITE}/measurements", params={**query, "format": "influx"})
        assert r.status_code == 200
        assert r.headers["content-type"].startswith("text/plain")
        lines = r.text.splitlines()
        assert len(lines) == len(js["points"]) == 360
        for line, point in zip(lines, js["points"], strict=True):
            p = line_protocol_parser.parse_line(line)
            assert p["measurement"] == "heliotwin"
            assert p["tags"] == {"array": ARRAY, "site": SITE, "source": "measured"}
            assert p["fields"] == {q: point[q] for q in ("voltage_v", "current_a", "power_w")}
            ts = dt.datetime.fromisoformat(point["ts"].replace("Z", "+00:00"))
            assert p["time"] == int(ts.timestamp()) * 10**9

        # downsampled: min/mean/max per bucket and the count as an integer field
        r = c.get(f"/api/v1/sites/{SITE}/measurements",
                  params={**query, "format": "influx", "max_points": 10})
        js = c.get(f"/api/v1/sites/{SITE}/measurements",
                   params={**query, "max_points": 10}).json()
        parsed = [line_protocol_parser.parse_line(x) for x in r.text.splitlines()]
        assert len(parsed) == len(js["points"]) > 0
        assert sum(p["fields"]["n"] for p in parsed) == 360
        for p, point in zip(parsed, js["points"], strict=True):
            assert p["fields"] == {k: v for k, v in point.items() if k != "ts"}
            assert p["fields"]["power_w_min"] <= p["fields"]["power_w"] \
                <= p["fields"]["power_w_max"]

        # an empty range is an empty body, not an error
        r = c.get(f"/api/v1/sites/{SITE}/measurements",
                  params={"array": "fixed", "start": "2024-03-15", "end": "2024-03-16",
                          "format": "influx"})
        assert r.status_code == 200 and r.text == ""

        r = c.get(f"/api/v1/sites/{SITE}/measurements",
                  params={**query, "format": "influxdb"})
        assert r.status_code == 422 and "format" in r.text


def test_openapi_documents_the_text_answer(server: tuple[InProcessServer, str]) -> None:
    proc, _ = server
    with proc.client(timeout_s=30.0) as c:
        doc = c.get("/openapi.json").json()
    op = doc["paths"]["/api/v1/sites/{site_id}/measurements"]["get"]
    assert "text/plain" in op["responses"]["200"]["content"]
    fmt = next(p for p in op["parameters"] if p["name"] == "format")
    assert "influx" in json.dumps(fmt["schema"])
