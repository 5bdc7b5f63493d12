"""The twin's expected I/V/P beside the measurements (source ``twin``).

Two ways the twin series gets into ``measurements``:

- the live loop (:meth:`TwinService.run_live`, its own thread): every minute while
  the service runs, the minute's row of each site (``sim.twin.simulate`` run an hour
  ahead at once, :meth:`TwinService._minute`), written through the writer, and handed
  to the 3D scene (``update_live``);
- on demand (:meth:`TwinService.ensure`): before a query reads twin data of past
  days, the missing part of each local day up to now is simulated in one
  vectorised run and stored, so ``twin_wh`` exists for any day, not only for the
  minutes the service happened to be running. ``twin_coverage`` remembers how
  far each day is stored; the live loop extends it by the minute it stores, so a read of
  today does not simulate that minute again.

The twin uses clear sky (``sim.twin.simulate`` with ``weather=None``).

A site whose config changed (edited from the dashboard, or its file changed
between two starts) has its stored twin readings, their rollups and its
``twin_coverage`` dropped (``backend.sites.drop_twin_cache``, under
:meth:`TwinService.site_lock`), so the next read simulates them again.
:meth:`TwinService.no_twin_reason` says why a period has no twin (a camera-only
site, a day in the future, or one older than the on-demand window).
"""

from __future__ import annotations

import asyncio
import datetime as dt
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import anyio
import numpy as np
import pandas as pd
from sqlalchemy import Connection, Engine, update
from sqlalchemy.dialects import postgresql, sqlite

from backend.measurements.writer import MeasurementJob, Writer
from backend.sites import Registry, SiteInfo
from backend.storage.sqlraw import fetch
from backend.storage.tables import SOURCE_CODES, TwinCoverage
from sim.twin import simulate

logger = logging.getLogger(__name__)
TWIN = SOURCE_CODES["twin"]
_COVERED = ("SELECT day_start_s, covered_until_s FROM twin_coverage "
            "WHERE site_id = ? AND day_start_s >= ? AND day_start_s <= ?")
_FIRST_READING = ("SELECT first_ts_s FROM measurement_rollups WHERE array_id = ? AND source = ? "
                  "AND n > 0 ORDER BY bucket_s LIMIT 1")


@dataclass
class LiveSample:
    """The twin at one minute: what the status tiles and the 3D scene show."""

    ts_s: int
    values: dict[str, float]


#: How far ahead the live twin simulates at once [s] (:meth:`TwinService._minute`).
AHEAD_S = 3600
#: Ticks of the live loop whose lag :meth:`LiveClock.status` takes the maximum of.
LAG_WINDOW = 60


