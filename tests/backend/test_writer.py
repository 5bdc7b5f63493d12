"""The writer: group commits, idempotency counts, and rollups kept equal to the readings.

Rollups are maintained two ways (merged increments for appended readings, a
recomputation from the stored rows otherwise); whatever the order of arrival,
they must equal the aggregates of the stored readings computed here directly
with NumPy, and energy must equal an independent trapezoid integration.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from live_service import new_database, service_context
from sqlalchemy import text

from backend.context import open_context
from backend.measurements.writer import SQLITE_CHUNK_ROWS, MeasurementJob, PartlyStored
from backend.settings import get_settings

T0 = 1_700_000_000 // 3600 * 3600 - 3600  # on the UTC hour grid (phase 0 for UTC-6)


@pytest.fixture(params=["sqlite", "postgresql"])
def ctx(request: pytest.FixtureRequest, tmp_path: Path):  # type: ignore[no-untyped-def]
    with service_context(request.param, tmp_path) as context:
        yield context


def _job(aid: int, ts: np.ndarray, seed: int) -> MeasurementJob:
    rng = np.random.default_rng(seed)
    v = 20 + 10 * rng.random(ts.size)
    i = 30 * rng.random(ts.size)
    return MeasurementJob(np.full(ts.size, aid), 0, ts.astype(np.int64), v, i, v * i)


def _assert_rollups_equal_direct_aggregates(ctx, aid: int, n: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Every hourly rollup of ``aid`` against NumPy aggregates of its stored readings, and
    the energy against a trapezoid per run of readings; returns where the runs break."""
    with ctx.engine.connect() as conn:
        rows = np.array(conn.execute(text(
            "SELECT ts_s, voltage_v, current_a, power_w FROM measurements "
            "WHERE array_id = :a AND source = 0 ORDER BY ts_s"), {"a": aid}).all(), float)
        roll = np.array(conn.execute(text(
            "SELECT bucket_s, n, energy_wh, sum_power_w, min_power_w, max_power_w, "
            "first_ts_s, last_ts_s FROM measurement_rollups WHERE array_id = :a AND source = 0 "
            "ORDER BY bucket_s"), {"a": aid}).all(), float)
    assert rows.shape[0] == n
    hour = (rows[:, 0] - T0) // 3600
    for r in roll:
        sel = hour == (r[0] - T0) // 3600
        assert r[1] == sel.sum()
        assert r[3] == pytest.approx(rows[sel, 3].sum(), rel=1e-12)
        assert (r[4], r[5]) == (rows[sel, 3].min(), rows[sel, 3].max())
        assert (r[6], r[7]) == (rows[sel, 0].min(), rows[sel, 0].max())
    assert roll[:, 1].sum() == n
    # energy: trapezoid per run of readings at most 600 s apart (the rule), independently
    gaps = np.flatnonzero(np.diff(rows[:, 0]) > 600) + 1
    expected = sum(float(np.trapezoid(p, t)) for t, p in zip(
        np.split(rows[:, 0], gaps), np.split(rows[:, 3], gaps), strict=True)) / 3600
    assert roll[:, 2].sum() == pytest.approx(expected, rel=1e-9)
    return gaps


def test_rollups_equal_direct_aggregates_in_any_order(ctx) -> None:  # type: ignore[no-untyped-def]
    aid = ctx.registry.sites["tehuantepec"].arrays["tracker"].array_id
    rng = np.random.default_rng(3)
    minutes = np.sort(rng.choice(3 * 24 * 60, size=3000, replace=False))
    outage = ((minutes >= 1000) & (minutes < 1030)) | ((minutes >= 2500) & (minutes < 2600))
    minutes = minutes[~outage]
    ts = T0 + 60 * minutes
    chunks = np.array_split(ts, 40)
    order = list(range(20)) + list(rng.permutation(np.arange(20, 40)))  # append, then shuffled
    futures = [ctx.writer.submit(_job(aid, chunks[k], k)) for k in order]
    futures.append(ctx.writer.submit(_job(aid, chunks[5][:10], 99)))  # re-sent minutes
    results = [f.result(timeout=60) for f in futures]
    assert sum(a for a, _ in results) == ts.size
    assert results[-1] == (0, 10)

    gaps = _assert_rollups_equal_direct_aggregates(ctx, aid, ts.size)
    assert len(gaps) > 0  # the data did have gaps not bridged


