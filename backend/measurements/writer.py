"""The one writer: a thread fed by a queue, committing in groups.

Every write of the running service goes through :class:`Writer`. Request
handlers submit a measurement batch (or a function to run in the writer's
transaction) and await a future. The writer takes whatever is queued — up to
``Settings.database.writer_max_group_rows`` rows — into one transaction: each batch is
inserted ``ON CONFLICT DO NOTHING`` (should the group fail, each batch is tried
again alone, so one failing batch fails alone, all-or-nothing), the hourly
rollups of every touched series are updated once for the whole group (merged
increments where the new readings fill holes, else recomputed), and
one COMMIT (one fsync with
SQLite ``synchronous=FULL``) makes the group durable. Only then are the futures
resolved, so a 2xx answer means the rows are committed.

A batch of more rows than that (a back-fill of months) is committed in pieces of at
most that many, each queued behind whatever arrived meanwhile, so a live logger waits
for one piece, not for the whole back-fill (200,000 rows in one transaction held a live
reading 0.56-0.74 s on SQLite and 5.3-9.0 s on PostgreSQL). The batch is answered after
its last piece; should a piece fail, the pieces before it stay stored and
:class:`PartlyStored` says how many readings — sending the batch again stores exactly
the rest, as readings are keyed by (array, source, second) and inserted
``ON CONFLICT DO NOTHING``.

The hot path talks to the DBAPI driver directly (SQLite: multi-row
``INSERT … VALUES``; PostgreSQL: ``INSERT … SELECT FROM unnest(arrays)``)
because SQLAlchemy Core would cost more than the whole rest of the request.
"""

from __future__ import annotations

import functools
import logging
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import Connection, Engine, delete, insert, select, text, update

from backend.errors import InputError, Refusal
from backend.measurements.buckets import ROLLUP_WIDTH_S
from backend.measurements.fields import SENSOR_NAMES
from backend.measurements.rollups import (
    ROLLUP_COLUMNS,
    ROLLUP_SUMMED,
    SeriesWindow,
    affected_runs,
    increment_rows,
    rollup_rows,
)
from backend.storage.engine import SQLITE_BUSY_TIMEOUT_MS
from backend.storage.tables import DiagnosisDay, ServiceState

logger = logging.getLogger(__name__)

_STOP = object()
#: Readings per multi-row INSERT on SQLite (5 parameters each; SQLite allows 32,766).
SQLITE_CHUNK_ROWS = 1000
#: Parameters of one statement the writer sends SQLite at most (SQLite allows 32,766).
SQLITE_MAX_PARAMS = 30_000
#: SQLite: a WAL file larger than this is checkpointed and truncated by the writer
#: between two groups (:meth:`Writer._bound_wal`) [bytes].
WAL_TRUNCATE_BYTES = 64 * 1024 * 1024
#: How long that checkpoint may wait for readers still on the WAL [ms], and how long the
#: writer waits before it tries again after such a reader made it give up [s].
WAL_TRUNCATE_WAIT_MS = 50
WAL_TRUNCATE_RETRY_S = 5.0


@dataclass
class MeasurementJob:
    """Readings of one request: equal-length arrays, one source."""

    array_ids: np.ndarray
    source: int
    ts_s: np.ndarray
    voltage_v: np.ndarray  # NaN: a power-only reading (stored as NULL)
    current_a: np.ndarray
    power_w: np.ndarray
    #: ``(n, len(SENSOR_FIELDS))`` optional sensor values, NaN where absent; None: none at all
    sensors: np.ndarray | None = None
    future: Future[tuple[int, int]] = field(default_factory=Future)

    def __len__(self) -> int:
        return int(self.ts_s.shape[0])

    def sort(self) -> None:
        """Put the readings in primary-key order (array, time), in place.

        Stable: of readings repeated in the batch the first is still inserted
        first and wins. The database then appends to its B-tree instead of
        alternating between arrays, and the writer splits series by slices.
        """
        if len(self) > 1:
            order = np.lexsort((self.ts_s, self.array_ids))
            self.array_ids, self.ts_s = self.array_ids[order], self.ts_s[order]
            self.voltage_v, self.current_a = self.voltage_v[order], self.current_a[order]
            self.power_w = self.power_w[order]
            if self.sensors is not None:
                self.sensors = self.sensors[order]

    def columns(self) -> tuple[np.ndarray, ...]:
        """Value columns in storage order: voltage, current, power, then the sensors."""
        base = (self.ts_s, self.voltage_v, self.current_a, self.power_w)
        return base if self.sensors is None else (*base, *self.sensors.T)


    def piece(self, sel: slice) -> MeasurementJob:
        """The readings ``sel`` of this job as a job of their own (views, a future of
        their own)."""
        return MeasurementJob(
            self.array_ids[sel], self.source, self.ts_s[sel], self.voltage_v[sel],
            self.current_a[sel], self.power_w[sel],
            None if self.sensors is None else self.sensors[sel])


