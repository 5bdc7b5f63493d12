"""Reads beside the writer and the live loop (issue 23 item 9; ``benchmarks/bench_load.py``
measures the mix itself).

- A month's energy per day comes from the hourly rollups summed by the database: few rows
  through the driver (each costs the reading thread a GIL hand-off), none of the raw
  minutes, on a connection that is not the writer's.
- A read of days whose twin is stored does not wait for the site's lock (another read
  simulating a missing day holds it).
- The live loop's tick is a lookup in an hour simulated at once, and its lag is served by
  ``GET /api/v1/live-twin``.
"""

from __future__ import annotations

import datetime as dt
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
import pandas as pd
import pytest
from live_service import InProcessServer, new_database

from backend.measurements import queries
from backend.measurements.energy import energy_rows
from backend.measurements.writer import MeasurementJob
from backend.twin import service as twin_service
from backend.twin.service import LiveClock

SITE = "tehuantepec"
TZ = dt.timezone(dt.timedelta(hours=-6))  # the site's zone (no DST)
MONTH = (dt.datetime(2025, 6, 1, tzinfo=TZ), dt.datetime(2025, 7, 1, tzinfo=TZ))


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessServer]:
    """The service in process with the live loop on (a 0.5 s tick), a month of 5-minute
    readings of both arrays stored and the month's twin stored by a first read."""
    db = new_database("sqlite", tmp_path_factory.mktemp("load-mix"))
    srv = InProcessServer(db.url, extra_env={"HELIOTWIN_LIVE_TWIN": "true",
                                             "HELIOTWIN_LIVE_TWIN_INTERVAL_S": "0.5"}).start()
    try:
        ctx = srv.ctx
        info = ctx.registry.sites[SITE]
        ts = np.arange(MONTH[0].timestamp(), MONTH[1].timestamp(), 300).astype(np.int64)
        h = (ts - ts[0]) % 86400 / 3600.0
        p = np.where((h > 6.5) & (h < 18.5), 700 * np.sin(np.pi * (h - 6.5) / 12), 0.0)
        for k, name in enumerate(("tracker", "fixed")):
            ids = np.full(ts.size, info.arrays[name].array_id, np.int64)
            power = p * (1.0 - 0.2 * k)
            ctx.writer.submit(MeasurementJob(ids, 0, ts, np.full(ts.size, 25.0),
                                             power / 25.0, power)).result(120)
        energy_rows(ctx, info, *MONTH, "day")  # stores the month's twin
        yield srv
    finally:
        srv.stop()


def test_a_month_per_day_is_summed_from_the_rollups_off_the_writer(server: InProcessServer
                                                                   ) -> None:
    ctx = server.ctx
    info = ctx.registry.sites[SITE]
    fetched: list[tuple[str, Any, int]] = []
    connections: list[Any] = []
    real_fetch = queries.fetch

    def counting(conn: Any, sql: str, params: Any) -> list[tuple[Any, ...]]:
        connections.append(conn.connection.driver_connection)
        rows = real_fetch(conn, sql, params)
        fetched.append((sql, params, len(rows)))
        return rows

    with mock.patch.object(queries, "fetch", counting):
        data = energy_rows(ctx, info, *MONTH, "day")
    assert len(data["rows"]) == 30
    # 2 arrays × 2 sources × 30 days, summed by the database (the hourly rollups: 2,880)
    assert [n for sql, _, n in fetched if "measurement_rollups" in sql] == [120]
    # raw minutes (for the twin over the logger's 5-minute readings) only of the first and
    # the last day, whose neighbours outside the range the read does not know; the other
    # days' came from the first read, their readings unchanged since
    day_1, day_30 = int(MONTH[0].timestamp()) + 86400, int(MONTH[1].timestamp()) - 86400
    raw = [params for sql, params, _ in fetched if "FROM measurements " in sql]
    assert raw and all(p[3] <= day_1 + 3600 or p[2] >= day_30 - 3600 for p in raw), raw
    tracker = [r["arrays"]["tracker"] for r in data["rows"]]
    assert all(a["readings"] == 288 and a["measured_wh"] > 0 and a["twin_wh"] > 0
               for a in tracker)
    # the read's connection is one of the pool's, never the one the writer holds
    writer_conn = ctx.writer.call(lambda conn: conn.connection.driver_connection).result(60)
    assert connections and all(c is not writer_conn for c in connections)