def test_call_jobs_and_failures_stay_isolated(ctx) -> None:  # type: ignore[no-untyped-def]
    aid = ctx.registry.sites["tehuantepec"].arrays["fixed"].array_id
    ok = ctx.writer.submit(_job(aid, T0 + 60 * np.arange(10), 1))
    bad = ctx.writer.submit(_job(10**6, T0 + 60 * np.arange(10), 2))  # no such array: FK
    also_ok = ctx.writer.submit(_job(aid, T0 + 60 * np.arange(10, 20), 3))
    assert ok.result(timeout=30) == (10, 0)
    with pytest.raises(Exception):  # noqa: B017 - the driver's integrity error
        bad.result(timeout=30)
    assert also_ok.result(timeout=30) == (10, 0)
    assert ctx.writer.call(lambda conn: 41 + 1).result(timeout=30) == 42


def test_big_batch_counts_duplicates_and_keeps_first_values(ctx) -> None:  # type: ignore[no-untyped-def]
    """A batch over several multi-row INSERT chunks (SQLITE_CHUNK_ROWS) with readings
    already stored and readings repeated inside the batch: exact counts, first write wins."""
    assert SQLITE_CHUNK_ROWS < 2000  # the batch below spans more than two chunks
    aid = ctx.registry.sites["tehuantepec"].arrays["tracker"].array_id
    stored = T0 + 60 * np.arange(1000, 1700)
    assert ctx.writer.submit(_job(aid, stored, 1)).result(timeout=60) == (700, 0)
    ts = np.concatenate([T0 + 60 * np.arange(2500), T0 + 60 * np.arange(100)])  # 100 repeats
    job = _job(aid, ts, 2)
    power_w = job.power_w  # the writer puts the job's columns in key order
    assert ctx.writer.submit(job).result(timeout=60) == (1800, 800)
    with ctx.engine.connect() as conn:
        got = dict(conn.execute(text(
            "SELECT ts_s, power_w FROM measurements WHERE array_id = :a AND source = 0"),
            {"a": aid}).all())
    assert len(got) == 2500
    first_p = _job(aid, stored, 1).power_w
    assert got[int(stored[0])] == first_p[0]  # stored before: kept
    assert got[int(ts[0])] == power_w[0]  # repeated in the batch: its first value kept
    assert got[int(ts[2499])] == power_w[2499]


def test_mixed_arrays_in_any_order_give_per_series_rollups(ctx) -> None:  # type: ignore[no-untyped-def]
    """One batch of both arrays, shuffled: each series' rollups match its own readings."""
    arrays = ctx.registry.sites["tehuantepec"].arrays
    ids = np.array([arrays["tracker"].array_id, arrays["fixed"].array_id])
    rng = np.random.default_rng(7)
    aid = np.repeat(ids, 600)
    ts = T0 + 60 * np.tile(np.arange(600), 2)
    order = rng.permutation(aid.size)
    v = 20 + 10 * rng.random(aid.size)
    i = 30 * rng.random(aid.size)
    job = MeasurementJob(aid[order], 0, ts[order].astype(np.int64), v[order], i[order],
                         (v * i)[order])
    assert ctx.writer.submit(job).result(timeout=60) == (1200, 0)
    with ctx.engine.connect() as conn:
        for k, a in enumerate(ids.tolist()):
            n, s, e = conn.execute(text(
                "SELECT SUM(n), SUM(sum_power_w), SUM(energy_wh) FROM measurement_rollups "
                "WHERE array_id = :a AND source = 0"), {"a": a}).one()
            p = (v * i)[k * 600:(k + 1) * 600]
            assert n == 600
            assert s == pytest.approx(p.sum(), rel=1e-12)
            assert e == pytest.approx(float(np.trapezoid(p, 60.0 * np.arange(600))) / 3600,
                                      rel=1e-9)


def test_single_readings_of_many_loggers_in_one_group_are_increments(ctx) -> None:  # type: ignore[no-untyped-def]
    """Single readings filling holes far apart (the minutes 200 loggers of one array send
    at once) merge as increments, whether or not the writer groups them: no recomputation,
    and the rollups still equal the direct aggregates."""
    aid = ctx.registry.sites["tehuantepec"].arrays["fixed"].array_id
    minutes = np.arange(2 * 24 * 60)
    holes = minutes[::30]  # 30 min apart: more than the energy gap between them
    stored = T0 + 60 * np.setdiff1d(minutes, holes)
    assert ctx.writer.submit(_job(aid, stored, 1)).result(timeout=60) == (stored.size, 0)
    refreshes = ctx.writer.rollup_refreshes
    rng = np.random.default_rng(5)
    futures = [ctx.writer.submit(_job(aid, np.array([T0 + 60 * m]), int(m)))
               for m in rng.permutation(holes)]
    assert [f.result(timeout=60) for f in futures] == [(1, 0)] * holes.size
    assert ctx.writer.rollup_refreshes == refreshes
    _assert_rollups_equal_direct_aggregates(ctx, aid, minutes.size)


