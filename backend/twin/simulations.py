"""Twin scenarios run from the API: in worker processes, a bounded queue, stored results.

A run is a :class:`backend.twin.scenario.Scenario` (site, range, step,
controller, disturbances, receiver) through ``run_scenario``. Every run —
synchronous or background — executes in its own worker process (forked from a
``forkserver`` that has the simulation modules imported, so a start costs
milliseconds), never in the web process's memory or under its GIL: a year at
one minute peaks at ≈ 400 MB and, with a controller stepped in Python, holds
the GIL for minutes; the process gives the memory back when it exits and
leaves the web process's threads their interpreter (``docs/architecture.md``,
"Threads and processes", has the measurement).

The worker touches no database. It sends its progress, then the summary and
the series packed as a compressed ``.npz`` (:func:`write_npz`: the bytes
themselves, not a pickle of them) back over a pipe; the web process stores
both through the one writer (``backend/measurements/writer.py``), in one
transaction that also marks the run done, so a run is ``done`` exactly when
its series is stored.

At most ``Settings.simulations.workers`` runs execute at once and
``Settings.simulations.queue`` wait; past that :meth:`SimulationRunner.submit`
raises :class:`backend.limits.Busy` (503 with ``Retry-After``, estimated from
the queued steps and the speed of the last finished run). Runs asked without a
token are marked ``anonymous``; only the newest
``Settings.simulations.anonymous_keep_runs`` of them stay stored.
"""

from __future__ import annotations

import io
import json
import logging
import multiprocessing
import tempfile
import threading
import time
import uuid
from concurrent.futures import Future, wait
from dataclasses import dataclass, field
from multiprocessing.connection import Connection as Pipe
from typing import IO, Any

import numpy as np
import pandas as pd
from sqlalchemy import Connection, Engine, insert, select, update

from backend.limits import Busy, prune_anonymous
from backend.measurements.writer import Writer
from backend.settings import Settings
from backend.sites import Registry
from backend.storage.tables import SimulationRun, SimulationSeries, utcnow
from backend.twin.scenario import Scenario, run_scenario
from sim.sites import Site

logger = logging.getLogger(__name__)

#: Worker processes fork from one server process that has these imported.
_MP = multiprocessing.get_context("forkserver")
_PRELOAD = ["backend.twin.simulations"]


class Cancelled(Exception):
    """A run gives up: it was cancelled, or the service is stopping."""


#: A cancelled run's ``error`` (its status is ``failed``).
CANCELLED = "cancelled"


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
    steps: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {"run_id": self.run_id, "site_id": self.site_id, "status": self.status,
                "progress": round(self.progress, 4), "summary": self.summary,
                "error": self.error, "params": self.params}


def write_npz(series: pd.DataFrame, file: IO[bytes]) -> None:
    """A run's series as a compressed ``.npz`` (``ts_s`` plus every column) into ``file``."""
    arrays = {c: series[c].to_numpy(np.float64) for c in series.columns}
    np.savez_compressed(file, ts_s=series.index.as_unit("s").asi8, **arrays)


def npz_to_series(blob: bytes) -> pd.DataFrame:
    """Inverse of :func:`write_npz`."""
    with np.load(io.BytesIO(blob)) as z:
        cols = {k: z[k] for k in z.files if k != "ts_s"}
        index = pd.to_datetime(z["ts_s"], unit="s", utc=True)
    return pd.DataFrame(cols, index=index)


def _work(pipe: Pipe, site: Site, params: Scenario, run_id: str) -> None:
    """The worker process: run, then send ``("done", summary)`` and the packed series
    (:meth:`Connection.send_bytes`), or ``("failed", message)``; it writes nothing itself."""
    last = [-1.0]

    def progress(fraction: float) -> None:
        if fraction - last[0] >= 0.005 or fraction >= 1.0:
            last[0] = fraction
            pipe.send(("progress", float(fraction)))

    try:
        result = run_scenario(site, params, progress=progress)
        summary = result.summary()
        summary["run_id"] = run_id
        # through a file, so the series is freed before its packed bytes are read back:
        # the peak stays the run's (≈ 400 MB for two years at one minute)
        with tempfile.TemporaryFile() as f:
            write_npz(result.series, f)
            del result
            f.seek(0)
            blob = f.read()
        pipe.send(("done", summary))
        pipe.send_bytes(blob)
    except Exception as exc:  # noqa: BLE001 - reported to the web process as the run's error
        pipe.send(("failed", str(exc) or type(exc).__name__))
    finally:
        pipe.close()


@dataclass
class _Result:
    """A finished run as its worker sent it: the summary and the packed series."""

    summary: dict[str, Any]
    npz: bytes