def test_period_sums_equal_the_rollups_added_up_in_python(server: InProcessServer) -> None:
    """The database's sums per period are the hourly rollups' (each bucket in the period
    its start lies in), also for periods cut off the hour at both ends."""
    ctx = server.ctx
    info = ctx.registry.sites[SITE]
    ids = [a.array_id for a in info.arrays.values()]
    start = int(MONTH[0].timestamp()) + 5400  # 01:30 local: a partial first hour
    edges = np.array([start, *range(int(MONTH[0].timestamp()) + 86400,
                                    int(MONTH[0].timestamp()) + 10 * 86400, 86400),
                      int(MONTH[0].timestamp()) + 10 * 86400 - 1800], np.int64)
    with ctx.engine.connect() as conn:
        table = queries.energy_table(conn, ids, edges, info.phase_s, 1200)
        rollups = queries.fetch(conn, "SELECT array_id, source, bucket_s, energy_wh, n FROM "
                                      "measurement_rollups WHERE bucket_s >= ? AND bucket_s < ?",
                                (int(edges[0]), int(edges[-1])))
    r = np.array(rollups, np.float64)
    whole = (r[:, 2] >= start + 1800) & (r[:, 2] + 3600 <= edges[-1])
    for key in table.energy_wh:
        sel = whole & (r[:, 0] == key[0]) & (r[:, 1] == key[1])
        per = np.searchsorted(edges, r[sel, 2], side="right") - 1
        n = np.bincount(per, weights=r[sel, 4], minlength=edges.size - 1)
        wh = np.bincount(per, weights=r[sel, 3], minlength=edges.size - 1)
        # the half hours at both ends come from the raw rows: 6 readings of the logger
        # (5-minute) and 30 of the twin (minutes) each
        raw = 6 if key[1] == 0 else 30
        assert table.readings[key][1:-1].tolist() == n[1:-1].astype(int).tolist()
        assert table.readings[key][0] == n[0] + raw and table.readings[key][-1] == n[-1] + raw
        np.testing.assert_allclose(table.energy_wh[key][1:-1], wh[1:-1], rtol=1e-12)


@pytest.mark.parametrize("periods", [30, 365, 1000])
def test_each_period_is_a_range_search_on_the_rollups_key(server: InProcessServer,
                                                          periods: int) -> None:
    """SQLite's plan of the period sums: the periods outside, each a search of the rollups by
    (array, source, bucket range). With the rollups outside (a plain JOIN past some 300
    periods) every rollup row was compared with every period: a year per day took 1.41 s
    instead of 0.04 s on a year back-filled (bench_service)."""
    ctx = server.ctx
    ids = [a.array_id for a in ctx.registry.sites[SITE].arrays.values()]
    sql = queries._ROLLUP_PERIODS.format(more=", (?, ?, ?)" * (periods - 1),
                                         ids=", ".join("?" * len(ids)))
    t0 = int(MONTH[0].timestamp())
    params = [v for i in range(periods) for v in (i, t0 + 3600 * i, t0 + 3600 * (i + 1))]
    with ctx.engine.connect() as conn:
        plan = [row[3] for row in queries.fetch(conn, "EXPLAIN QUERY PLAN " + sql,
                                                (*params, *ids))]
    searches = [step for step in plan if step.startswith("SEARCH r ")]
    assert plan.index("SCAN p") < plan.index(searches[0]), plan
    assert searches == ["SEARCH r USING PRIMARY KEY (array_id=? AND source=? AND bucket_s>? "
                        "AND bucket_s<?)"], plan


def test_a_read_of_stored_days_does_not_wait_for_the_site_lock(server: InProcessServer
                                                               ) -> None:
    ctx = server.ctx
    info = ctx.registry.sites[SITE]
    done = threading.Event()

    def read() -> None:
        energy_rows(ctx, info, *MONTH, "day")
        done.set()

    with ctx.twin.site_lock(SITE):  # as a read simulating a missing day holds it
        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        finished = done.wait(60)
    reader.join(60)
    assert finished, "a read of stored days waited for the site's lock"