def test_a_re_sent_batch_leaves_the_rollups_untouched(ctx) -> None:  # type: ignore[no-untyped-def]
    """A logger re-sending readings the service has (a retry after a lost answer): all
    duplicates, so no rollup work at all, and the rollups still equal the readings."""
    aid = ctx.registry.sites["tehuantepec"].arrays["tracker"].array_id
    ts = T0 + 60 * np.arange(0, 600, 2)
    assert ctx.writer.submit(_job(aid, ts, 1)).result(timeout=60) == (ts.size, 0)
    with ctx.engine.connect() as conn:
        before = conn.execute(text("SELECT * FROM measurement_rollups WHERE array_id = :a "
                                   "ORDER BY bucket_s"), {"a": aid}).all()
    refreshes = ctx.writer.rollup_refreshes
    again = ctx.writer.submit(_job(aid, ts[50:250], 2))  # other values: first write wins
    assert again.result(timeout=60) == (0, 200)
    assert ctx.writer.rollup_refreshes == refreshes
    with ctx.engine.connect() as conn:
        after = conn.execute(text("SELECT * FROM measurement_rollups WHERE array_id = :a "
                                  "ORDER BY bucket_s"), {"a": aid}).all()
    assert after == before
    _assert_rollups_equal_direct_aggregates(ctx, aid, ts.size)


def _hold_writer(ctx) -> threading.Event:  # type: ignore[no-untyped-def]
    """Park the writer in a call until the returned gate is set: what is submitted meanwhile
    is queued in submission order."""
    holding, gate = threading.Event(), threading.Event()

    def hold(_conn: object) -> None:
        holding.set()
        gate.wait(60)

    ctx.writer.call(hold)
    assert holding.wait(60)
    return gate


def test_a_back_fill_is_committed_in_pieces_and_a_live_reading_goes_between(ctx) -> None:  # type: ignore[no-untyped-def]
    """A batch over ``max_group_rows`` readings is committed in pieces of at most that many,
    each behind whatever was queued meanwhile: a live reading queued after a 10-piece
    back-fill is committed before the back-fill's last piece (it waited behind all 10,000
    rows in one transaction before), the back-fill is answered once, after its last
    piece, with the counts of all of them, and the rollups equal the readings."""
    arrays = ctx.registry.sites["tehuantepec"].arrays
    back, live = arrays["tracker"].array_id, arrays["fixed"].array_id
    ctx.writer.max_group_rows = 1000
    done: list[str] = []
    gate = _hold_writer(ctx)
    ts = T0 + 60 * np.arange(10_000)
    big = ctx.writer.submit(_job(back, ts[::-1].copy(), 1))  # newest first: sorted by the writer
    small = ctx.writer.submit(_job(live, np.array([T0]), 2))
    big.add_done_callback(lambda _f: done.append("back-fill"))
    small.add_done_callback(lambda _f: done.append("live"))
    groups = ctx.writer.groups_committed
    gate.set()
    assert big.result(timeout=60) == (10_000, 0)
    assert small.result(timeout=60) == (1, 0)
    assert done == ["live", "back-fill"]
    assert ctx.writer.groups_committed - groups == 11  # 10 pieces and the live reading
    _assert_rollups_equal_direct_aggregates(ctx, back, ts.size)


def test_a_batch_failing_part_way_says_what_is_stored_and_a_retry_completes_it(ctx) -> None:  # type: ignore[no-untyped-def]
    """A piece that fails ends the batch: the pieces committed before stay (the error says
    how many readings), the rest is not written, and sending the batch again stores
    exactly the rest — readings are keyed by (array, source, second) — with rollups equal
    to the readings, as if it had gone through at once."""
    aid = ctx.registry.sites["tehuantepec"].arrays["tracker"].array_id
    ctx.writer.max_group_rows = 1000
    ts = T0 + 60 * np.arange(3500)
    good = _job(aid, ts, 1)
    bad = _job(10**6, T0 + 60 * np.arange(10), 2)  # no such array (FK): sorts last
    job = MeasurementJob(*(np.concatenate([getattr(good, c), getattr(bad, c)]) if c != "source"
                           else 0 for c in ("array_ids", "source", "ts_s", "voltage_v",
                                            "current_a", "power_w")))
    with pytest.raises(PartlyStored) as err:
        ctx.writer.submit(job).result(timeout=60)
    assert (err.value.stored, err.value.total) == (3000, 3510)
    with ctx.engine.connect() as conn:
        assert conn.execute(text("SELECT COUNT(*) FROM measurements WHERE array_id = :a"),
                            {"a": aid}).scalar() == 3000
    assert ctx.writer.submit(_job(aid, ts, 1)).result(timeout=60) == (500, 3000)
    _assert_rollups_equal_direct_aggregates(ctx, aid, ts.size)