class PartlyStored(Exception):
    """A batch committed in pieces failed at a piece: its first ``stored`` of ``total``
    readings are committed, the rest is not written (the piece's error is the cause)."""

    def __init__(self, stored: int, total: int) -> None:
        super().__init__(f"{stored} of {total} readings stored before a piece failed")
        self.stored = stored
        self.total = total


@dataclass
class CallJob:
    """A function run by the writer in a transaction of its own."""

    fn: Callable[[Connection], Any]
    future: Future[Any] = field(default_factory=Future)


class _Sql:
    """Dialect-specific statements of the hot path."""

    def __init__(self, dialect: str) -> None:
        self.pg = dialect == "postgresql"
        self._values: dict[tuple[int, int, int], str] = {}
        ph = "%s" if self.pg else "?"
        cols = ", ".join(ROLLUP_COLUMNS)
        updates = ", ".join(f"{c} = excluded.{c}" for c in ROLLUP_COLUMNS[1:])
        self.upsert_rollup = (
            f"INSERT INTO measurement_rollups (array_id, source, {cols}) "
            f"VALUES ({', '.join([ph] * (len(ROLLUP_COLUMNS) + 2))}) "
            f"ON CONFLICT (array_id, source, bucket_s) DO UPDATE SET {updates}"
        )
        least, greatest = ("LEAST", "GREATEST") if self.pg else ("MIN", "MAX")
        t = "measurement_rollups"

        def extreme(fn: str, c: str) -> str:  # NULL (no value yet) on either side is ignored
            return f"{c} = {fn}(COALESCE({t}.{c}, excluded.{c}), COALESCE(excluded.{c}, {t}.{c}))"

        merge = ", ".join(
            [f"{c} = {t}.{c} + excluded.{c}" for c in ROLLUP_SUMMED]
            + [extreme(least, c) for c in ROLLUP_COLUMNS if c.startswith("min_")]
            + [extreme(greatest, c) for c in ROLLUP_COLUMNS if c.startswith("max_")]
            + [f"first_ts_s = {least}({t}.first_ts_s, excluded.first_ts_s)",
               f"last_ts_s = {greatest}({t}.last_ts_s, excluded.last_ts_s)"]
        )
        self.merge_rollup = (
            f"INSERT INTO measurement_rollups (array_id, source, {cols}) "
            f"VALUES ({', '.join([ph] * (len(ROLLUP_COLUMNS) + 2))}) "
            f"ON CONFLICT (array_id, source, bucket_s) DO UPDATE SET {merge}"
        )
        series = f"FROM measurements WHERE array_id = {ph} AND source = {ph}"
        self.before = f"SELECT ts_s, power_w {series} AND ts_s < {ph} ORDER BY ts_s DESC LIMIT 1"
        self.after = f"SELECT ts_s, power_w {series} AND ts_s >= {ph} ORDER BY ts_s LIMIT 1"
        self._ph = ph
        self._rollup_cols = cols
        self._merge_set = merge
        self._upsert_set = updates
        self.window = (
            f"SELECT ts_s, voltage_v, current_a, power_w, {', '.join(SENSOR_NAMES)} "
            "FROM measurements "
            f"WHERE array_id = {ph} AND source = {ph} AND ts_s >= {ph} AND ts_s <= {ph} "
            "ORDER BY ts_s"
        )
        self.drop_diagnosis = (  # backend/diagnosis/service.py caches per local day
            "DELETE FROM diagnosis_days WHERE site_id = (SELECT site_id FROM arrays WHERE id = "
            f"{ph}) AND day_end_s > {ph} AND day_start_s <= {ph}")
    def neighbours_of_runs(self, runs: int) -> str:
        """One statement giving, for each of ``runs`` runs ``(i, lo, hi)`` (parameters: the
        series' array and source, then the runs), the stored reading at or after ``lo``
        and the one before it — primary-key seeks inside the database, so the writer
        hands the GIL back once for all runs instead of twice per run."""
        ph = self._ph
        first = (f"(CAST({ph} AS INTEGER), CAST({ph} AS BIGINT), CAST({ph} AS BIGINT))")
        rest = f", ({ph}, {ph}, {ph})" * (runs - 1)

        def seek(col: str, where: str, order: str) -> str:
            return (f"(SELECT {col} FROM measurements m WHERE m.array_id = k.a AND "
                    f"m.source = k.s AND m.ts_s {where} ORDER BY m.ts_s {order} LIMIT 1)")

        return (
            f"WITH k(a, s) AS (VALUES (CAST({ph} AS INTEGER), CAST({ph} AS INTEGER))), "
            f"r(i, lo, hi) AS (VALUES {first}{rest}) "
            f"SELECT r.i, {seek('ts_s', '>= r.lo', 'ASC')}, {seek('power_w', '>= r.lo', 'ASC')}, "
            f"{seek('ts_s', '< r.lo', 'DESC')}, {seek('power_w', '< r.lo', 'DESC')} "
            "FROM r, k ORDER BY r.i")

    def rollup_rows_sql(self, rows: int, merge: bool) -> str:
        """SQLite: one ``INSERT … VALUES (…), (…) … ON CONFLICT DO UPDATE`` of ``rows``
        rollup rows (merged increments or recomputed rows). SQLite applies the rows in
        order, a later row of the same bucket merging into the earlier one as
        ``executemany`` would, but steps once for all of them (see :meth:`insert_job`)."""
        one = f"({', '.join(['?'] * (len(ROLLUP_COLUMNS) + 2))})"
        return (f"INSERT INTO measurement_rollups (array_id, source, {self._rollup_cols}) "
                f"VALUES {', '.join([one] * rows)} ON CONFLICT (array_id, source, bucket_s) "
                f"DO UPDATE SET {self._merge_set if merge else self._upsert_set}")

    def upsert_rollups(self, cur: Any, rows: list[tuple[Any, ...]], merge: bool) -> None:
        """Write rollup rows ``(array_id, source, *ROLLUP_COLUMNS)``: merged into the stored
        ones (increments) or replacing them. PostgreSQL: ``executemany`` (one statement
        may not update a row twice there; psycopg pipelines it)."""
        if not rows:
            return
        rows = _nan_to_none(rows)
        if self.pg:
            cur.executemany(self.merge_rollup if merge else self.upsert_rollup, rows)
            return
        width = len(ROLLUP_COLUMNS) + 2
        chunk = SQLITE_MAX_PARAMS // width
        for k in range(0, len(rows), chunk):
            part = rows[k:k + chunk]
            cur.execute(self.rollup_rows_sql(len(part), merge),
                        [x for row in part for x in row])

    def insert_job(self, cur: Any, job: MeasurementJob) -> int:
        """Insert a job's readings (``ON CONFLICT DO NOTHING``); how many were new.

        A job without sensor values names only the electrical columns (the others
        default to NULL), so the common case binds 5 values a reading, not 11.
        NaN is NULL at rest: SQLite stores a bound NaN as NULL itself, PostgreSQL
        would keep a float NaN, so NaN is sent to it as None.
        """
        n = len(job)
        names = _INSERT_COLUMNS[:5] if job.sensors is None else _INSERT_COLUMNS
        cols = (job.array_ids, *job.columns())
        if self.pg:
            types = ["int", "bigint", *["float8"] * (len(names) - 2)]
            aliases = ", ".join(f"c{j}" for j in range(1, len(names)))
            sql = (f"INSERT INTO measurements (array_id, source, {', '.join(names[1:])}) "
                   f"SELECT a, {int(job.source)}, {aliases} "
                   f"FROM unnest({', '.join(f'%s::{t}[]' for t in types)}) AS u(a, {aliases}) "
                   "ON CONFLICT DO NOTHING")
            cur.execute(sql, [_sql_list(c) for c in cols])
            return int(cur.rowcount)
        # SQLite: one multi-row INSERT per chunk, not executemany. executemany steps
        # (and releases the GIL) once per row, and each time the writer waits to get
        # the GIL back from the event loop (up to sys.getswitchinterval(), 5 ms): a
        # 3-4x slower insert under load. One statement steps once per chunk.
        width = len(names)
        flat: list[Any] = [None] * (width * n)
        for j, col in enumerate(cols):
            flat[j::width] = col.tolist()
        chunk = SQLITE_CHUNK_ROWS if width == 5 else SQLITE_CHUNK_ROWS // 2
        inserted = 0
        for k in range(0, n, chunk):
            rows = min(chunk, n - k)
            cur.execute(self._values_insert(rows, int(job.source), names),
                        flat[width * k:width * (k + rows)])
            inserted += cur.rowcount
        return inserted

    def _values_insert(self, rows: int, source: int, names: tuple[str, ...]) -> str:
        """``INSERT … VALUES (…), (…) …`` of ``rows`` readings of one source (memoised)."""
        key = (rows, source, len(names))
        sql = self._values.get(key)
        if sql is None:
            if len(self._values) >= 64:  # odd batch sizes: keep the memo small
                self._values.clear()
            one = f"(?, {source}, {', '.join(['?'] * (len(names) - 1))})"
            sql = self._values[key] = (
                f"INSERT INTO measurements (array_id, source, {', '.join(names[1:])}) "
                f"VALUES {', '.join([one] * rows)} ON CONFLICT DO NOTHING")
        return sql