def _runs_of_2025(sim: mock.MagicMock) -> int:
    """Simulations of 2025 the mock saw (the running live loop simulates the present)."""
    return sum(c.args[1].year == 2025 for c in sim.call_args_list)


def test_live_ticks_are_rows_of_an_hour_simulated_at_once(server: InProcessServer) -> None:
    ctx = server.ctx
    twin = twin_service.TwinService(ctx.registry, ctx.engine, ctx.writer, 10)
    info = ctx.registry.sites[SITE]
    minute = int(dt.datetime(2025, 6, 10, 17, 3, tzinfo=dt.UTC).timestamp())
    with mock.patch.object(twin_service, "simulate", wraps=twin_service.simulate) as sim:
        rows = [twin._minute(info, minute + 60 * k)[1] for k in (0, 29, 58)]
        twin._minute(info, minute + 3600)  # the next hour
    assert _runs_of_2025(sim) == 2
    # each row is what a one-minute run gives
    for k, row in zip((0, 29, 58), rows, strict=True):
        t = pd.Timestamp(minute + 60 * k, unit="s", tz="UTC")
        one = twin_service.simulate(info.site, t, t + pd.Timedelta(minutes=1)).series
        assert row.index[0] == t
        np.testing.assert_allclose(row.to_numpy(np.float64), one.to_numpy(np.float64),
                                   rtol=1e-6, atol=1e-4)
    twin.forget(SITE)  # a config change drops the window
    with mock.patch.object(twin_service, "simulate", wraps=twin_service.simulate) as sim:
        twin._minute(info, minute + 60)
    assert _runs_of_2025(sim) == 1


def test_the_live_loop_reports_its_lag(server: InProcessServer) -> None:
    with server.client() as c:
        deadline = time.monotonic() + 60
        while (live := c.get("/api/v1/live-twin").json())["ticks"] < 2:
            assert time.monotonic() < deadline, live
            time.sleep(0.2)
    assert live["enabled"] and live["interval_s"] == 0.5
    assert live["lag_s"] is not None and 0 <= live["lag_s"] <= live["max_lag_s"]
    assert live["last_start_delay_s"] >= 0 and live["last_step_s"] >= 0
    last = dt.datetime.fromisoformat(live["last_minute_utc"].replace("Z", "+00:00"))
    done = dt.datetime.fromisoformat(live["last_done_utc"].replace("Z", "+00:00"))
    assert last.second == 0 and dt.timedelta(0) <= done - last < dt.timedelta(minutes=2)


def test_live_twin_route_without_the_loop(tmp_path: Path) -> None:
    db = new_database("sqlite", tmp_path)
    with InProcessServer(db.url) as srv, srv.client() as c:
        assert c.get("/api/v1/live-twin").json() == {
            "enabled": False, "interval_s": None, "ticks": 0, "last_minute_utc": None,
            "last_done_utc": None, "lag_s": None, "max_lag_s": None,
            "last_start_delay_s": None, "last_step_s": None}


def test_live_clock_lag_grid_and_window() -> None:
    clock = LiveClock(60.0)
    assert clock.next_due(120.0) == 180.0 and clock.next_due(179.9) == 180.0
    assert clock.status(100.0)["lag_s"] is None
    clock.begin(120.0)
    assert clock.status(123.0)["lag_s"] == 3.0  # a tick still running: now − due
    clock.end(120.0, 125.5, started_s=121.0)
    st = clock.status(200.0)
    assert (st["lag_s"], st["max_lag_s"], st["ticks"], st["last_minute_s"]) == (5.5, 5.5, 1, 120)
    assert (st["last_start_delay_s"], st["last_step_s"]) == (1.0, 4.5)
    # a tick that overran the next due time: the next one is due after it ended
    clock.begin(180.0)
    clock.end(180.0, 250.0)
    assert clock.next_due(250.0) == 300.0 and clock.status(260.0)["max_lag_s"] == 70.0
    for k in range(twin_service.LAG_WINDOW):  # the window forgets old ticks
        clock.begin(300.0 + 60 * k)
        clock.end(300.0 + 60 * k, 301.0 + 60 * k)
    assert clock.status()["max_lag_s"] == 1.0
