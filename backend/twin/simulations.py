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
raises :class:`backend.limits.Busy` (503 with ``Retry-After``: when the next
queued run is expected to start).

The queue is priced in worker seconds (:mod:`backend.twin.cost`: the
controller's loop and camera frames, not the step count) and fair between
callers (a client is a token's site, or the address of a caller without one):
a free worker takes the queued run with the least *client work*: the expected
time its caller's running runs still need, plus its caller's runs queued before
it, plus its own, minus the time it has waited. A caller's second long run thus
waits behind others' short ones, and no run waits forever. The same order gives
each queued run its place and expected wait (:meth:`SimulationRunner.get`).

Without a token a run is refused (:class:`RunTooCostly`, 422) when its estimate
exceeds ``anonymous_run_max_s`` and stopped when it runs longer than that; a
client's estimates (trued up to the time taken) in any hour are bounded by
``anonymous_hour_max_s`` (:class:`backend.limits.WindowBudget`, 429). Runs
asked without a token are marked ``anonymous``; only the newest
``Settings.simulations.anonymous_keep_runs`` of them stay stored.
"""

from __future__ import annotations

import dataclasses
import io
import json
import logging
import multiprocessing
import re
import tempfile
import threading
import time
import uuid
import weakref
from concurrent.futures import Future, wait
from dataclasses import dataclass, field
from multiprocessing.connection import Connection as Pipe
from typing import IO, Any

import numpy as np
import pandas as pd
from sqlalchemy import Connection, Engine, func, insert, select, update

from backend.limits import Busy, Charge, WindowBudget, prune_anonymous
from backend.measurements.writer import Writer
from backend.settings import Settings
from backend.sites import Registry
from backend.storage.tables import SimulationRun, SimulationSeries, utcnow
from backend.twin.cost import CostModel, table_cost_s
from backend.twin.scenario import Scenario, run_scenario
from sim.sites import Site

logger = logging.getLogger(__name__)

#: Worker processes fork from one server process that has these imported.
_MP = multiprocessing.get_context("forkserver")
_PRELOAD = ["backend.twin.simulations"]
#: The forkserver's first start with its imports (:data:`_PRELOAD`) [s], which the service's
#: first run waits for: 1.5 s measured on the development machine (later starts: 12 ms).
#: A 4-day run at 1 min (0.5 s of the cost table) said "about 1 s" and took 3.9 s, and the
#: learned factor took that start for the run's own time (:meth:`CostModel.learn` now gets
#: the worker's time alone, :attr:`_Result.worker_s`).
WORKER_FIRST_START_S = 1.5


class Cancelled(Exception):
    """A run gives up: it was cancelled, or the service is stopping."""


class RunTooCostly(ValueError):
    """A run asked without a token is expected to take longer than its callers may."""


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
    estimated_run_s: float | None = None
    started_at: str | None = None
    finished_at: str | None = None
    started_mono: float | None = None  # time.monotonic() at the start, while in memory
    queue_position: int | None = None  # set by SimulationRunner.get while queued
    estimated_wait_s: float | None = None  # likewise

    def to_dict(self) -> dict[str, Any]:
        return {"run_id": self.run_id, "site_id": self.site_id, "status": self.status,
                "progress": round(self.progress, 4), "summary": self.summary,
                "error": self.error, "params": self.params,
                "estimated_run_s": _round(self.estimated_run_s),
                "estimated_wait_s": _round(self.estimated_wait_s),
                "queue_position": self.queue_position,
                "started_at": self.started_at, "finished_at": self.finished_at}

    def remaining_s(self, now: float) -> float:
        """Expected worker time left of a running run [s] (0 when it runs past its estimate)."""
        if self.started_mono is None or self.estimated_run_s is None:
            return self.estimated_run_s or 0.0
        return max(0.0, self.estimated_run_s - (now - self.started_mono))


def _round(x: float | None) -> float | None:
    return None if x is None else round(x, 1)


def _iso_now() -> str:
    return utcnow().isoformat()


class SharedBlob:
    """A run's packed series bytes, shared by the readers holding this object (weakly
    remembered by :meth:`SimulationRunner.series_blob`: gone when the last reader is)."""

    __slots__ = ("data", "__weakref__")

    def __init__(self, data: bytes) -> None:
        self.data = data


@dataclass
class _Job:
    """A queued run: its state, scenario, caller and what it was charged."""

    state: RunState
    params: Scenario
    client: str
    anonymous: bool
    fut: Future[dict[str, Any]]
    cost_s: float
    table_s: float  # the cost table's price, before the learned factor (CostModel.learn)
    queued_mono: float
    charge: Charge | None = None


@dataclass
class Estimate:
    """What a run would cost and when it would start, asked before it is queued."""

    estimated_run_s: float
    estimated_wait_s: float
    runs_ahead: int
    anonymous_run_max_s: float | None
    anonymous_hour_left_s: float | None
    reason: str | None  # why it would be refused now; None: it would be accepted


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


#: Ended runs a :class:`SimulationRunner` remembers in memory (the newest; a bound on it).
KEEP_ENDED = 100


def insert_series(conn: Connection, run_id: str, npz: bytes) -> None:
    """Store a run's packed series. SQLite: a ``zeroblob`` row written through the blob
    interface (``sqlite3.Connection.blobopen``) — bound as a parameter, the prepared
    statement kept its own copy of the bytes (43 MB for a year) until the next run's
    series replaced it (issue 23 item 5)."""
    if conn.dialect.name != "sqlite":
        conn.execute(insert(SimulationSeries).values(run_id=run_id, npz=npz))
        return
    rowid = conn.execute(insert(SimulationSeries).values(
        run_id=run_id, npz=func.zeroblob(len(npz)))).lastrowid
    dbapi: Any = conn.connection.driver_connection
    with dbapi.blobopen(SimulationSeries.__tablename__, "npz", rowid) as blob:
        blob.write(npz)


def shrink_page_cache(conn: Connection) -> None:
    """SQLite: free the connection's unused cached pages (``PRAGMA shrink_memory``).

    Each connection caches up to 64 MiB of pages (``backend.storage.engine``); after a
    run's packed series (43 MB for a year at one minute) was written or read, they held
    its pages until the connection read something else: 40-90 MB of an idle server's
    memory per connection that touched one (issue 23 item 5)."""
    if conn.dialect.name == "sqlite":
        conn.exec_driver_sql("PRAGMA shrink_memory")


def _work(pipe: Pipe, site: Site, params: Scenario, run_id: str) -> None:
    """The worker process: run, then send ``("done", summary)`` and the packed series
    (:meth:`Connection.send_bytes`), or ``("failed", message)``; it writes nothing itself."""
    last = [-1.0]

    def progress(fraction: float) -> None:
        if fraction - last[0] >= 0.005 or fraction >= 1.0:
            last[0] = fraction
            pipe.send(("progress", float(fraction)))

    try:
        pipe.send(("started", 0.0))
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
    #: the worker's own time [s], from its start of the run to its result (what the cost
    #: table prices: not the forkserver's first start, nor storing the series)
    worker_s: float = 0.0


class SimulationRunner:
    """Runs scenarios in worker processes, a bounded number at a time, fairly between
    callers, and remembers them."""

    def __init__(self, registry: Registry, engine: Engine, writer: Writer,
                 settings: Settings) -> None:
        self.registry = registry
        self.engine = engine
        self.writer = writer
        self.settings = settings
        self.costs = CostModel()
        #: a worker has started in this runner: the forkserver is up, and a start costs
        #: milliseconds, not WORKER_FIRST_START_S
        self._worker_started = False
        s = settings.simulations
        self.anonymous_hours = WindowBudget(
            s.anonymous_hour_max_s, 3600.0, "s of compute (simulation worker time and plant "
            "computations, backend/api/routes/plants.py)",
            "HELIOTWIN_SIMULATION_ANONYMOUS_HOUR_MAX_S")
        self._runs: dict[str, RunState] = {}
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._queue: list[_Job] = []
        self._running: dict[str, _Job] = {}
        self._wake = threading.Condition(self._lock)
        self._threads: list[threading.Thread] = []
        self._futures: dict[str, Future[dict[str, Any]]] = {}  # runs queued or running
        self._cancel: set[str] = set()  # running runs asked to stop
        self._blobs: weakref.WeakValueDictionary[str, SharedBlob] = (
            weakref.WeakValueDictionary())  # packed series being read
        self._blob_load = threading.Lock()

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
        for job in queued:
            self._fail(job, Cancelled("the service stopped before it ran"))
        for t in self._threads:
            t.join(30)

    # ------------------------------------------------------------------ the order

    def _order(self, extra: _Job | None = None) -> list[tuple[_Job, float]]:
        """The queued runs (and ``extra``) in the order free workers take them, each with
        its expected wait [s]; call with the lock held.

        The key of a run is its caller's *client work* (module docstring): the caller's
        running runs' expected remaining time, its queued runs before this one and this
        one, minus the time this one has waited. The waits come from handing the runs in
        that order to the worker that frees first.
        """
        now = time.monotonic()
        jobs = [*self._queue, *([extra] if extra is not None else [])]
        ahead: dict[str, float] = {}
        for job in self._running.values():
            ahead[job.client] = ahead.get(job.client, 0.0) + job.state.remaining_s(now)
        keyed = []
        for i, job in enumerate(jobs):
            ahead[job.client] = ahead.get(job.client, 0.0) + job.cost_s
            keyed.append((ahead[job.client] - (now - job.queued_mono), i, job))
        keyed.sort(key=lambda k: k[:2])
        free = sorted(j.state.remaining_s(now) for j in self._running.values())
        free += [0.0] * (self.settings.simulations.workers - len(free))
        out = []
        for _, _, job in keyed:
            start = free.pop(0) if free else 0.0
            out.append((job, start))
            free.append(start + job.cost_s)
            free.sort()
        return out

    # ------------------------------------------------------------------ admission

    def _check_cost(self, cost_s: float, anonymous: bool) -> None:
        limit = self.settings.simulations.anonymous_run_max_s
        if anonymous and cost_s > limit:
            raise RunTooCostly(
                f"end, step_s, controller: this run is expected to take {_duration(cost_s)} "
                f"of the simulation worker; a run asked without a write token may take at "
                f"most {_duration(limit)} (HELIOTWIN_SIMULATION_ANONYMOUS_RUN_MAX_S): use a "
                "larger step_s, a shorter range or a cheaper controller, or send "
                "'Authorization: Bearer <token>'")

    def _table_s(self, params: Scenario) -> float:
        """The cost table's price of ``params`` at its site (:func:`table_cost_s`) [s]."""
        return table_cost_s(params, self.registry.sites[params.site_id].site)

    def _place_refused(self, client: str, anonymous: bool) -> Busy | None:
        """Why the queue has no place for ``client`` now (call under the lock), else None:
        full (503); without a token, the address's one run already queued or running
        (429). Three 49-s runs of one address without a token had filled the worker and
        the queue, and the site's operator was refused for 150 s (a tester's finding)."""
        s = self.settings.simulations
        jobs = [*self._running.values(), *self._queue]
        order = self._order()
        retry_s = order[0][1] if order else 1.0
        if len(jobs) >= s.workers + s.queue:
            return Busy(503, f"busy: {len(self._running)} simulations running and "
                             f"{len(self._queue)} waiting, the most this service queues "
                             "(HELIOTWIN_SIMULATION_WORKERS, HELIOTWIN_SIMULATION_QUEUE)",
                        retry_s)
        if anonymous and any(j.anonymous and j.client == client for j in jobs):
            return Busy(429, "rate limit: without a write token an address may have one "
                             "simulation queued or running at a time: wait for it, or send "
                             "'Authorization: Bearer <token>'", retry_s)
        return None

    def first_start_s(self) -> float:
        """What a run waits before it starts when no worker has started yet: the forkserver's
        own start with its imports (:data:`WORKER_FIRST_START_S`), else 0."""
        return 0.0 if self._worker_started else WORKER_FIRST_START_S

    def estimate(self, params: Scenario, client: str, anonymous: bool) -> Estimate:
        """What ``params`` would cost and when it would start if queued now (nothing is
        queued or charged)."""
        table_s = self._table_s(params)
        cost = self.costs.estimate_s(table_s, params.controller)
        shown = cost + self.first_start_s()
        phantom = _Job(RunState("", params.site_id, "queued"), params, client, anonymous,
                       Future(), cost, table_s, time.monotonic())
        with self._lock:
            order = self._order(phantom)
            running = len(self._running)
            refused = self._place_refused(client, anonymous)
        place = next(i for i, (job, _) in enumerate(order) if job is phantom)
        s = self.settings.simulations
        left = (max(0.0, s.anonymous_hour_max_s - self.anonymous_hours.used(client))
                if anonymous else None)
        reason = None
        try:
            self._check_cost(cost, anonymous)
        except RunTooCostly as exc:
            reason = str(exc)
        if reason is None and left is not None and min(cost, s.anonymous_hour_max_s) > left:
            reason = (f"rate limit: {_duration(left)} of the {_duration(s.anonymous_hour_max_s)}"
                      " of worker time an address may ask without a token in an hour are left "
                      "(HELIOTWIN_SIMULATION_ANONYMOUS_HOUR_MAX_S)")
        if reason is None and refused is not None:
            reason = refused.message
        return Estimate(shown, order[place][1], place + running,
                        s.anonymous_run_max_s if anonymous else None, left, reason)

    def submit(self, params: Scenario, anonymous: bool, client: str = "?"
               ) -> tuple[RunState, Future[dict[str, Any]]]:
        """Queue a run for ``client``; raise :class:`RunTooCostly` (422) when a run without
        a token is expected to take longer than it may, :class:`Busy` when the queue is
        full (503) or the caller's hour is spent (429)."""
        table_s = self._table_s(params)
        cost = self.costs.estimate_s(table_s, params.controller)
        self._check_cost(cost, anonymous)
        with self._lock:
            if (refused := self._place_refused(client, anonymous)) is not None:
                raise refused
        charge = self.anonymous_hours.take(client, cost) if anonymous else None
        state = RunState(uuid.uuid4().hex, params.site_id, "queued",
                         params=json.loads(params.to_json()),
                         estimated_run_s=cost + self.first_start_s())
        try:
            self.writer.call(lambda conn: conn.execute(insert(SimulationRun).values(
                run_id=state.run_id, site_id=state.site_id, params_json=params.to_json(),
                status="queued", progress=0.0, created_at=utcnow(),
                anonymous=anonymous))).result()
        except Exception:
            if charge is not None:
                self.anonymous_hours.settle(charge, 0.0)
            raise
        fut: Future[dict[str, Any]] = Future()
        job = _Job(state, params, client, anonymous, fut, cost, table_s, time.monotonic(),
                   charge)
        with self._lock:
            self._runs[state.run_id] = state
            self._futures[state.run_id] = fut
            self._queue.append(job)
            self._start_threads()
            self._wake.notify()
        return self.get(state.run_id) or state, fut

    def cancel(self, run_id: str, timeout_s: float = 30.0) -> RunState | None:
        """Cancel a queued or running run and return its state once it has ended: ``failed``
        with the error ``cancelled`` (a running run's worker is terminated), or as it was
        when it had already ended. None for an unknown run."""
        with self._lock:
            fut = self._futures.get(run_id)
            job = next((j for j in self._queue if j.state.run_id == run_id), None)
            if job is not None:
                self._queue.remove(job)
            elif fut is not None:
                self._cancel.add(run_id)
        if job is not None:
            self._fail(job, Cancelled(CANCELLED))
        elif fut is not None:
            wait([fut], timeout_s)
        return self.get(run_id)

    def run_sync(self, params: Scenario, anonymous: bool = False, client: str = "?"
                 ) -> dict[str, Any]:
        """Queue a run and wait for its summary (with ``run_id``)."""
        return self.submit(params, anonymous, client)[1].result()

    def start_background(self, params: Scenario, anonymous: bool = False,
                         client: str = "?") -> RunState:
        """Queue a run; poll :meth:`get` for its progress."""
        return self.submit(params, anonymous, client)[0]

    # ------------------------------------------------------------------ execution

    def _slot(self) -> None:
        while True:
            with self._lock:
                while not self._queue and not self._stopping.is_set():
                    self._wake.wait()
                if self._stopping.is_set():
                    return
                job = self._order()[0][0]
                self._queue.remove(job)
                self._running[job.state.run_id] = job
                job.state.status = "running"
                job.state.started_mono = time.monotonic()
                job.state.started_at = _iso_now()
            try:
                self._execute(job)
            except Exception as exc:  # noqa: BLE001 - a bug past _execute's own handling:
                # the run still ends (its caller would wait forever) and the slot lives on
                logger.exception("simulation %s: the slot failed", job.state.run_id)
                if not job.fut.done():
                    self._fail(job, exc)

    def _execute(self, job: _Job) -> None:
        state = job.state
        t0 = time.monotonic()
        keep = self.settings.simulations.anonymous_keep_runs
        try:
            result = self._in_worker(job)
            elapsed, worker_s = time.monotonic() - t0, result.worker_s
            state.summary, state.progress = result.summary, 1.0
            state.finished_at = _iso_now()
            # the packed series (43 MB for a year at one minute) is handed over in a
            # list emptied once stored: the writer thread keeps its last job until the
            # next one comes, and with it everything the job's function refers to
            npz = [result.npz]
            del result

            def store(conn: Connection) -> int:
                """The series, the run done, the anonymous runs pruned: one transaction."""
                insert_series(conn, state.run_id, npz.pop())
                _finish(conn, state)
                return prune_anonymous(conn, SimulationRun, keep) if job.anonymous else 0

            pruned = self.writer.call(store).result()
            self.writer.call(shrink_page_cache)  # the series' pages, now committed
        except Exception as exc:  # noqa: BLE001 - reported through the run's status
            self._fail(job, exc, time.monotonic() - t0)
            return
        try:  # bookkeeping: the run is stored and done whatever happens here
            self.costs.learn(job.params.controller, job.table_s, worker_s)
            if job.charge is not None:
                self.anonymous_hours.settle(job.charge, elapsed)
            if pruned:
                self._forget_pruned()
        except Exception:  # noqa: BLE001
            logger.exception("simulation %s: its bookkeeping failed", state.run_id)
        self._ended(state, "done")
        job.fut.set_result(state.summary)

    def _fail(self, job: _Job, exc: Exception, elapsed_s: float = 0.0) -> None:
        """A run ends without a result: ``failed`` with ``exc`` as its error, stored; an
        anonymous caller is charged the time it ran (nothing when it never started)."""
        state = job.state
        if job.charge is not None:
            self.anonymous_hours.settle(job.charge, elapsed_s)
        state.summary, state.error = None, str(exc)
        state.finished_at = _iso_now()
        logger.warning("simulation %s failed: %s", state.run_id, exc)
        try:
            self.writer.call(lambda conn: _finish(conn, state)).result()
        except Exception:  # noqa: BLE001 - the writer has stopped: the row stays running
            logger.warning("simulation %s: its failure not stored", state.run_id)
        self._ended(state, "failed")
        job.fut.set_exception(exc)

    def _ended(self, state: RunState, status: str) -> None:
        """The run leaves the worker with ``status`` (done | failed): one step under the
        lock, so no caller sees it ended while its place is still held (a client that sends
        its next run on the answer must not find this one still running)."""
        with self._lock:
            state.status = status
            self._running.pop(state.run_id, None)
            self._futures.pop(state.run_id, None)
            self._cancel.discard(state.run_id)
            # the newest KEEP_ENDED ended runs stay in memory; older ones are read back
            # from the database (:meth:`get`): runs with a token were kept forever
            ended = [r for r, st in self._runs.items() if st.status in ("done", "failed")]
            for run_id in ended[:max(0, len(ended) - KEEP_ENDED)]:
                del self._runs[run_id]

    def _in_worker(self, job: _Job) -> _Result:
        """Run the job in a worker process; its progress into its state; its result.

        Polled every 0.2 s so a stopping service, a cancel or an anonymous run past
        ``anonymous_run_max_s`` terminates the worker at once.
        """
        state, params = job.state, job.params
        limit_s = self.settings.simulations.anonymous_run_max_s if job.anonymous else None
        site = self.registry.sites[params.site_id].site
        ours, theirs = _MP.Pipe(duplex=False)
        proc = _MP.Process(target=_work, name=f"heliotwin-sim-{state.run_id[:8]}",
                           args=(theirs, site, params, state.run_id), daemon=True)
        proc.start()
        theirs.close()
        t0 = None  # when the worker began the run (not the forkserver's first start)
        ended = "the worker process ended (exit code {}) without a result"
        try:
            while True:
                if self._stopping.is_set():
                    raise Cancelled("service stopping")
                if state.run_id in self._cancel:
                    raise Cancelled(CANCELLED)
                if limit_s is not None and t0 is not None and time.monotonic() - t0 > limit_s:
                    raise Cancelled(
                        f"stopped after {_duration(limit_s)}, the most a run asked without a "
                        "write token may take (HELIOTWIN_SIMULATION_ANONYMOUS_RUN_MAX_S); it "
                        f"was expected to take {_duration(state.estimated_run_s or 0.0)}")
                if not ours.poll(0.2):
                    if not proc.is_alive() and not ours.poll(0):
                        raise RuntimeError(ended.format(proc.exitcode))
                    continue
                try:
                    kind, value = ours.recv()
                    if kind == "started":
                        t0 = time.monotonic()
                        self._worker_started = True
                    elif kind == "progress":
                        state.progress = max(state.progress, min(float(value), 0.999))
                    elif kind == "done":
                        return _Result(dict(value), ours.recv_bytes(),
                                       time.monotonic() - (t0 if t0 is not None else 0.0))
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
        """A run's state: from memory (a queued run with its place and expected wait, a
        running one with its expected time left), or as stored; None for an unknown run,
        or an id no run has (not a uuid4's 32 hex digits: PostgreSQL refused a NUL in the
        query with a 500)."""
        if not _RUN_ID.fullmatch(run_id):
            return None
        with self._lock:
            state = self._runs.get(run_id)
            if state is not None:
                state = dataclasses.replace(state)
                if state.status == "queued":
                    for i, (job, wait_s) in enumerate(self._order()):
                        if job.state.run_id == run_id:
                            state.queue_position, state.estimated_wait_s = i, wait_s
                elif state.status == "running":
                    state.estimated_wait_s = 0.0
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
                        row.error, json.loads(row.params_json),
                        finished_at=row.finished_at.isoformat() if row.finished_at else None)

    def series_blob(self, run_id: str) -> SharedBlob | None:
        """A finished run's packed series (:func:`write_npz`), or None; readers of one run
        at the same time share one copy (a year's is 43 MB), held while any holds it."""
        state = self.get(run_id)
        if state is None or state.status != "done":
            return None
        with self._blob_load:  # one load at a time: readers arriving together share it
            with self._lock:
                held = self._blobs.get(run_id)
            if held is not None:
                return held
            with self.engine.connect() as conn:
                data = conn.execute(
                    select(SimulationSeries.npz).where(SimulationSeries.run_id == run_id)
                ).scalar_one_or_none()
                shrink_page_cache(conn)
            if data is None:
                return None
            held = SharedBlob(bytes(data))
            with self._lock:
                self._blobs[run_id] = held
            return held

    def series(self, run_id: str) -> pd.DataFrame | None:
        """A finished run's series (read from the database), or None."""
        blob = self.series_blob(run_id)
        return None if blob is None else npz_to_series(blob.data)


#: What a run id is (``uuid.uuid4().hex``, :meth:`SimulationRunner.submit`).
_RUN_ID = re.compile(r"[0-9a-f]{32}")


def _duration(seconds: float) -> str:
    """A worker time for people: "45 s", "12 min", "1 h 13 min"."""
    if seconds < 90:
        return f"{max(seconds, 1):.0f} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 60 else f"{minutes // 60} h {minutes % 60} min"


def _finish(conn: Connection, state: RunState) -> None:
    done = state.summary is not None
    conn.execute(update(SimulationRun).where(SimulationRun.run_id == state.run_id).values(
        status="done" if done else "failed", progress=state.progress,
        summary_json=json.dumps(state.summary) if done else None,
        error=state.error, finished_at=utcnow()))
