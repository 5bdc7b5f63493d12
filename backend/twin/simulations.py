"""Twin scenarios run from the API: synchronous, or in the background with progress.

A run is a :class:`backend.twin.scenario.Scenario` (site, range, step,
controller, disturbances, receiver) through ``run_scenario``. Background runs
execute one at a time on a worker thread; their status and progress live in
memory while they run, and the finished run (its summary and its series as a
compressed ``.npz``) is stored in ``simulation_runs``/``simulation_series``, so
results survive a restart.
"""

from __future__ import annotations

import io
import json
import logging
import threading
import uuid
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import Connection, Engine, insert, select, update

from backend.measurements.writer import Writer
from backend.sites import Registry
from backend.storage.tables import SimulationRun, SimulationSeries, utcnow
from backend.twin.scenario import Scenario, run_scenario

logger = logging.getLogger(__name__)


class Cancelled(Exception):
    """The service is stopping; a background run gives up."""


@dataclass
class RunState:
    """What ``GET /api/v1/simulations/{run_id}`` answers."""

    run_id: str
    site_id: str
    status: str  # queued | running | done | failed
    progress: float = 0.0
    summary: dict[str, Any] | None = None
    error: str | None = None
    params: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"run_id": self.run_id, "site_id": self.site_id, "status": self.status,
                "progress": round(self.progress, 4), "summary": self.summary,
                "error": self.error, "params": self.params}


def series_to_npz(series: pd.DataFrame) -> bytes:
    """A run's series as compressed ``.npz`` bytes (``ts_s`` plus every column)."""
    buf = io.BytesIO()
    arrays = {c: series[c].to_numpy(np.float64) for c in series.columns}
    np.savez_compressed(buf, ts_s=series.index.as_unit("s").asi8, **arrays)
    return buf.getvalue()


def npz_to_series(blob: bytes) -> pd.DataFrame:
    """Inverse of :func:`series_to_npz`."""
    with np.load(io.BytesIO(blob)) as z:
        cols = {k: z[k] for k in z.files if k != "ts_s"}
        index = pd.to_datetime(z["ts_s"], unit="s", utc=True)
    return pd.DataFrame(cols, index=index)


class SimulationRunner:
    """Runs scenarios and remembers them."""

    def __init__(self, registry: Registry, engine: Engine, writer: Writer) -> None:
        self.registry = registry
        self.engine = engine
        self.writer = writer
        self._runs: dict[str, RunState] = {}
        self._series: dict[str, pd.DataFrame] = {}
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="heliotwin-sim")

    def stop(self) -> None:
        """Cancel queued and running background runs."""
        self._stopping.set()
        self._pool.shutdown(wait=True, cancel_futures=True)

    def _record(self, state: RunState, params: Scenario) -> None:
        self.writer.call(lambda conn: conn.execute(insert(SimulationRun).values(
            run_id=state.run_id, site_id=state.site_id, params_json=params.to_json(),
            status=state.status, progress=0.0, created_at=utcnow()))).result()

    def _execute(self, state: RunState, params: Scenario) -> dict[str, Any]:
        info = self.registry.sites[params.site_id]

        def progress(fraction: float) -> None:
            state.progress = float(fraction)
            if self._stopping.is_set():
                raise Cancelled("service stopping")

        state.status = "running"
        try:
            result = run_scenario(info.site, params, progress=progress)
        except Exception as exc:
            state.status, state.error = "failed", str(exc)
            self.writer.call(lambda conn: _finish(conn, state, None)).result()
            raise
        summary = result.summary()
        summary["run_id"] = state.run_id
        blob = series_to_npz(result.series)
        state.summary, state.progress = summary, 1.0
        self.writer.call(lambda conn: _finish(conn, state, blob)).result()
        state.status = "done"
        with self._lock:
            self._series[state.run_id] = result.series
            while len(self._series) > 4:
                self._series.pop(next(iter(self._series)))
        return summary

    def run_sync(self, params: Scenario) -> dict[str, Any]:
        """Run now and return the summary (with ``run_id``)."""
        state = RunState(uuid.uuid4().hex, params.site_id, "running",
                         params=json.loads(params.to_json()))
        self._record(state, params)
        with self._lock:
            self._runs[state.run_id] = state
        return self._execute(state, params)

    def start_background(self, params: Scenario) -> RunState:
        """Queue a run; poll :meth:`get` for its progress."""
        state = RunState(uuid.uuid4().hex, params.site_id, "queued",
                         params=json.loads(params.to_json()))
        self._record(state, params)
        with self._lock:
            self._runs[state.run_id] = state

        def job() -> None:
            try:
                self._execute(state, params)
            except Exception as exc:  # noqa: BLE001 - reported through the run's status
                logger.warning("simulation %s failed: %s", state.run_id, exc)

        self._pool.submit(job)
        return state

    def get(self, run_id: str) -> RunState | None:
        """A run's state: from memory, or as stored."""
        with self._lock:
            state = self._runs.get(run_id)
        if state is not None:
            return state
        with self.engine.connect() as conn:
            row = conn.execute(
                select(SimulationRun).where(SimulationRun.run_id == run_id)
            ).scalars().first()
        if row is None:
            return None
        return RunState(row.run_id, row.site_id, row.status, row.progress,
                        json.loads(row.summary_json) if row.summary_json else None,
                        row.error, json.loads(row.params_json))

    def series(self, run_id: str) -> pd.DataFrame | None:
        """A finished run's series, or None."""
        with self._lock:
            cached = self._series.get(run_id)
        if cached is not None:
            return cached
        with self.engine.connect() as conn:
            blob = conn.execute(
                select(SimulationSeries.npz).where(SimulationSeries.run_id == run_id)
            ).scalar_one_or_none()
        return None if blob is None else npz_to_series(blob)


def _finish(conn: Connection, state: RunState, blob: bytes | None) -> None:
    conn.execute(update(SimulationRun).where(SimulationRun.run_id == state.run_id).values(
        status="done" if blob is not None else "failed", progress=state.progress,
        summary_json=json.dumps(state.summary) if state.summary else None,
        error=state.error, finished_at=utcnow()))
    if blob is not None:
        conn.execute(insert(SimulationSeries).values(run_id=state.run_id, npz=blob))