class SimulationRunner:
    """Runs scenarios in worker processes, a bounded number at a time, and remembers them."""

    def __init__(self, registry: Registry, engine: Engine, writer: Writer,
                 settings: Settings) -> None:
        self.registry = registry
        self.engine = engine
        self.writer = writer
        self.settings = settings
        self._runs: dict[str, RunState] = {}
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._queue: list[tuple[RunState, Scenario, bool, Future[dict[str, Any]]]] = []
        self._wake = threading.Condition(self._lock)
        self._active = 0
        self._steps_per_s = 300_000.0  # until a run is timed (2 years at 1 min: ≈ 3.5 s)
        self._threads: list[threading.Thread] = []
        self._futures: dict[str, Future[dict[str, Any]]] = {}  # runs queued or running
        self._cancel: set[str] = set()  # running runs asked to stop

    def _start_threads(self) -> None:
        if self._threads:
            return
        _MP.set_forkserver_preload(_PRELOAD)
        for i in range(self.settings.simulations.workers):
            t = threading.Thread(target=self._slot, name=f"heliotwin-sim-{i}", daemon=True)
            t.start()
            self._threads.append(t)

    def stop(self) -> None:
        """Fail queued runs, stop running ones (their worker processes are terminated)."""
        self._stopping.set()
        with self._lock:
            queued, self._queue = self._queue, []
            self._wake.notify_all()
        for state, _, _, fut in queued:
            self._fail(state, Cancelled("the service stopped before it ran"), fut)
        for t in self._threads:
            t.join(30)

    # ------------------------------------------------------------------ admission

    def submit(self, params: Scenario, anonymous: bool) -> tuple[RunState,
                                                                 Future[dict[str, Any]]]:
        """Queue a run, or raise :class:`Busy` (503) when the queue is full."""
        steps = (params.end - params.start).total_seconds() / params.step_s
        with self._lock:
            waiting = len(self._queue)
            if self._active + waiting >= self.settings.simulations.workers + \
                    self.settings.simulations.queue:
                ahead = sum(s.steps * (1 - s.progress) for s in self._runs.values()
                            if s.status in ("queued", "running"))
                raise Busy(503, f"busy: {self._active} simulations running and {waiting} "
                                f"waiting, the most this service queues "
                                "(HELIOTWIN_SIMULATION_WORKERS, HELIOTWIN_SIMULATION_QUEUE)",
                           ahead / self._steps_per_s / self.settings.simulations.workers)
        state = RunState(uuid.uuid4().hex, params.site_id, "queued",
                         params=json.loads(params.to_json()), steps=steps)
        self.writer.call(lambda conn: conn.execute(insert(SimulationRun).values(
            run_id=state.run_id, site_id=state.site_id, params_json=params.to_json(),
            status="queued", progress=0.0, created_at=utcnow(), anonymous=anonymous))).result()
        fut: Future[dict[str, Any]] = Future()
        with self._lock:
            self._runs[state.run_id] = state
            self._futures[state.run_id] = fut
            self._queue.append((state, params, anonymous, fut))
            self._start_threads()
            self._wake.notify()
        return state, fut

    def cancel(self, run_id: str, timeout_s: float = 30.0) -> RunState | None:
        """Cancel a queued or running run and return its state once it has ended: ``failed``
        with the error ``cancelled`` (a running run's worker is terminated), or as it was
        when it had already ended. None for an unknown run."""
        with self._lock:
            fut = self._futures.get(run_id)
            job = next((j for j in self._queue if j[0].run_id == run_id), None)
            if job is not None:
                self._queue.remove(job)
            elif fut is not None:
                self._cancel.add(run_id)
        if job is not None:
            self._fail(job[0], Cancelled(CANCELLED), job[3])
        elif fut is not None:
            wait([fut], timeout_s)
        return self.get(run_id)

    def run_sync(self, params: Scenario, anonymous: bool = False) -> dict[str, Any]:
        """Queue a run and wait for its summary (with ``run_id``)."""
        return self.submit(params, anonymous)[1].result()

    def start_background(self, params: Scenario, anonymous: bool = False) -> RunState:
        """Queue a run; poll :meth:`get` for its progress."""
        return self.submit(params, anonymous)[0]

    # ------------------------------------------------------------------ execution

    def _slot(self) -> None:
        while True:
            with self._lock:
                while not self._queue and not self._stopping.is_set():
                    self._wake.wait()
                if self._stopping.is_set():
                    return
                job = self._queue.pop(0)
                self._active += 1
            try:
                self._execute(*job)
            finally:
                with self._lock:
                    self._active -= 1

    def _execute(self, state: RunState, params: Scenario, anonymous: bool,
                 fut: Future[dict[str, Any]]) -> None:
        state.status = "running"
        t0 = time.monotonic()
        keep = self.settings.simulations.anonymous_keep_runs
        try:
            result = self._in_worker(state, params)
            elapsed = time.monotonic() - t0
            state.summary, state.progress = result.summary, 1.0

            def store(conn: Connection) -> int:
                """The series, the run done, the anonymous runs pruned: one transaction."""
                conn.execute(insert(SimulationSeries).values(run_id=state.run_id,
                                                             npz=result.npz))
                _finish(conn, state)
                return prune_anonymous(conn, SimulationRun, keep) if anonymous else 0

            pruned = self.writer.call(store).result()
        except Exception as exc:  # noqa: BLE001 - reported through the run's status
            self._fail(state, exc, fut)
            return
        if elapsed > 0.5:
            self._steps_per_s = state.steps / elapsed
        if pruned:
            self._forget_pruned()
        state.status = "done"
        self._ended(state)
        fut.set_result(state.summary)

    def _fail(self, state: RunState, exc: Exception, fut: Future[dict[str, Any]]) -> None:
        """A run ends without a result: ``failed`` with ``exc`` as its error, stored."""
        state.summary, state.status, state.error = None, "failed", str(exc)
        logger.warning("simulation %s failed: %s", state.run_id, exc)
        try:
            self.writer.call(lambda conn: _finish(conn, state)).result()
        except Exception:  # noqa: BLE001 - the writer has stopped: the row stays running
            logger.warning("simulation %s: its failure not stored", state.run_id)
        self._ended(state)
        fut.set_exception(exc)

    def _ended(self, state: RunState) -> None:
        with self._lock:
            self._futures.pop(state.run_id, None)
            self._cancel.discard(state.run_id)

    def _in_worker(self, state: RunState, params: Scenario) -> _Result:
        """Run ``params`` in a worker process; its progress into ``state``; its result.

        Polled every 0.2 s so a stopping service terminates the worker at once.
        """
        site = self.registry.sites[params.site_id].site
        ours, theirs = _MP.Pipe(duplex=False)
        proc = _MP.Process(target=_work, name=f"heliotwin-sim-{state.run_id[:8]}",
                           args=(theirs, site, params, state.run_id), daemon=True)
        proc.start()
        theirs.close()
        ended = "the worker process ended (exit code {}) without a result"
        try:
            while True:
                if self._stopping.is_set():
                    raise Cancelled("service stopping")
                if state.run_id in self._cancel:
                    raise Cancelled(CANCELLED)
                if not ours.poll(0.2):
                    if not proc.is_alive() and not ours.poll(0):
                        raise RuntimeError(ended.format(proc.exitcode))
                    continue
                try:
                    kind, value = ours.recv()
                    if kind == "progress":
                        state.progress = max(state.progress, min(float(value), 0.999))
                    elif kind == "done":
                        return _Result(dict(value), ours.recv_bytes())
                    else:
                        raise ValueError(str(value))
                except EOFError:
                    raise RuntimeError(ended.format(proc.exitcode)) from None
        finally:
            ours.close()
            if proc.is_alive():
                proc.terminate()
            proc.join(10)

    def _forget_pruned(self) -> None:
        with self.engine.connect() as conn:
            kept = set(conn.execute(select(SimulationRun.run_id)).scalars())
        with self._lock:
            for run_id in [r for r, s in self._runs.items()
                           if s.status == "done" and r not in kept]:
                del self._runs[run_id]

    # ------------------------------------------------------------------ reads

    def get(self, run_id: str) -> RunState | None:
        """A run's state: from memory, or as stored."""
        with self._lock:
            state = self._runs.get(run_id)
        if state is not None:
            return state
        with self.engine.connect() as conn:
            row = conn.execute(
                select(SimulationRun).where(SimulationRun.run_id == run_id)
            ).first()
        if row is None:
            return None
        return RunState(row.run_id, row.site_id, row.status, row.progress,
                        json.loads(row.summary_json) if row.summary_json else None,
                        row.error, json.loads(row.params_json))

    def series(self, run_id: str) -> pd.DataFrame | None:
        """A finished run's series (read from the database), or None."""
        state = self.get(run_id)
        if state is None or state.status != "done":
            return None
        with self.engine.connect() as conn:
            blob = conn.execute(
                select(SimulationSeries.npz).where(SimulationSeries.run_id == run_id)
            ).scalar_one_or_none()
        return None if blob is None else npz_to_series(blob)


def _finish(conn: Connection, state: RunState) -> None:
    done = state.summary is not None
    conn.execute(update(SimulationRun).where(SimulationRun.run_id == state.run_id).values(
        status="done" if done else "failed", progress=state.progress,
        summary_json=json.dumps(state.summary) if done else None,
        error=state.error, finished_at=utcnow()))