@dataclass
class LiveClock:
    """When the live loop's ticks were due and when each one's minute was committed.

    A tick is due on the grid of ``interval_s`` (minute boundaries by default); its lag
    is how long after that its readings were committed. A tick that overruns the next
    due time skips it (the next one is due at the next grid point after it ended), so
    the loop never queues work it cannot do, and the overrun shows as that tick's lag.
    """

    interval_s: float
    ticks: int = 0
    running_due_s: float | None = None
    last_minute_s: int | None = None
    last_done_s: float | None = None
    #: of the last tick: from its due time until its step began (the live thread's
    #: wake-up), and from then until its readings were committed [s]
    last_start_delay_s: float | None = None
    last_step_s: float | None = None
    recent_lags_s: list[float] = field(default_factory=list)

    def next_due(self, now_s: float) -> float:
        """The first grid point after ``now_s``."""
        return (now_s // self.interval_s + 1) * self.interval_s

    def begin(self, due_s: float) -> None:
        self.running_due_s = due_s

    def end(self, due_s: float, done_s: float, started_s: float | None = None) -> None:
        self.ticks += 1
        if started_s is not None:
            self.last_start_delay_s = started_s - due_s
            self.last_step_s = done_s - started_s
        self.running_due_s = None
        self.last_minute_s = int(due_s // 60 * 60)
        self.last_done_s = done_s
        self.recent_lags_s = [*self.recent_lags_s[-(LAG_WINDOW - 1):], done_s - due_s]

    def status(self, now_s: float | None = None) -> dict[str, Any]:
        """The loop's lag: of a tick still running, now minus its due time; else the last
        tick's; ``max_lag_s`` over the last :data:`LAG_WINDOW` ticks and the running one."""
        now = time.time() if now_s is None else now_s
        running = None if self.running_due_s is None else max(0.0, now - self.running_due_s)
        lags = self.recent_lags_s + ([running] if running is not None else [])
        return {
            "interval_s": self.interval_s, "ticks": self.ticks,
            "last_minute_s": self.last_minute_s, "last_done_s": self.last_done_s,
            "lag_s": running if running is not None else
            (self.recent_lags_s[-1] if self.recent_lags_s else None),
            "max_lag_s": max(lags) if lags else None,
            "last_start_delay_s": self.last_start_delay_s, "last_step_s": self.last_step_s,
        }


def jobs_from_series(info: SiteInfo, series: pd.DataFrame) -> list[MeasurementJob]:
    """One ``twin`` measurement job per array from a ``TwinResult.series``."""
    ts = (series.index.as_unit("s").asi8).astype(np.int64)
    jobs = []
    for name, arr in info.arrays.items():
        cols = [f"{name}_{q}" for q in ("voltage_v", "current_a", "power_w")]
        if not all(c in series.columns for c in cols):
            continue
        v, i, p = (np.nan_to_num(series[c].to_numpy(np.float64)) for c in cols)
        jobs.append(MeasurementJob(np.full(ts.size, arr.array_id, np.int64), TWIN, ts, v, i, p))
    return jobs


class TwinService:
    """Writes and caches twin series for every site."""

    def __init__(self, registry: Registry, engine: Engine, writer: Writer,
                 max_days: int, scene: Any = None, scene_site: str | None = None,
                 history_days: int = 400) -> None:
        self.registry = registry
        self.engine = engine
        self.writer = writer
        self.max_days = max_days
        self.history_days = history_days
        self.scene = scene
        self.scene_site = scene_site
        self.latest: dict[str, LiveSample] = {}
        #: per site: its Site, the window [from, to) [s] and its minutes (see :meth:`_minute`)
        self._ahead: dict[str, tuple[Any, int, int, pd.DataFrame]] = {}
        #: per site: the first and the last minute of the live loop's current run of
        #: minutes stored tick after tick (:meth:`live_step`, :func:`_extend_coverage`)
        self._live_run: dict[str, tuple[int, int]] = {}
        #: the live loop's schedule and lag (None until :meth:`run_live` starts)
        self.clock: LiveClock | None = None
        self._locks = {sid: threading.Lock() for sid in registry.sites}

    def _lock(self, site_id: str) -> threading.Lock:
        return self._locks.setdefault(site_id, threading.Lock())  # a site added while running

    def simulable(self, site_id: str) -> bool:
        """Whether ``sim.twin.simulate`` can run the site (it has a tracker and a fixed array)."""
        info = self.registry.sites.get(site_id)
        return info is not None and {"tracker", "fixed"} <= set(info.site.arrays)

    # -- on demand ----------------------------------------------------------
    def _day_starts(self, info: SiteInfo, start_s: int, end_s: int) -> list[int]:
        zone = info.zone
        d = dt.datetime.fromtimestamp(start_s, zone).date()
        out = []
        for _ in range(self.max_days + 1):
            t = int(dt.datetime(d.year, d.month, d.day, tzinfo=zone).timestamp())
            if t >= end_s:
                break
            out.append(t)
            d += dt.timedelta(days=1)
        if len(out) > self.max_days:
            logger.warning("twin on demand limited to %d days", self.max_days)
            out = out[: self.max_days]
        return out

    def ensure(self, site_id: str, start_s: int, end_s: int, now_s: float | None = None) -> int:
        """Store the twin series of every local day touching ``[start_s, end_s)`` up to now.

        Returns the number of readings simulated (0 when everything was stored). What is
        stored is looked up first without the site's lock (a read of stored days, the
        common case, waits for no other read); only missing days take the lock, look
        again and simulate.
        """
        if not self.simulable(site_id):
            return 0
        info = self.registry.sites[site_id]
        now_minute = int((time.time() if now_s is None else now_s) // 60 * 60)
        with self.engine.connect() as conn:
            start_s = max(start_s, self._history_floor_s(info, now_minute, conn))
            days = self._day_starts(info, start_s, min(end_s, now_minute + 1))
            if not days or not self._missing(conn, info, days, now_minute)[1]:
                return 0
        with self._lock(site_id):
            with self.engine.connect() as conn:
                spans, marks = self._missing(conn, info, days, now_minute)
            total = 0
            for lo, hi in spans:
                total += self._simulate_and_store(info, lo, hi)
            if marks:
                self.writer.call(lambda conn: _mark_coverage(conn, site_id, marks)).result()
            return total

    @staticmethod
    def _missing(conn: Connection, info: SiteInfo, days: list[int], now_minute: int
                 ) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
        """The pieces of ``days`` (local day starts) not stored yet, up to ``now_minute``:
        ``(from, to)`` spans to simulate and ``(day, covered_until)`` marks to store."""
        covered = dict(fetch(conn, _COVERED, (info.site_id, days[0], days[-1])))
        spans: list[tuple[int, int]] = []
        marks: list[tuple[int, int]] = []
        for j, day in enumerate(days):
            day_end = days[j + 1] if j + 1 < len(days) else int(
                (dt.datetime.fromtimestamp(day, info.zone) + dt.timedelta(hours=36))
                .replace(hour=0, minute=0, second=0).timestamp())
            want = min(day_end, now_minute)
            have = covered.get(day, day)
            if have >= want:
                continue
            marks.append((day, want))
            if spans and spans[-1][1] == have:
                spans[-1] = (spans[-1][0], want)
            else:
                spans.append((have, want))
        return spans, marks

    def site_lock(self, site_id: str) -> threading.Lock:
        """The lock :meth:`ensure` holds while it simulates and stores a site's twin; a
        config change (``backend.sites.save_site``) holds it while it drops the cache."""
        return self._lock(site_id)

    def forget(self, site_id: str) -> None:
        """Drop the cached live sample of a site whose config changed."""
        self.latest.pop(site_id, None)
        self._ahead.pop(site_id, None)
        self._live_run.pop(site_id, None)

    def no_twin_reason(self, site_id: str, start_s: int, end_s: int,
                       now_s: float | None = None) -> str | None:
        """Why ``[start_s, end_s)`` has no on-demand twin, or None when it can have one."""
        if not self.simulable(site_id):
            return "no twin: the site has no tracker and fixed array pair to simulate"
        now = int(time.time() if now_s is None else now_s)
        if start_s >= now:
            return "no twin yet: the period has not begun"
        info = self.registry.sites[site_id]
        floor = self._history_floor_s(info, now // 60 * 60)
        if end_s <= floor:
            return (f"no twin: older than the on-demand twin window ({self.history_days} days "
                    "before now, HELIOTWIN_TWIN_HISTORY_DAYS, or the site's first reading)")
        return None

    def _history_floor_s(self, info: SiteInfo, now_s: int, conn: Connection | None = None
                         ) -> int:
        """Earliest time reads fill with the twin: ``history_days`` before now, or the
        first measured reading of the site if that is older.

        Reads need no token, so without this floor anyone could make the server
        simulate and store twin series for any range of years. The first reading is
        each array's first measured rollup bucket with a reading (a primary-key seek).
        """
        floor = now_s - self.history_days * 86_400
        array_ids = [a.array_id for a in info.arrays.values()]
        if not array_ids:
            return floor
        if conn is None:
            with self.engine.connect() as own:
                return self._history_floor_s(info, now_s, own)
        firsts = [int(row[0][0]) for a in array_ids
                  if (row := fetch(conn, _FIRST_READING, (a, SOURCE_CODES["measured"])))]
        return min([floor, *firsts])

    def _simulate_and_store(self, info: SiteInfo, lo: int, hi: int) -> int:
        result = simulate(info.site, pd.Timestamp(lo, unit="s", tz="UTC"),
                          pd.Timestamp(hi, unit="s", tz="UTC"), step_s=60)
        futures = [self.writer.submit(job) for job in jobs_from_series(info, result.series)]
        for f in futures:
            f.result()
        logger.info("twin stored for %s: %d minutes from %s", info.site_id,
                    len(result.series), pd.Timestamp(lo, unit="s", tz="UTC"))
        return len(result.series)

    # -- live ---------------------------------------------------------------
    def _minute(self, info: SiteInfo, minute: int) -> tuple[LiveSample, pd.DataFrame]:
        """The one-minute row both the tiles and the live loop use.

        Taken from the site's clear-sky window of the next :data:`AHEAD_S`, simulated
        at once when ``minute`` leaves it (or the site's config changed): an hour of
        minutes costs what one minute costs (~45 ms of CPU, most of it holding the GIL),
        so a tick of the live loop is a lookup and a write, not a simulation. The rows
        equal one-minute runs to 1e-5 (pvlib's vectorised solar position).
        """
        win = self._ahead.get(info.site_id)
        if win is None or win[0] is not info.site or not win[1] <= minute < win[2]:
            series = simulate(info.site, pd.Timestamp(minute, unit="s", tz="UTC"),
                              pd.Timestamp(minute + AHEAD_S, unit="s", tz="UTC"),
                              step_s=60).series
            win = self._ahead[info.site_id] = (info.site, minute, minute + AHEAD_S, series)
        k = (minute - win[1]) // 60
        row = win[3].iloc[k:k + 1]
        sample = LiveSample(minute, {c: float(v) for c, v in row.iloc[0].items()})
        self.latest[info.site_id] = sample
        return sample, row

    def sample(self, site_id: str, now_s: float | None = None) -> LiveSample:
        """The twin at the current minute (computed, cached per minute; empty if not simulable)."""
        minute = int((time.time() if now_s is None else now_s) // 60 * 60)
        cached = self.latest.get(site_id)
        if cached is not None and cached.ts_s == minute:
            return cached
        if not self.simulable(site_id):
            return LiveSample(minute, {})
        return self._minute(self.registry.sites[site_id], minute)[0]

    def live_step(self, now_s: float | None = None) -> None:
        """One tick of the live loop: the current minute for every site, stored."""
        minute = int((time.time() if now_s is None else now_s) // 60 * 60)
        futures = []
        runs: list[tuple[str, int, int]] = []  # (site, local day start, the run's first minute)
        for site_id, info in self.registry.sites.items():
            if not self.simulable(site_id):
                continue
            sample, series = self._minute(info, minute)
            futures += [self.writer.submit(job) for job in jobs_from_series(info, series)]
            first, last = self._live_run.get(site_id, (minute, minute))
            d = dt.datetime.fromtimestamp(minute, info.zone).date()
            runs.append((site_id, int(dt.datetime(d.year, d.month, d.day,
                                                  tzinfo=info.zone).timestamp()),
                         first if last == minute - 60 else minute))
            if self.scene is not None and site_id == self.scene_site:
                try:
                    self.scene.update_live(
                        pd.Timestamp(minute, unit="s", tz="UTC"),
                        sample.values.get("tracker_power_w", 0.0),
                        sample.values.get("fixed_power_w", 0.0),
                    )
                except Exception:  # the scene must never stop the loop
                    logger.exception("3D scene update failed")
        for f in futures:
            f.result()
        self._live_run.update({site_id: (first, minute) for site_id, _, first in runs})
        if runs:
            self.writer.call(lambda conn: _extend_coverage(conn, runs, minute)).result()

    async def run_live(self, stop: asyncio.Event, interval_s: float) -> None:
        """Run the live loop on its own thread (``heliotwin-live``) until ``stop`` is set.

        Not an asyncio task stepping on AnyIO's pool: under load the event loop fires a
        timer only after the callbacks ready before it (every pending request), and the
        pool's threads are shared with the reads, so a tick was late by seconds before
        its step began. The thread waits on an event; each tick's lag is kept in
        :attr:`clock` (``GET /api/v1/live-twin``).
        """
        self.clock = clock = LiveClock(interval_s)
        halt = threading.Event()
        thread = threading.Thread(target=self._live_loop, args=(clock, halt),
                                  name="heliotwin-live", daemon=True)
        thread.start()
        try:
            await stop.wait()
        finally:
            halt.set()
            await anyio.to_thread.run_sync(thread.join, 30.0)

    def _live_loop(self, clock: LiveClock, halt: threading.Event) -> None:
        """:meth:`live_step` on the grid of ``clock.interval_s`` until ``halt`` is set."""
        due = time.time()
        while not halt.is_set():
            clock.begin(due)
            started = time.time()
            try:
                self.live_step(due)
            except Exception:
                logger.exception("live twin step failed")
            clock.end(due, time.time(), started)
            due = clock.next_due(time.time())
            halt.wait(max(0.0, due - time.time()))


def _extend_coverage(conn: Connection, runs: list[tuple[str, int, int]], minute: int) -> None:
    """Count the live loop's minutes in each ``(site, local day)``'s coverage: where it
    reaches the first minute of the loop's current run (every minute from there to
    ``minute`` stored), it now reaches past ``minute``. Without this every read of today
    (the tiles, Home Assistant's states every minute) simulated the minute the loop had
    just stored again: a fleet of 40 sites ran 40 ``simulate`` calls a minute."""
    for site_id, day, first in runs:
        conn.execute(update(TwinCoverage).where(
            TwinCoverage.site_id == site_id, TwinCoverage.day_start_s == day,
            TwinCoverage.covered_until_s >= first,
            TwinCoverage.covered_until_s < minute + 60).values(covered_until_s=minute + 60))


def _mark_coverage(conn: Connection, site_id: str, marks: list[tuple[int, int]]) -> None:
    ins = postgresql.insert if conn.dialect.name == "postgresql" else sqlite.insert
    for day, until in marks:
        stmt = ins(TwinCoverage).values(site_id=site_id, day_start_s=day, covered_until_s=until)
        conn.execute(stmt.on_conflict_do_update(
            index_elements=["site_id", "day_start_s"],
            set_={"covered_until_s": stmt.excluded.covered_until_s},
        ))