#: Columns of an insert, ``array_id`` first (``source`` is a literal of the statement).
_INSERT_COLUMNS = ("array_id", "ts_s", "voltage_v", "current_a", "power_w", *SENSOR_NAMES)


def _sql_list(col: np.ndarray) -> list[Any]:
    """A column as a Python list for the driver, NaN as None (NULL)."""
    if col.dtype.kind == "f" and np.isnan(col).any():
        out = col.astype(object)
        out[np.isnan(col)] = None
        return out.tolist()
    return col.tolist()


def _all_duplicates(jobs: list[MeasurementJob], counts: list[int]) -> set[tuple[int, int]]:
    """Series whose every job of the group is of that series alone and inserted nothing
    (``ON CONFLICT DO NOTHING`` kept the stored rows), so their rollups stand as they are."""
    seen: dict[tuple[int, int], bool] = {}
    for job, inserted in zip(jobs, counts, strict=True):
        ids = np.unique(job.array_ids)
        for a in ids.tolist():
            key = (int(a), job.source)
            seen[key] = seen.get(key, True) and ids.size == 1 and inserted == 0
    return {key for key, dup in seen.items() if dup}


def _series_window(parts: list[tuple[np.ndarray, ...]]) -> SeriesWindow:
    """The new readings of one series (parts as :meth:`MeasurementJob.columns`, in
    submission order) sorted by time; of a second sent twice the first write wins."""
    ts, first = np.unique(np.concatenate([p[0] for p in parts]), return_index=True)
    v, i, p = (np.concatenate([part[j] for part in parts])[first] for j in (1, 2, 3))
    sensors = None
    if any(len(part) > 4 for part in parts):
        sensors = np.concatenate([
            np.column_stack(part[4:]) if len(part) > 4
            else np.full((part[0].size, len(SENSOR_NAMES)), np.nan) for part in parts
        ])[first]
    return SeriesWindow(ts, v, i, p, sensors)