def test_a_group_of_many_loggers_costs_few_statements(tmp_path: Path) -> None:
    """SQLite: the writer hands the GIL back at every statement (and at every row of an
    ``executemany``), and waits to get it back from the event loop each time. 100 loggers'
    single readings far apart in one group: the stored readings around every run are
    found by one statement, the rollup increments written by another, so the group costs
    about a statement per job (each job's INSERT counts its duplicates), not 2 per run
    and one per rollup row (454 here before)."""
    db = new_database("sqlite", tmp_path)
    ctx = open_context(get_settings(database_url=db.url, alerts=False,
                                    sites_dir=get_settings().sites.user_dir))
    try:
        aid = ctx.registry.sites["tehuantepec"].arrays["fixed"].array_id
        minutes = np.arange(0, 100 * 30, 30)
        stored = T0 + 60 * np.setdiff1d(np.arange(minutes[-1] + 1), minutes)
        assert ctx.writer.submit(_job(aid, stored, 1)).result(timeout=60)[0] == stored.size
        statements: list[str] = []
        ctx.writer.call(lambda conn: conn.connection.driver_connection.set_trace_callback(
            statements.append)).result(timeout=60)
        holding, gate = threading.Event(), threading.Event()

        def hold(_conn: object) -> None:  # the writer waits here: the jobs queue up
            holding.set()
            gate.wait(60)

        ctx.writer.call(hold)
        assert holding.wait(60)
        futures = [ctx.writer.submit(_job(aid, np.array([T0 + 60 * m]), int(m)))
                   for m in minutes]
        statements.clear()
        gate.set()
        assert [f.result(timeout=60) for f in futures] == [(1, 0)] * minutes.size
        assert ctx.writer.rollup_refreshes == 0
        others = [s[:60] for s in statements if not s.startswith("INSERT INTO measurements ")]
        assert len(statements) <= minutes.size + 8, others
        _assert_rollups_equal_direct_aggregates(ctx, aid, stored.size + minutes.size)
    finally:
        ctx.close()


def test_the_writer_truncates_a_grown_wal_without_waiting_for_a_long_reader(
        tmp_path: Path) -> None:
    """SQLite: the WAL of back-to-back commits is checkpointed and truncated between two
    groups once past the writer's bound; a reader that keeps the WAL makes it give up at
    once (the commit is not held) and try again later."""
    db = new_database("sqlite", tmp_path)
    ctx = open_context(get_settings(database_url=db.url, alerts=False,
                                    sites_dir=get_settings().sites.user_dir))
    try:
        writer = ctx.writer
        wal = Path(f"{ctx.engine.url.database}-wal")
        writer.wal_truncate_bytes = 256 * 1024
        aid = ctx.registry.sites["tehuantepec"].arrays["fixed"].array_id
        reader = ctx.engine.connect()
        reader.execute(text("SELECT COUNT(*) FROM measurements")).all()  # a snapshot, kept
        for k in range(4):
            ts = T0 + 60 * np.arange(k * 3000, (k + 1) * 3000)
            assert writer.submit(_job(aid, ts, k)).result(timeout=60) == (ts.size, 0)
        assert writer.wal_truncations == 0 and wal.stat().st_size > writer.wal_truncate_bytes
        reader.close()
        for k in range(50):  # the checkpointer thread may hold the WAL a moment: retry
            writer._wal_next_try = 0.0  # the retry's wait, skipped
            ts = np.array([T0 + 60 * (12_000 + k)])
            assert writer.submit(_job(aid, ts, 9)).result(timeout=60) == (1, 0)
            if writer.wal_truncations:
                break
        assert writer.wal_truncations == 1 and wal.stat().st_size <= writer.wal_truncate_bytes
        _assert_rollups_equal_direct_aggregates(ctx, aid, 12_001 + k)
    finally:
        ctx.close()
