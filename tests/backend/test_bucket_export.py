"""A bucketed CSV or line-protocol export (``max_points`` under the range's readings) is
streamed in pages of buckets, as the raw export is in pages of readings: a year of
minutes as 492,750 buckets (``max_points=500000``) had been built whole in memory (the
service from 262 to 745 MB). Over HTTP in process, SQLite; the buckets checked against
NumPy aggregates of the readings sent, per bucket of the width the answer names."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from live_service import InProcessServer, new_database

import backend.api.routes.measurements as route
import backend.measurements.queries as queries

SITE = "tehuantepec"
T0 = 1_710_460_800  # 2024-03-15T00:00Z, on the hour grid (tehuantepec: UTC-6, phase 0)
MINUTES = 3 * 24 * 60
PAGE = 10


def _power_w() -> np.ndarray:
    return 100.0 + (np.arange(MINUTES) * 37 % 500)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    """The service with three days of the tracker's minutes (power only)."""
    db = new_database("sqlite", tmp_path_factory.mktemp("bucket_export"))
    proc = InProcessServer(db.url).start()
    body = "ts,array,power_w\n" + "".join(
        f"{_iso(T0 + 60 * m)},tracker,{w}\n" for m, w in enumerate(_power_w().tolist()))
    try:
        with proc.client() as c:
            r = c.post(f"/api/v1/sites/{SITE}/measurements", content=body, headers={
                "Authorization": f"Bearer {proc.token(SITE)}", "Content-Type": "text/csv"})
            assert r.status_code == 200 and r.json()["accepted"] == MINUTES, r.text
        yield proc
    finally:
        proc.stop()


@pytest.mark.parametrize("max_points", [3000, 72], ids=["raw_buckets_87s", "rollup_hours"])
def test_a_bucketed_csv_is_read_a_page_at_a_time_and_equals_the_readings(
        server: InProcessServer, monkeypatch: pytest.MonkeyPatch, max_points: int) -> None:
    ts = T0 + 60 * np.arange(MINUTES)
    p = _power_w()
    held: list[int] = []  # bucket rows each read of the export hands over
    real_fetch = queries.fetch

    def fetch(conn: Any, sql: str, params: Any) -> list[Any]:
        rows = real_fetch(conn, sql, params)
        if "GROUP BY 1" in sql:
            held.append(len(rows))
        return rows

    monkeypatch.setattr(queries, "fetch", fetch)
    monkeypatch.setattr(route, "EXPORT_PAGE_ROWS", PAGE)
    with server.client() as c:
        r = c.get(f"/api/v1/sites/{SITE}/measurements", params={
            "array": "tracker", "start": "2024-03-15T00:00:00Z", "end": "2024-03-18T00:00:00Z",
            "max_points": max_points, "format": "csv"})
    assert r.status_code == 200, r.text
    rows = list(csv.DictReader(io.StringIO(r.text)))
    # the width of the answer's own rule, here from the range: ceil(span / max_points),
    # whole hours past an hour
    width = -(-(3 * 86400) // max_points)
    width = width if width < 3600 else 3600 * -(-width // 3600)
    k = (ts - T0) // width
    keys = np.unique(k)
    assert len(rows) == keys.size  # every bucket that holds a reading, once
    for row, key in zip(rows, keys.tolist(), strict=True):
        sel = p[k == key]
        assert _iso(T0 + key * width) == row["ts"]
        assert int(row["n"]) == sel.size
        assert float(row["power_w"]) == pytest.approx(sel.mean(), rel=1e-12)
        assert (float(row["power_w_min"]), float(row["power_w_max"])) == (sel.min(), sel.max())
    assert max(held) <= PAGE and len(held) >= keys.size // PAGE, held


def _iso(t: int) -> str:
    return str(np.datetime_as_string(np.datetime64(int(t), "s"), unit="s")) + "Z"