def _rows(job: Any) -> int:
    """Readings a queued job writes (a call: none)."""
    return len(job) if isinstance(job, MeasurementJob) else 0


#: A run of new readings of a series (a slice of them) and the stored readings
#: ``(ts_s, power_w)`` just before and after it.
_Hole = tuple[slice, tuple[int, float] | None, tuple[int, float] | None]
#: Most runs a group's new readings of one series are checked in for holes; past
#: it their rollups are recomputed (a sparse batch: one window read is cheaper).
MAX_RUNS = 256


def _nan_to_none(rows: list[tuple[Any, ...]]) -> list[tuple[Any, ...]]:
    """Rollup rows with NaN (an aggregate of no value) as None, for both drivers."""
    return [tuple(None if type(x) is float and x != x else x for x in r) for r in rows]


class Writer:
    """The service's single database writer (a daemon thread and a queue)."""

    def __init__(
        self, engine: Engine, phase_of_array: Callable[[int], int], max_gap_s: int,
        max_group_rows: int = 20_000,
    ) -> None:
        self.engine = engine
        self.phase_of_array = phase_of_array
        self.max_gap_s = max_gap_s
        self.max_group_rows = max_group_rows
        self._queue: queue.Queue[Any] = queue.Queue()
        self._thread: threading.Thread | None = None
        self._sql = _Sql(engine.dialect.name)
        self.groups_committed = 0
        self.rows_committed = 0
        #: series rollups recomputed from stored rows (new readings among stored ones)
        self.rollup_refreshes = 0
        self._checkpointer: threading.Thread | None = None
        self._stop_checkpoints = threading.Event()
        database = engine.url.database
        self._wal_path = (Path(f"{database}-wal") if not self._sql.pg and database
                          and database != ":memory:" else None)
        self.wal_truncate_bytes = WAL_TRUNCATE_BYTES
        #: WAL truncations done, and when the writer may try the next one (monotonic s)
        self.wal_truncations = 0
        self._wal_next_try = 0.0
        #: batches committed in pieces whose last piece is still to come (writer thread only)
        self._split_open = 0

    # -- lifecycle ---------------------------------------------------------
    def start(self) -> None:
        """Start the writer thread (and, on SQLite, the WAL checkpointer)."""
        self._thread = threading.Thread(target=self._run, name="heliotwin-writer", daemon=True)
        self._thread.start()
        if not self._sql.pg:
            self._stop_checkpoints.clear()
            self._checkpointer = threading.Thread(
                target=self._checkpoint_loop, name="heliotwin-checkpoint", daemon=True)
            self._checkpointer.start()

    def stop(self, timeout_s: float = 30.0) -> None:
        """Finish everything queued so far, then stop the thread."""
        if self._thread is None:
            return
        self._queue.put(_STOP)
        self._thread.join(timeout_s)
        self._thread = None
        self._stop_checkpoints.set()
        if self._checkpointer is not None:
            self._checkpointer.join(timeout_s)
            self._checkpointer = None

    # -- submitting --------------------------------------------------------
    def submit(self, job: MeasurementJob) -> Future[tuple[int, int]]:
        """Queue a batch; the future gives ``(accepted, duplicates)`` once committed.

        The writer owns the job from here: it rebinds the job's columns in key order.
        """
        self._check_running()
        self._queue.put(job)
        return job.future

    def call(self, fn: Callable[[Connection], Any]) -> Future[Any]:
        """Run ``fn(connection)`` in a writer transaction; the future gives its result."""
        self._check_running()
        job = CallJob(fn)
        self._queue.put(job)
        return job.future

    def _check_running(self) -> None:
        if self._thread is None:
            raise RuntimeError("the writer is not running")

    # -- the threads -------------------------------------------------------
    def _checkpoint_loop(self, interval_s: float = 1.0) -> None:
        """SQLite: copy the WAL into the database file every second, off the writer.

        The writer's connection has automatic checkpoints off, so a commit never
        waits for a checkpoint (whose fsync can take long on a busy disk); a
        PASSIVE checkpoint waits for no reader or writer (SQLite docs, "WAL").
        """
        conn = self.engine.connect()
        try:
            dbapi: Any = conn.connection.driver_connection
            while not self._stop_checkpoints.wait(interval_s):
                try:
                    dbapi.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchall()
                except Exception:  # noqa: BLE001 - a busy database: try again next time
                    logger.debug("checkpoint skipped", exc_info=True)
            dbapi.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()
        finally:
            conn.close()

    def _run(self) -> None:
        conn = self.engine.connect().execution_options(sqlite_immediate=True)
        if not self._sql.pg:
            conn.connection.driver_connection.execute(  # type: ignore[union-attr]
                "PRAGMA wal_autocheckpoint=0")
        carry: Any = None  # a job taken from the queue that did not fit the last group
        try:
            while True:
                first = self._queue.get() if carry is None else carry
                carry = None
                if first is _STOP:
                    if self._split_open:  # a batch's next piece is queued behind the stop
                        self._queue.put(_STOP)
                        continue
                    break
                first = self._first_piece(first)
                group = [first]
                rows = _rows(first)
                while rows < self.max_group_rows:
                    try:
                        nxt = self._queue.get_nowait()
                    except queue.Empty:
                        break
                    if nxt is _STOP or rows + _rows(nxt) > self.max_group_rows:
                        carry = nxt
                        break
                    group.append(nxt)
                    rows += _rows(nxt)
                self._commit_group(conn, group)
                self._check_gap(conn)
                if self._wal_path is not None:
                    self._bound_wal(conn)
        finally:
            conn.close()
            logger.info("writer stopped after %d group commits of %d readings "
                        "(%d rollup recomputations)", self.groups_committed,
                        self.rows_committed, self.rollup_refreshes)

    def _first_piece(self, job: Any) -> Any:
        """A job, or of a batch over :attr:`max_group_rows` readings its first piece.

        The batch is sorted and cut into pieces of at most that many readings; each piece
        commits in a group of its own, and once it has, the next is queued behind what
        arrived meanwhile (the batch's other writes wait for one piece at a time). The
        batch's future gives the summed counts after the last piece, or
        :class:`PartlyStored` after a failed one (the rest is then not written)."""
        if not isinstance(job, MeasurementJob) or len(job) <= self.max_group_rows:
            return job
        job.sort()
        step = self.max_group_rows
        pieces = [job.piece(slice(k, k + step)) for k in range(0, len(job), step)]
        counts = [0, 0]  # accepted, duplicates so far
        self._split_open += 1

        def committed(k: int, done: Future[tuple[int, int]]) -> None:  # on the writer thread
            exc = done.exception()
            if exc is not None:
                self._split_open -= 1
                err = PartlyStored(sum(counts), len(job))
                err.__cause__ = exc
                job.future.set_exception(err)
                return
            accepted, duplicates = done.result()
            counts[0] += accepted
            counts[1] += duplicates
            if k + 1 < len(pieces):
                self._queue.put(pieces[k + 1])
            else:
                self._split_open -= 1
                job.future.set_result((counts[0], counts[1]))

        for k, piece in enumerate(pieces):
            piece.future.add_done_callback(functools.partial(committed, k))
        return pieces[0]

    def _bound_wal(self, conn: Connection) -> None:
        """SQLite: checkpoint and truncate a WAL grown past :attr:`wal_truncate_bytes`.

        The checkpointer's PASSIVE checkpoints copy the WAL into the database, but SQLite
        starts the WAL file over only when a write begins with all of it copied and no
        reader on it, which a writer committing back to back rarely meets: under
        bench_load's writes (no readers) the WAL reached 79 MB in 30 s and kept growing.
        Here, between two groups, nothing else writes; readers still on the WAL are
        waited for at most :data:`WAL_TRUNCATE_WAIT_MS` (a long read makes it give up and
        try again :data:`WAL_TRUNCATE_RETRY_S` later), so a commit waits for no reader.
        """
        assert self._wal_path is not None
        try:
            size = self._wal_path.stat().st_size
        except OSError:
            return
        if size <= self.wal_truncate_bytes or time.monotonic() < self._wal_next_try:
            return
        dbapi: Any = conn.connection.driver_connection
        dbapi.execute(f"PRAGMA busy_timeout={WAL_TRUNCATE_WAIT_MS}")
        try:
            busy = dbapi.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()[0]
        except Exception:  # noqa: BLE001 - the database is busy: the next try will do
            busy = 1
        finally:
            dbapi.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
        if busy:
            self._wal_next_try = time.monotonic() + WAL_TRUNCATE_RETRY_S
        else:
            self.wal_truncations += 1

    def _commit_group(self, conn: Connection, group: list[Any]) -> None:
        jobs = [j for j in group if isinstance(j, MeasurementJob)]
        if jobs:
            try:
                counts = self._commit_measurements(conn, jobs)
            except Exception as exc:
                if len(jobs) == 1:
                    logger.warning("write of %d readings failed: %r", len(jobs[0]), exc)
                    jobs[0].future.set_exception(exc)
                else:  # find the culprit: each batch alone, all-or-nothing
                    for job in jobs:
                        self._commit_group(conn, [job])
            else:
                self.groups_committed += 1
                self.rows_committed += sum(len(job) for job in jobs)
                for job, accepted in zip(jobs, counts, strict=True):
                    job.future.set_result((accepted, len(job) - accepted))
        for job in group:
            if isinstance(job, CallJob):
                try:
                    with conn.begin():
                        result = job.fn(conn)
                except Exception as exc:  # noqa: BLE001 - reported to the submitter
                    # a refusal or bad input (a 404, a 422) is the caller's answer, not a
                    # failed write
                    answer = isinstance(exc, Refusal | InputError)
                    logger.log(logging.DEBUG if answer else logging.WARNING,
                               "write call failed: %r", exc)
                    job.future.set_exception(exc)
                else:
                    job.future.set_result(result)

    def _commit_measurements(self, conn: Connection, jobs: list[MeasurementJob]) -> list[int]:
        """Insert the batches and refresh their rollups in one transaction; accepted counts.

        Plain DBAPI: ``BEGIN IMMEDIATE`` … ``COMMIT`` on SQLite (the driver is in
        autocommit mode, see ``backend.storage.engine``), the driver's implicit transaction and
        ``commit()`` on PostgreSQL.
        """
        dbapi: Any = conn.connection.driver_connection
        cur = dbapi.cursor()
        try:
            if not self._sql.pg:
                cur.execute("BEGIN IMMEDIATE")
            touched: dict[tuple[int, int], list[tuple[np.ndarray, ...]]] = {}
            for job in jobs:
                job.sort()
                self._note_touched(job, touched)
            new = {key: _series_window(parts) for key, parts in touched.items()}
            holes = {key: self._holes(cur, key, w.ts_s) for key, w in new.items()}
            counts = [self._sql.insert_job(cur, job) for job in jobs]
            unchanged = _all_duplicates(jobs, counts)
            for key, w in new.items():
                if key in unchanged:  # a re-sent batch: stored rows and rollups as they were
                    continue
                self._update_rollups(cur, key, w, holes[key])
                if key[1] == 0:  # measured readings: that day's cached diagnosis is stale
                    cur.execute(self._sql.drop_diagnosis,
                                (key[0], int(w.ts_s[0]), int(w.ts_s[-1])))
            if self._sql.pg:
                dbapi.commit()
            else:
                cur.execute("COMMIT")
            return counts
        except BaseException:
            if self._sql.pg:
                dbapi.rollback()
            elif dbapi.in_transaction:
                cur.execute("ROLLBACK")
            raise
        finally:
            cur.close()

    @staticmethod
    def _note_touched(
        job: MeasurementJob, touched: dict[tuple[int, int], list[tuple[np.ndarray, ...]]]
    ) -> None:
        cols = job.columns()
        ids = job.array_ids
        if ids.size and (ids == ids[0]).all():
            touched.setdefault((int(ids[0]), job.source), []).append(cols)
            return
        edges = [0, *(np.flatnonzero(np.diff(ids)) + 1).tolist(), ids.size]  # sorted by id
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            touched.setdefault((int(ids[a]), job.source), []).append(tuple(c[a:b] for c in cols))

    def _holes(self, cur: Any, key: tuple[int, int], ts: np.ndarray) -> list[_Hole] | None:
        """Where the new readings ``ts`` (sorted, unique) of a series go: runs of them, each
        with the stored readings just before and after it, or None when a stored reading
        lies among the new ones of a run (then the rollups are recomputed).

        One run when no stored reading lies within their span (a live logger's append, a
        back-fill). Else the readings are split where they are more than ``max_gap_s``
        apart — a group commit holds readings of many loggers of one array, each
        appending to its own stretch of time — and each run must fill a hole: an
        interval between two runs is longer than the gap, so it carries no energy and
        the runs' increments add up to the whole group's.
        """
        whole = self._neighbours(cur, key, int(ts[0]), int(ts[-1]))
        if whole is not None:
            return [(slice(None), *whole)]
        cuts = np.flatnonzero(np.diff(ts) > self.max_gap_s) + 1
        if cuts.size == 0 or cuts.size >= MAX_RUNS:
            return None
        edges = [0, *cuts.tolist(), ts.size]
        bounds = [(int(ts[a]), int(ts[b - 1])) for a, b in zip(edges[:-1], edges[1:],
                                                                strict=True)]
        found = self._neighbours_of_runs(cur, key, bounds)
        if found is None:
            return None
        return [(slice(a, b), *around)
                for a, b, around in zip(edges[:-1], edges[1:], found, strict=True)]

    def _neighbours_of_runs(self, cur: Any, key: tuple[int, int], bounds: list[tuple[int, int]]
                            ) -> list[tuple[tuple[int, float] | None, tuple[int, float] | None]
                                      ] | None:
        """:meth:`_neighbours` of every run ``(lo, hi)`` in one statement (see
        :meth:`_Sql.neighbours_of_runs`); None when a stored reading lies within a run."""
        out = []
        per = SQLITE_MAX_PARAMS // 3 - 1
        for k in range(0, len(bounds), per):
            part = bounds[k:k + per]
            params = [*key, *(x for j, (lo, hi) in enumerate(part, k) for x in (j, lo, hi))]
            cur.execute(self._sql.neighbours_of_runs(len(part)), params)
            for (_, after_ts, after_p, before_ts, before_p), (_, hi) in zip(
                    cur.fetchall(), part, strict=True):
                if after_ts is not None and after_ts <= hi:
                    return None
                out.append((None if before_ts is None else (int(before_ts), float(before_p)),
                            None if after_ts is None else (int(after_ts), float(after_p))))
        return out

    def _neighbours(self, cur: Any, key: tuple[int, int], lo: int, hi: int
                    ) -> tuple[tuple[int, float] | None, tuple[int, float] | None] | None:
        """Stored readings just before ``lo`` and after ``hi``, or None when stored
        readings lie within ``[lo, hi]``."""
        cur.execute(self._sql.after, (*key, lo))
        row = cur.fetchone()
        if row is not None and row[0] <= hi:
            return None
        nxt = None if row is None else (int(row[0]), float(row[1]))
        cur.execute(self._sql.before, (*key, lo))
        row = cur.fetchone()
        return (None if row is None else (int(row[0]), float(row[1]))), nxt

    def _update_rollups(self, cur: Any, key: tuple[int, int], w: SeriesWindow,
                        holes: list[_Hole] | None) -> None:
        """Rollups after new readings ``w``: merged increments when they fill holes of
        the series (appends of live loggers, back-fills in any order), else recomputed."""
        if holes is not None:
            phase = self.phase_of_array(key[0])
            rows = [r for sel, prev, nxt in holes
                    for r in increment_rows(prev, nxt, w.part(sel), phase, self.max_gap_s)]
            self._sql.upsert_rollups(cur, [(*key, *r) for r in rows], merge=True)
            return
        self.rollup_refreshes += 1
        self._refresh_rollups(cur, key[0], key[1], w.ts_s)

    def _refresh_rollups(self, cur: Any, array_id: int, source: int, ts_s: np.ndarray,
                         phase: int | None = None) -> None:
        """Recompute the rollups of every bucket that new readings at ``ts_s`` can change
        (``phase``: the site's rollup phase, by default the registry's)."""
        phase = self.phase_of_array(array_id) if phase is None else phase
        gap = self.max_gap_s
        width = ROLLUP_WIDTH_S
        out: list[tuple[Any, ...]] = []
        for k_first, k_last in affected_runs(ts_s, phase, gap):
            lo = k_first * width + phase - gap
            hi = (k_last + 1) * width + phase + gap
            cur.execute(self._sql.window, (array_id, source, lo, hi))
            fetched = cur.fetchall()
            if not fetched:
                continue
            data = np.array(fetched, dtype=np.float64)  # NULL → NaN
            window = SeriesWindow(data[:, 0].astype(np.int64), data[:, 1], data[:, 2], data[:, 3],
                                  data[:, 4:])
            out.extend((array_id, source, *row)
                       for row in rollup_rows(window, k_first, k_last, phase, gap))
        self._sql.upsert_rollups(cur, out, merge=False)

    #: hours of one series recomputed at a time when the energy gap changes (a month)
    GAP_REBUILD_BUCKETS = 720
    #: how often [s], at most, the writer looks whether another service on the database
    #: recorded another energy gap (:meth:`_check_gap`)
    GAP_CHECK_S = 30.0
    _gap_checked = 0.0

    def _check_gap(self, conn: Connection) -> None:
        """Another service on this database that started with another energy gap recomputed
        the hours and recorded its gap; the hours this one writes bridge its own (a rolling
        restart that changes ``HELIOTWIN_ENERGY_MAX_GAP_S``: both kept writing, and the
        next start saw its gap recorded and recomputed nothing; a tester's finding). Seen
        here, the record is marked mixed, so the next start of any service recomputes every
        hour under its gap, and an error says to restart this one."""
        now = time.monotonic()
        if now - self._gap_checked < self.GAP_CHECK_S:
            return
        self._gap_checked = now
        key = "rollup_energy_max_gap_s"
        try:
            with conn.begin():
                stored = conn.execute(select(ServiceState.value)
                                      .where(ServiceState.key == key)).scalar()
                if stored is None or stored == str(self.max_gap_s) or stored.startswith("mixed"):
                    return
                conn.execute(update(ServiceState).where(ServiceState.key == key)
                             .values(value=f"mixed {stored} and {self.max_gap_s}"))
        except Exception:  # noqa: BLE001 - a look, not a write of readings
            logger.warning("energy gap check failed", exc_info=True)
            return
        logger.error("another service on this database bridges energy gaps of %s s, this one "
                     "%d s (HELIOTWIN_ENERGY_MAX_GAP_S): the hours are marked to be "
                     "recomputed at the next start; restart every service with one gap",
                     stored, self.max_gap_s)

    def match_rollups_to_gap(self, conn: Connection) -> int:
        """Recompute every stored hour's rollup when the energy gap is not the one they were
        built with (``service_state.rollup_energy_max_gap_s``; unrecorded on a database
        from before migration 0013: once, whatever the gap), drop the cached diagnosis days
        (computed with the old gap too) and record the gap. Raising
        ``HELIOTWIN_ENERGY_MAX_GAP_S`` for an hourly logger left its stored hours at 0 Wh
        shown as full coverage. Every series is recomputed, with its site's phase as stored
        (``sites.bucket_phase_s``: a site whose file is gone keeps right hours should it come
        back); the twin's, stored at 60 s steps, only when a gap under 60 s is involved.
        Run in a writer transaction (:meth:`call`) before the service serves; the series it
        recomputed."""
        key = "rollup_energy_max_gap_s"
        stored = conn.execute(select(ServiceState.value).where(ServiceState.key == key)
                              ).scalar()
        if stored == str(self.max_gap_s):
            return 0
        twin_too = stored is None or not stored.isdigit() or min(int(stored), self.max_gap_s) < 60
        series = conn.execute(text(
            "SELECT DISTINCT r.array_id, r.source, s.bucket_phase_s FROM measurement_rollups r "
            "JOIN arrays a ON a.id = r.array_id JOIN sites s ON s.site_id = a.site_id "
            "ORDER BY r.array_id, r.source")).all()
        series = [x for x in series if twin_too or x[1] == 0]
        if series:
            logger.warning("the energy gap is %d s, the stored hourly energies bridged %s: "
                           "recomputing %d series before serving", self.max_gap_s,
                           f"{stored} s" if stored is not None else "an unrecorded one",
                           len(series))
        cur = conn.connection.driver_connection.cursor()  # type: ignore[union-attr]
        half = ROLLUP_WIDTH_S // 2
        started = time.monotonic()
        try:
            for k, (array_id, source, phase) in enumerate(series, 1):
                buckets = np.array(conn.execute(text(
                    "SELECT bucket_s FROM measurement_rollups WHERE array_id = :a AND "
                    "source = :s ORDER BY bucket_s"), {"a": array_id, "s": source}
                    ).scalars().all(), dtype=np.int64)
                for lo in range(0, buckets.size, self.GAP_REBUILD_BUCKETS):
                    # an hour's middle: the hours it and its readings' intervals can change
                    self._refresh_rollups(cur, array_id, source,
                                          buckets[lo:lo + self.GAP_REBUILD_BUCKETS] + half,
                                          int(phase or 0))
                logger.info("energy gap: series %d of %d recomputed (%d hours, %.0f s so far)",
                            k, len(series), buckets.size, time.monotonic() - started)
        finally:
            cur.close()
        conn.execute(delete(DiagnosisDay))
        conn.execute(delete(ServiceState).where(ServiceState.key == key))
        conn.execute(insert(ServiceState).values(key=key, value=str(self.max_gap_s)))
        return len(series)
