"""The twin's expected I/V/P beside the measurements (source ``twin``).

Two ways the twin series gets into ``measurements``:

- the live loop (:meth:`TwinService.run_live`): every minute while the service
  runs, ``sim.twin.simulate(site, t, t + 60 s)`` for each site, written through
  the writer, and handed to the 3D scene (``update_live``);
- on demand (:meth:`TwinService.ensure`): before a query reads twin data of past
  days, the missing part of each local day up to now is simulated in one
  vectorised run and stored, so ``twin_wh`` exists for any day, not only for the
  minutes the service happened to be running. ``twin_coverage`` remembers how
  far each day is stored.

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
from dataclasses import dataclass
from typing import Any

import anyio
import numpy as np
import pandas as pd
from sqlalchemy import Connection, Engine, func, select
from sqlalchemy.dialects import postgresql, sqlite

from backend.measurements.writer import MeasurementJob, Writer
from backend.sites import Registry, SiteInfo
from backend.storage.tables import SOURCE_CODES, MeasurementRollup, TwinCoverage
from sim.twin import simulate

logger = logging.getLogger(__name__)
TWIN = SOURCE_CODES["twin"]


@dataclass
class LiveSample:
    """The twin at one minute: what the status tiles and the 3D scene show."""

    ts_s: int
    values: dict[str, float]


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

        Returns the number of readings simulated (0 when everything was stored).
        """
        if not self.simulable(site_id):
            return 0
        info = self.registry.sites[site_id]
        now_minute = int((time.time() if now_s is None else now_s) // 60 * 60)
        start_s = max(start_s, self._history_floor_s(info, now_minute))
        days = self._day_starts(info, start_s, min(end_s, now_minute + 1))
        if not days:
            return 0
        with self._lock(site_id):
            with self.engine.connect() as conn:
                covered = dict(conn.execute(
                    select(TwinCoverage.day_start_s, TwinCoverage.covered_until_s).where(
                        TwinCoverage.site_id == site_id,
                        TwinCoverage.day_start_s >= days[0],
                        TwinCoverage.day_start_s <= days[-1],
                    )).tuples().all())
            spans: list[tuple[int, int]] = []  # (from, to) of missing pieces
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
            total = 0
            for lo, hi in spans:
                total += self._simulate_and_store(info, lo, hi)
            if marks:
                self.writer.call(lambda conn: _mark_coverage(conn, site_id, marks)).result()
            return total

    def site_lock(self, site_id: str) -> threading.Lock:
        """The lock :meth:`ensure` holds while it simulates and stores a site's twin; a
        config change (``backend.sites.save_site``) holds it while it drops the cache."""
        return self._lock(site_id)

    def forget(self, site_id: str) -> None:
        """Drop the cached live sample of a site whose config changed."""
        self.latest.pop(site_id, None)

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

    def _history_floor_s(self, info: SiteInfo, now_s: int) -> int:
        """Earliest time reads fill with the twin: ``history_days`` before now, or the
        first measured reading of the site if that is older.

        Reads need no token, so without this floor anyone could make the server
        simulate and store twin series for any range of years.
        """
        floor = now_s - self.history_days * 86_400
        array_ids = [a.array_id for a in info.arrays.values()]
        if not array_ids:
            return floor
        with self.engine.connect() as conn:
            first = conn.execute(
                select(func.min(MeasurementRollup.first_ts_s)).where(
                    MeasurementRollup.array_id.in_(array_ids),
                    MeasurementRollup.source == SOURCE_CODES["measured"],
                )
            ).scalar()
        return floor if first is None else min(floor, int(first))

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
        """The one-minute simulation both the tiles and the live loop use (cached)."""
        result = simulate(info.site, pd.Timestamp(minute, unit="s", tz="UTC"),
                          pd.Timestamp(minute + 60, unit="s", tz="UTC"), step_s=60)
        sample = LiveSample(minute, {k: float(v) for k, v in result.series.iloc[0].items()})
        self.latest[info.site_id] = sample
        return sample, result.series

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
        for site_id, info in self.registry.sites.items():
            if not self.simulable(site_id):
                continue
            sample, series = self._minute(info, minute)
            futures += [self.writer.submit(job) for job in jobs_from_series(info, series)]
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

    async def run_live(self, stop: asyncio.Event, interval_s: float) -> None:
        """Call :meth:`live_step` every ``interval_s`` until ``stop`` is set."""
        while not stop.is_set():
            try:
                await anyio.to_thread.run_sync(self.live_step)
            except Exception:
                logger.exception("live twin step failed")
            delay = interval_s - (time.time() % interval_s) if interval_s >= 60 else interval_s
            try:
                await asyncio.wait_for(stop.wait(), timeout=delay)
            except TimeoutError:
                pass


def _mark_coverage(conn: Connection, site_id: str, marks: list[tuple[int, int]]) -> None:
    ins = postgresql.insert if conn.dialect.name == "postgresql" else sqlite.insert
    for day, until in marks:
        stmt = ins(TwinCoverage).values(site_id=site_id, day_start_s=day, covered_until_s=until)
        conn.execute(stmt.on_conflict_do_update(
            index_elements=["site_id", "day_start_s"],
            set_={"covered_until_s": stmt.excluded.covered_until_s},
        ))
