"""Plant-design sweeps as Dask tasks (``dask.distributed``): one task per (layout, GCR,
strategy) case over the whole range (issue 26).

The physics of a case is :func:`sim.plant.sweep.run_case`; this module only schedules:

- ``scheduler="tcp://HOST:PORT"``: the cases go to that running cluster (``Client``);
- no scheduler and more than one case: a ``LocalCluster`` of one single-threaded worker
  process per core (at most one per case), closed when the sweep ends;
- one case and no scheduler: in this process, no cluster.

Cases are submitted longest first (:func:`expected_cost`: strategy, then GCR), as Graham's
LPT rule schedules jobs on identical machines, so that no worker is left with a dense
case while the others idle.

The sky of the range (SPA sun positions and clear-sky or weather irradiance) depends on
the place and the range only, not on the case: each worker process computes it at its
first case and keeps it (:func:`sweep_task`'s per-process cache), so a sweep computes
it at most once per worker. Weather goes to the workers once (``Client.scatter``).
"""

from __future__ import annotations

import logging
import os
import re
import signal
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import pandas as pd

from sim.energy import check_step, step_problem
from sim.plant.layout import Plant
from sim.plant.sweep import SweepCase, SweepSpec, case_sky, run_case

log = logging.getLogger(__name__)

#: How long a client waits to reach the scheduler.
CONNECT_TIMEOUT = "5s"
#: How often a running sweep looks at its ``cancelled`` callback [s].
CANCEL_POLL_S = 0.2
#: A sweep whose scheduler has had no worker this long fails [s]: every worker killed, its
#: tasks waited for one to come back, and the sweep showed "running" for ever.
NO_WORKERS_S = 60.0
#: How often a sweep waiting for results asks its scheduler for the workers [s].
WORKERS_LOOK_S = 5.0
#: Most workers of a LocalCluster per core (each a process: 1,000 on 2 cores hung).
MAX_WORKERS_PER_CORE = 4


class SweepSetupError(ValueError):
    """A scheduler address Dask cannot read, or a worker count out of bounds; the message
    starts with the parameter's name (``scheduler:``, ``workers:``)."""

#: This process's sky of the last sweep range it ran: (SweepSpec.sky_key(), sky); one range
#: (a Dask worker's, reused by the cases it runs); a one-case sweep run in the caller's
#: process (the service's) drops it when done.
_SKY_CACHE: dict[tuple[Any, ...], dict[str, Any]] = {}
_SKY_LOCK = threading.Lock()


def _sky(spec: SweepSpec, weather: pd.DataFrame | None) -> tuple[dict[str, Any], bool]:
    """The range's sky from this process's cache, or computed (and kept); True if computed."""
    key = spec.sky_key()
    with _SKY_LOCK:
        sky = _SKY_CACHE.get(key)
        if sky is not None:
            return sky, False
        sky = case_sky(spec, weather)
        _SKY_CACHE.clear()                      # one range at a time: bounded memory
        _SKY_CACHE[key] = sky
        return sky, True


def sweep_task(spec: SweepSpec, case: SweepCase, weather: pd.DataFrame | None = None
               ) -> dict[str, Any]:
    """One Dask task: the case's row, with ``_sky_computed`` (this task computed the sky)
    and ``_pid`` (the worker process) for the sweep's account of the work."""
    sky, computed = _sky(spec, weather)
    row = run_case(spec, case, sky, weather)
    row["_sky_computed"] = computed
    row["_pid"] = os.getpid()
    return row


#: Order of the strategies' cost per step (the sky scan tries ~650 orientations, the
#: backtracking fan ~40).
_STRATEGY_COST_RANK = {"sun": 0, "backtrack": 1, "sky_scan": 2}


def expected_cost(case: SweepCase) -> tuple[int, float]:
    """A key that orders cases by their expected cost: the strategy first, then the GCR (a
    denser field has more pairs within shading distance at more steps)."""
    return _STRATEGY_COST_RANK.get(case.strategy, 0), case.gcr


def _import_case_modules() -> None:
    """Import what a case needs (run on every worker before the cases, so that a
    worker's first case is not also its imports: the sweep's ``compute_s`` is the cases')."""
    import pvlib.irradiance  # noqa: F401
    import pvlib.pvsystem  # noqa: F401
    import pvlib.temperature  # noqa: F401

    import sim.plant.sweep  # noqa: F401


#: What a worker that cannot import the cases' code needs.
_INSTALL_ON_WORKERS = ("install heliotwin in the workers' environment, as the client's "
                       "(docs/plants.md, § Layout and spacing sweeps)")


def _short_error(exc: BaseException) -> str:
    """``ModuleNotFoundError: No module named 'backend'`` of a worker's failure (Dask wraps
    one in ``Exception('ModuleNotFoundError(...)')`` when the function does not unpickle)."""
    text = str(exc)
    return text if type(exc) is Exception and text else f"{type(exc).__name__}: {text}"


def _finish(rows: list[dict[str, Any]], engine: str, extra: dict[str, Any],
            started: float, compute_s: float) -> dict[str, Any]:
    order = {id(r): k for k, r in enumerate(rows)}
    rows = sorted(rows, key=lambda r: (r["layout"], r["strategy"], r["gcr"], order[id(r)]))
    computed = sum(bool(r.pop("_sky_computed")) for r in rows)
    pids = {r.pop("_pid") for r in rows}
    return {"engine": engine, **extra, "worker_processes": len(pids),
            "sky_computations": computed, "cases": len(rows),
            "wall_s": round(time.perf_counter() - started, 3),
            "compute_s": round(compute_s, 3), "rows": rows}


def local_cluster(n_workers: int) -> Any:
    """A ``LocalCluster`` of ``n_workers`` single-threaded worker processes for one sweep.

    Dask's nannies start workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which also fixes
    glibc's mmap threshold at 128 KiB: every array of a case is then mapped and unmapped
    afresh, and the bench's 12 cases took 11.5 s instead of 7.1 s (one process, each
    setting). The cluster lives for one sweep, so its workers keep glibc's defaults. (A
    cluster of your own: set ``distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_``
    to null in its Dask config for the same speed.)

    Nor does the cluster keep Dask's monitors at their dashboard rates: the statistical
    profiler (each worker's stack every 10 ms, under the GIL), the event-loop tick (20 ms)
    and the system monitor (500 ms) feed only the Dask dashboard, which this cluster does
    not serve, and the memory limits are checked every second instead of every 100 ms. Idle,
    the default monitors cost 5 % of a core in this process and 3 % in each worker, about
    12 % of one of this machine's two cores that a 2-worker sweep needs (1.4 % with these
    settings; 10 s idle, measured once)."""
    import dask
    from distributed import LocalCluster

    # its worker processes ignore SIGINT (a disposition SIG_IGN outlives their exec; a
    # handler does not): a Ctrl-C at the terminal, sent to the whole process group, stops the
    # sweep in this process (the CLI's cancel) instead of killing each worker with a
    # KeyboardInterrupt traceback. Only the main thread may set a handler (not the service's).
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        return _local_cluster(dask, LocalCluster, n_workers)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _local_cluster(dask: Any, LocalCluster: Any, n_workers: int) -> Any:  # noqa: N803
    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                          "distributed.worker.profile.enabled": False,
                          "distributed.admin.tick.interval": "1s",
                          "distributed.admin.system-monitor.interval": "5s",
                          "distributed.worker.memory.monitor-interval": "1s"}):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                            dashboard_address=None, silence_logs=logging.WARNING)


#: Said with every "cannot reach" of a scheduler address: the port users mistake for it.
_SCHEDULER_PORT_HINT = ("give the scheduler's own port (8786 by default), not its "
                        "dashboard's (8787) or a web service's")


def reach_scheduler(address: str, cancelled: Callable[[], bool] | None = None) -> None:
    """Check that a Dask scheduler answers at ``address`` within :data:`CONNECT_TIMEOUT`,
    else :class:`SweepSetupError` (``scheduler: …``) saying what answered.

    ``distributed``'s ``connect`` bounds the TCP connection by its timeout but not the
    handshake after it (``comm.read()``): a port that accepts and never answers (the Dask
    dashboard's, ``python -m http.server``) left ``Client(address, timeout=…)`` waiting
    for ever, and one that answers HTTP had its reply read as a frame length (a numpy
    ``MemoryError`` of exbibytes). Here the connection and its handshake run under one
    deadline, ``cancelled`` polled every :data:`CANCEL_POLL_S` (:class:`SweepCancelled`)."""
    import asyncio

    from dask.utils import parse_timedelta
    from distributed.comm import connect, parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, loc = parse_address(address, strict=True)
        get_backend(scheme)
        port = parse_host_port(loc)[1] if scheme in ("tcp", "tls") else None
    except (ValueError, TypeError) as exc:
        raise SweepSetupError(f"scheduler: {address!r} is no Dask scheduler address "
                              f"(tcp://HOST:PORT): {exc}") from None
    if port is not None and not 1 <= port <= 65535:
        raise SweepSetupError(f"scheduler: {address!r}: port {port} is out of range "
                              "(1 to 65535)")
    timeout_s = float(parse_timedelta(CONNECT_TIMEOUT, default="seconds") or 5.0)

    async def probe() -> None:
        # the slack: connect's own "Timed out" (nothing listens) comes first
        task = asyncio.ensure_future(asyncio.wait_for(connect(address, timeout=timeout_s),
                                                      timeout_s + 1.0))
        try:
            while not task.done():
                await asyncio.wait({task}, timeout=CANCEL_POLL_S)
                if not task.done() and cancelled is not None and cancelled():
                    raise SweepCancelled("cancelled while connecting to the scheduler")
            comm = task.result()
        finally:
            if not task.done():
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)
        await comm.close()

    why: str | None = None
    try:
        # a loop of its own on a thread of its own: the caller's thread may run an event
        # loop already (asyncio.run refuses to start there: a RuntimeError that read as
        # "not a Dask scheduler" on every address, under a test run's browser)
        with ThreadPoolExecutor(1, thread_name_prefix="heliotwin-dask-probe") as probe_thread:
            probe_thread.submit(asyncio.run, probe()).result()
    except SweepCancelled:
        raise
    except TimeoutError:                # connected, and no handshake came back (before OSError:
        # TimeoutError is one)
        why = (f"it accepts connections but gave no Dask handshake within {timeout_s:g} s, "
               "so it is not a Dask scheduler")
    except OSError as exc:              # nothing listens (distributed's "Timed out …")
        why = str(exc) or type(exc).__name__
    except Exception as exc:            # an answer Dask cannot read (HTTP's: MemoryError)
        why = f"it answered, but not as a Dask scheduler ({type(exc).__name__})"
    if why is not None:
        raise SweepSetupError(f"scheduler: cannot reach {address!r}: {why}; "
                              f"{_SCHEDULER_PORT_HINT}")


def runs_in_process(cases: Sequence[SweepCase], scheduler: str | None) -> bool:
    """Whether :func:`run_sweep` runs its one case in the caller's process (no Dask, and no
    ``cancelled`` polled: it cannot be stopped between cases)."""
    return scheduler is None and len(cases) == 1


def run_sweep(spec: SweepSpec, cases: Sequence[SweepCase], weather: pd.DataFrame | None = None,
              scheduler: str | None = None, n_workers: int | None = None,
              progress: Callable[[int, int], None] | None = None,
              cancelled: Callable[[], bool] | None = None) -> dict[str, Any]:
    """Run every case; rows sorted by layout, strategy and GCR.

    Parameters
    ----------
    spec, cases
        What the cases share, and the cases (see :mod:`sim.plant.sweep`).
    weather : pandas.DataFrame, optional
        Covering the range (clear sky when None); ``spec.weather_token`` must name it.
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a running Dask scheduler (``HOST:PORT`` means tcp, as to
        Dask's ``Client``).
    n_workers : int, optional
        Workers of the ``LocalCluster`` (default: the cores, at most one per case).
    progress : callable, optional
        Called with (cases done, cases) as each case finishes.
    cancelled : callable, optional
        Polled every :data:`CANCEL_POLL_S` while cases run; when it returns True the
        remaining tasks are cancelled and
        :class:`SweepCancelled` is raised.

    Returns
    -------
    dict
        ``engine`` (``"dask"`` or ``"in-process"``), ``scheduler``, ``workers``,
        ``worker_processes`` (that ran a case), ``sky_computations`` (sky computed that
        many times: at most once per worker), ``cases``, ``wall_s`` (all of it, a
        LocalCluster's start included), ``compute_s`` (from the first task submitted to
        the last result), ``rows``.
    """
    started = time.perf_counter()
    if not cases:
        raise ValueError("a sweep needs at least one case")
    if runs_in_process(cases, scheduler):
        row = sweep_task(spec, cases[0], weather)
        with _SKY_LOCK:  # in the caller's process (the service): not kept after the sweep
            _SKY_CACHE.clear()
        if progress is not None:
            progress(1, 1)
        return _finish([row], "in-process", {"scheduler": None, "workers": 1}, started,
                       time.perf_counter() - started)
    from concurrent.futures import CancelledError

    from distributed import Client, wait

    cores = os.cpu_count() or 1
    if n_workers is not None and not 1 <= n_workers <= MAX_WORKERS_PER_CORE * cores:
        raise SweepSetupError(f"workers: {n_workers} is not in "
                              f"[1, {MAX_WORKERS_PER_CORE * cores}] ({MAX_WORKERS_PER_CORE} "
                              f"processes a core, {cores} cores)")
    cluster = None
    if scheduler is None:
        cluster = local_cluster(n_workers or min(cores, len(cases)))
    elif "://" not in scheduler:  # HOST:PORT is tcp to Dask's own Client (a tester's finding)
        scheduler = f"tcp://{scheduler}"
    if scheduler is not None:   # before the Client, whose handshake has no time bound
        reach_scheduler(scheduler, cancelled)
    try:
        try:
            client_cm = Client(cluster if cluster is not None else scheduler,
                               timeout=CONNECT_TIMEOUT)
        except ValueError as exc:  # distributed's own words: "unknown address scheme" …
            raise SweepSetupError(f"scheduler: {scheduler!r} is no Dask scheduler address "
                                  f"(tcp://HOST:PORT): {exc}") from None
        with client_cm as client:
            workers = len(client.scheduler_info(n_workers=-1)["workers"])
            address = client.scheduler.address
            log.info("plant sweep: %d cases on %s (%d workers)", len(cases), address, workers)
            # each worker's imports, before the clock starts; and a worker that cannot import
            # them (no heliotwin in its environment) refused by name before any case fails
            imported = client.run(_import_case_modules, on_error="return")
            lacking = {w: e for w, e in imported.items() if isinstance(e, BaseException)}
            if lacking:
                raise SweepSetupError(
                    f"scheduler: {len(lacking)} of {len(imported)} workers of {address} cannot "
                    "import heliotwin's code ("
                    + "; ".join(f"{w}: {_short_error(e)}" for w, e in sorted(lacking.items()))
                    + f"): {_INSTALL_ON_WORKERS}")
            submitted = time.perf_counter()
            w = client.scatter(weather, broadcast=True) if weather is not None else None
            # longest cases first (Graham's LPT rule): the workers finish together instead
            # of one waiting on a dense case submitted last
            futures = [client.submit(sweep_task, spec, c, w, pure=False, priority=-rank)
                       for rank, c in enumerate(sorted(cases, key=expected_cost, reverse=True))]
            rows: list[dict[str, Any]] = []
            pending = set(futures)
            no_workers_since: float | None = None
            next_look = time.monotonic() + WORKERS_LOOK_S
            while pending:
                # woken by the next result (not by a poll's sleep: the last case's result is
                # taken when it lands), or after CANCEL_POLL_S to look at `cancelled`
                try:
                    try:
                        finished = wait(list(pending), timeout=CANCEL_POLL_S,
                                        return_when="FIRST_COMPLETED").done
                    except TimeoutError:
                        finished = set()
                    for fut in finished:
                        pending.discard(fut)
                        try:
                            rows.append(fut.result())
                        except ModuleNotFoundError as exc:
                            if (exc.name or "").split(".")[0] not in ("backend", "sim",
                                                                      "vision"):
                                raise  # a case's own failure, not a missing install
                            client.cancel(futures)  # a worker that joined without heliotwin
                            raise SweepFailed(f"a worker of {address} cannot import "
                                              f"heliotwin's code ({_short_error(exc)}): "
                                              f"{_INSTALL_ON_WORKERS}") from None
                        if progress is not None:
                            progress(len(rows), len(cases))
                except (CancelledError, OSError) as exc:
                    # the client lost its scheduler: Dask cancels every future ("scheduler-
                    # connection-lost"); the cases done are kept, as a cancelled sweep's
                    if client.status == "running" and "connection-lost" not in str(exc):
                        raise
                    done = _finish(rows, "dask", {"scheduler": None if cluster is not None
                                                  else address, "workers": workers},
                                   started, time.perf_counter() - submitted)
                    raise SweepFailed(f"the scheduler at {address} was lost after {len(rows)} "
                                      f"of {len(cases)} cases", done) from None
                if pending and cancelled is not None and cancelled():
                    client.cancel(futures)
                    done = _finish(rows, "dask", {"scheduler": None if cluster is not None
                                                  else address, "workers": workers},
                                   started, time.perf_counter() - submitted)
                    raise SweepCancelled(f"cancelled after {len(rows)} of {len(cases)} cases",
                                         done)
                if pending and not finished and time.monotonic() >= next_look:
                    next_look = time.monotonic() + WORKERS_LOOK_S
                    if client.nthreads():
                        no_workers_since = None
                    elif no_workers_since is None:
                        no_workers_since = time.monotonic()
                    elif time.monotonic() - no_workers_since > NO_WORKERS_S:
                        client.cancel(futures)
                        raise SweepFailed(
                            f"the Dask scheduler at {address} has had no worker for "
                            f"{NO_WORKERS_S:.0f} s ({len(rows)} of {len(cases)} cases done): "
                            "start workers (dask worker tcp://…) and run the sweep again")
            compute_s = time.perf_counter() - submitted
    finally:
        if cluster is not None:
            cluster.close()
    return _finish(rows, "dask", {"scheduler": None if cluster is not None else address,
                                  "workers": workers}, started, compute_s)


class SweepFailed(RuntimeError):
    """A sweep its cluster could not finish (the scheduler lost, no worker left, a worker
    without heliotwin): a message for the user, no traceback; ``result`` holds the cases
    finished before it (as :func:`run_sweep` returns them) when there were any to keep."""

    def __init__(self, message: str, result: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.result = result


class SweepCancelled(RuntimeError):
    """A sweep stopped by its ``cancelled`` callback; ``result`` holds the cases finished
    before it (as :func:`run_sweep` returns them), not thrown away."""

    def __init__(self, message: str, result: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.result = result


#: The parameters of a sweep by their request keys (``SweepCreate``'s fields), which a
#: :class:`SweepInputError` names: the CLI maps each to its flag
#: (``backend.cli.plant.SWEEP_FLAGS``), the HTTP route answers it as it is.
SWEEP_FIELDS = ("layouts", "gcr", "strategies", "collector_m", "collector_polygon_m",
                "latitude_deg", "longitude_deg", "altitude_m", "plant_id", "field_size",
                "aspect_ratio", "offset", "rotation_deg", "slope_azimuth_deg", "slope_tilt_deg",
                "start", "end", "step_s", "timezone")
_REF = re.compile(r"\{(\w+)\}")


class SweepInputError(ValueError):
    """A bad sweep parameter: ``field`` (a request key of :data:`SWEEP_FIELDS`) and what is
    wrong. ``problem`` may name other parameters as ``{key}``; :meth:`message` writes every
    name as the caller spells it (the CLI its flags, the API its JSON keys), so each rule
    has one message."""

    def __init__(self, field: str, problem: str) -> None:
        self.field, self.problem = field, problem
        super().__init__(self.message())

    def message(self, name: Callable[[str], str] = str) -> str:
        """``field: problem`` with the parameters' names given by ``name`` (a request key →
        the caller's name for it; the keys themselves by default)."""
        def ref(m: re.Match[str]) -> str:
            return name(m[1]) if m[1] in SWEEP_FIELDS else m[0]

        return f"{name(self.field)}: {_REF.sub(ref, self.problem)}"


def sweep_zone(plant: Plant | None, timezone: str | None) -> str:
    """The zone of a sweep's local days: the plant's, else ``timezone`` (an IANA name:
    a bare latitude/longitude has no zone of its own), else UTC. Its dates (``start``,
    ``end``) and the shade chart's day are read in it. :class:`SweepInputError` names
    ``timezone``."""
    from sim.site_config import check_iana_zone

    if plant is not None:
        if timezone is not None:
            raise SweepInputError("timezone", "the plant ({plant_id}) has its own zone "
                                  f"({plant.timezone}): give it or {{timezone}}, not both")
        return plant.timezone
    if timezone is None:
        return "UTC"
    try:
        return check_iana_zone(timezone)
    except ValueError as exc:
        raise SweepInputError("timezone", str(exc)) from None


#: Largest number of cases × steps of one sweep (a bound on its cost).
MAX_CASE_STEPS = 50_000_000
#: Most layouts, GCRs and strategies one sweep may list (``SweepCreate``'s list bounds too),
#: and so most cases: a bound on the Dask tasks it schedules, whatever the step.
MAX_LAYOUTS, MAX_GCRS, MAX_STRATEGIES = 5, 40, 3
MAX_CASES = MAX_LAYOUTS * MAX_GCRS * MAX_STRATEGIES


def case_steps(spec: SweepSpec, n_cases: int) -> float:
    """What a sweep of ``n_cases`` cases of ``spec`` costs, in rectangle case-steps: cases ×
    steps, a polygon collector's steps weighing :func:`backend.plants.cost_factor` (its
    shade costs that much more). The one measure of :data:`MAX_CASE_STEPS`, the anonymous
    bound and the anonymous allowance spent."""
    from backend.plants import cost_factor

    steps = (spec.end - spec.start).total_seconds() / spec.step_s
    return n_cases * steps * cost_factor(spec.collector)


def parse_gcr(text: str) -> list[float]:
    """``"0.15,0.25"`` or a range ``"START:STOP:STEP"`` (STOP included) → GCRs."""
    try:
        if ":" in text:
            lo, hi, step = (float(x) for x in text.split(":"))
            if not (step > 0 and hi >= lo and np.isfinite([lo, hi, step]).all()):
                raise SweepInputError("gcr", f"range {text!r} needs finite numbers, STOP ≥ START "
                                      "and STEP > 0")
            n = int(np.floor((hi - lo) / step + 1e-9)) + 1
            if n > MAX_GCRS:                   # before making the list: 0.1:0.3:1e-12
                raise SweepInputError("gcr", f"range {text!r} holds {n:,} values, more than "
                                      f"{MAX_GCRS}: use a larger STEP")
            values = [round(lo + k * step, 10) for k in range(n)]
        else:
            values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError as exc:
        if isinstance(exc, SweepInputError):
            raise
        raise SweepInputError("gcr", f"expected numbers like 0.15,0.25 or 0.1:0.5:0.05, "
                              f"got {text!r}") from None
    if not values:
        raise SweepInputError("gcr", "no value given")
    return values


#: A collector's WIDTHxHEIGHT [m] (``collector_m``) and a regular field's ROWSxCOLUMNS
#: (``field_size``), spaces around the x allowed: the one rule of the CLI's --collector-m and
#: --field (:func:`parse_size`) and of the HTTP body's pattern ("8 x 4" was refused by the
#: body's pattern and run by the CLI, which split on "x" and let float() read the rest).
COLLECTOR_SIZE_PATTERN = r"^\s*\d+(\.\d+)?\s*[xX]\s*\d+(\.\d+)?\s*$"
FIELD_SIZE_PATTERN = r"^\s*\d{1,2}\s*[xX]\s*\d{1,2}\s*$"


def parse_size(text: str, field: str) -> tuple[float, float]:
    """``"12x5"`` → (12.0, 5.0): a collector's WIDTHxHEIGHT, a field's ROWSxCOLUMNS
    (``field`` ``"field_size"``), by :data:`COLLECTOR_SIZE_PATTERN` / :data:`FIELD_SIZE_PATTERN`."""
    is_field = field == "field_size"
    if not re.fullmatch(FIELD_SIZE_PATTERN if is_field else COLLECTOR_SIZE_PATTERN, text):
        shape = ("ROWSxCOLUMNS like 5x5" if is_field
                 else "WIDTHxHEIGHT in metres like 12x5")
        raise SweepInputError(field, f"expected {shape}, got {text!r}")
    a, b = (float(x) for x in re.split("[xX]", text))
    if not (a > 0 and b > 0 and np.isfinite(a) and np.isfinite(b)):
        raise SweepInputError(field, f"both sizes must be positive, got {text!r}")
    return a, b


def parse_polygon(text: str, field: str) -> list[tuple[float, float]]:
    """``"u1,v1;u2,v2;…"`` [m], or the path of a file holding that text or a JSON list of
    ``[u, v]`` pairs → the vertices (checked later by
    :func:`sim.plant.layout.check_outline`)."""
    import json
    from pathlib import Path

    body = text
    if ";" not in text and Path(text).is_file():
        body = Path(text).read_text(encoding="utf-8")
    try:
        if body.lstrip().startswith("["):
            pairs = [(float(u), float(v)) for u, v in json.loads(body)]
        else:
            pairs = [(float(a), float(b)) for a, b in
                     (p.split(",") for p in body.replace("\n", ";").split(";") if p.strip())]
    except (ValueError, TypeError):
        raise SweepInputError(field, "expected vertices u,v [m] about the pivot separated by "
                              f"';' (e.g. -6,-2.5;6,-2.5;0,2.5) or such a file, got "
                              f"{text[:80]!r}") from None
    return pairs


#: What a sweep of regular fields takes when a parameter is not given (``None``); a plant's
#: sweep takes none of them (its layout, field, ground and altitude are the plant's).
REGULAR_DEFAULTS: dict[str, Any] = {"layouts": ("square",), "field_size": (5, 5),
                                    "altitude_m": 0.0, "slope_azimuth_deg": 0.0,
                                    "slope_tilt_deg": 0.0}


def prepare_sweep(*, gcr: Sequence[float], strategies: Sequence[str],
                  start: pd.Timestamp, end: pd.Timestamp, step_s: float,
                  layouts: Sequence[str] | None = None,
                  latitude_deg: float | None = None, longitude_deg: float | None = None,
                  altitude_m: float | None = None,
                  collector_m: tuple[float, float] | None = None,
                  collector_polygon_m: Sequence[Sequence[float]] | None = None,
                  plant: Plant | None = None, field_size: tuple[int, int] | None = None,
                  custom: tuple[float | None, float | None, float | None] | None = None,
                  slope_azimuth_deg: float | None = None, slope_tilt_deg: float | None = None,
                  timezone: str | None = None, weather_token: str = "",
                  max_case_steps: float = MAX_CASE_STEPS, bound_note: str = ""
                  ) -> tuple[SweepSpec, list[SweepCase]]:
    """Check a sweep's parameters and build its spec and cases (every layout × GCR ×
    strategy; an existing ``plant`` gives one layout, itself scaled: the place, collector,
    layouts, field, ground, altitude and layout custom's numbers are then the plant's and
    refused when given; ``None`` elsewhere is :data:`REGULAR_DEFAULTS`). The collector is
    ``collector_m`` (a rectangle) or ``collector_polygon_m`` ((u, v) vertices [m] about
    the pivot), wired like Peñarroya's. Every case's field is built once here, so an
    infeasible GCR is refused before any task runs. ``custom``: layout custom's (aspect
    ratio, offset, rotation [°]), all three or none; ``timezone``: :func:`sweep_zone`;
    ``max_case_steps``: the caller's bound on :func:`case_steps` (an anonymous caller's is
    lower), ``bound_note`` said after it (" without a write token").
    :class:`SweepInputError` names the parameter (its request key, :data:`SWEEP_FIELDS`)."""
    from backend.plants import cost_factor
    from sim.paths import package_dir
    from sim.plant.fields import LAYOUT_TYPES, collector_from_outline, collector_from_size
    from sim.plant.layout import load_plant
    from sim.plant.strategies import STRATEGIES, strategies_for
    from sim.plant.sweep import PLANT_LAYOUT, case_plant
    from sim.site_config import ALTITUDE_MAX_M, ALTITUDE_MIN_M

    bad = [s for s in strategies if s not in STRATEGIES]
    if bad or not strategies:
        raise SweepInputError("strategies", f"must be one or more of {', '.join(STRATEGIES)}, "
                              f"got {','.join(strategies) or 'nothing'}")
    _listed_once("strategies", strategies)
    if not end > start:
        raise SweepInputError("end", "must be after start (end is exclusive)")
    try:
        check_step(start, end, float(step_s))  # the energy rule's bounds (at most an hour)
    except ValueError as exc:
        raise SweepInputError("step_s", step_problem(exc)) from None
    given: dict[str, Any] = {
        "latitude_deg": latitude_deg, "longitude_deg": longitude_deg,
        "collector_m": collector_m, "collector_polygon_m": collector_polygon_m,
        "layouts": layouts, "field_size": field_size, "altitude_m": altitude_m,
        "slope_azimuth_deg": slope_azimuth_deg, "slope_tilt_deg": slope_tilt_deg,
        **dict(zip(("aspect_ratio", "offset", "rotation_deg"), custom or (None,) * 3,
                   strict=True))}
    if plant is not None:
        named = [k for k, v in given.items() if v is not None]
        if named:  # the plant's were used and these echoed back as if they had been
            raise SweepInputError(named[0], "the plant ({plant_id}) sets the place, the "
                                  "collector, the layout, the field and its ground: give "
                                  f"{{plant_id}} or {{{named[0]}}}, not both")
    else:
        layouts, field_size, altitude_m, slope_azimuth_deg, slope_tilt_deg = (
            REGULAR_DEFAULTS[k] if given[k] is None else given[k] for k in REGULAR_DEFAULTS)
    if len(gcr) > MAX_GCRS:
        raise SweepInputError("gcr", f"{len(gcr):,} values, more than {MAX_GCRS}")
    if any(not (0 < g < 1) for g in gcr):
        raise SweepInputError("gcr", f"every GCR must be in (0, 1), got {list(gcr)}: a fraction "
                              "of the ground, 0.3 not 30 (%)")
    _listed_once("gcr", [float(g) for g in gcr])
    rows, columns = field_size or REGULAR_DEFAULTS["field_size"]
    if not (1 <= rows <= 15 and 1 <= columns <= 15):
        raise SweepInputError("field_size", f"rows and columns must be 1 to 15, "
                              f"got {rows}x{columns}")
    layout_custom: tuple[float, float, float] | None = None
    if plant is not None:
        names = [PLANT_LAYOUT]
        collector = plant.collector
        lat, lon, alt = plant.latitude, plant.longitude, plant.altitude
    else:
        if latitude_deg is None or longitude_deg is None:
            raise SweepInputError("latitude_deg" if latitude_deg is None else "longitude_deg",
                                  "give {latitude_deg} and {longitude_deg} (or {plant_id})")
        if not (-90 <= latitude_deg <= 90):
            raise SweepInputError("latitude_deg", f"must be in [-90, 90], got {latitude_deg}")
        if not (-180 <= longitude_deg <= 180):
            raise SweepInputError("longitude_deg", f"must be in [-180, 180], got {longitude_deg}")
        if altitude_m is not None and not (ALTITUDE_MIN_M <= altitude_m <= ALTITUDE_MAX_M):
            raise SweepInputError("altitude_m", f"must be in [{ALTITUDE_MIN_M:g}, "  # 99,999 m
                                  f"{ALTITUDE_MAX_M:g}] m, got {altitude_m:g}")  # gave < 0 kWh
        if (collector_m is None) == (collector_polygon_m is None):
            raise SweepInputError("collector_m", "give the collector size, e.g. 12x5, or "
                                  "its polygon ({collector_polygon_m}), one of the two")
        template = load_plant("penarroya", package_dir("sim", "data", "plants")).collector
        if collector_m is not None:
            try:
                collector = collector_from_size(collector_m[0], collector_m[1], template)
            except ValueError as exc:
                raise SweepInputError("collector_m", str(exc)) from None
        else:
            try:
                collector = collector_from_outline(collector_polygon_m, template)
            except ValueError as exc:
                raise SweepInputError("collector_polygon_m", str(exc)) from None
        names = list(layouts or ())
        known = [*LAYOUT_TYPES, "custom"]
        if not names or any(n not in known for n in names):
            raise SweepInputError("layouts", f"must be one or more of {', '.join(known)}, "
                                  f"got {','.join(names) or 'nothing'}")
        _listed_once("layouts", names)
        layout_custom = _custom_layout(names, custom)
        lat, lon, alt = latitude_deg, longitude_deg, float(altitude_m or 0.0)
    tz = sweep_zone(plant, timezone)
    spec = SweepSpec(latitude=lat, longitude=lon, altitude=alt, start=start, end=end,
                     step_s=float(step_s), collector=collector, rows=rows, columns=columns,
                     slope_azimuth_deg=float(slope_azimuth_deg or 0.0),
                     slope_tilt_deg=float(slope_tilt_deg or 0.0),
                     custom=layout_custom, plant=plant, timezone=tz, weather_token=weather_token,
                     **({"albedo": plant.albedo, "temp_air": plant.temp_air,
                         "wind_speed": plant.wind_speed} if plant is not None else {}))
    if any(s not in strategies_for(collector) for s in strategies):
        raise SweepInputError("strategies", "a polygon collector takes strategy sun only (the "
                              "backtrack and sky_scan shade-free tests are the rectangle's)")
    n_cases = len(names) * len(gcr) * len(strategies)
    if n_cases > MAX_CASES:
        raise SweepInputError("gcr", f"{len(names)} layouts × {len(gcr)} GCRs × "
                              f"{len(strategies)} strategies is {n_cases:,} cases, more than "
                              f"{MAX_CASES}: fewer GCRs, layouts or strategies")
    cases = [SweepCase(n, float(g), s) for n in names for g in gcr for s in strategies]
    bound = min(max_case_steps, MAX_CASE_STEPS)
    if case_steps(spec, len(cases)) > bound:
        steps = (end - start).total_seconds() / step_s
        factor = cost_factor(collector)
        weight = f" (a polygon collector's steps count {factor:g}×)" if factor > 1 else ""
        raise SweepInputError("step_s", f"{len(cases)} cases × {steps:.0f} steps{weight} is "
                              f"more than {bound:,.0f}{bound_note}: use a larger {{step_s}}, "
                              "a shorter range or fewer cases")
    for case in {SweepCase(c.layout, c.gcr, "sun") for c in cases}:
        try:
            case_plant(spec, case)
        except ValueError as exc:
            field = _case_field(str(exc), case.layout, plant is not None)
            what = case.layout if plant is None else f"plant {plant.plant_id}"
            raise SweepInputError(field, f"{what} at GCR {case.gcr:g}: {exc}") from None
    return spec, cases


def _listed_once(field: str, values: Sequence[Any]) -> None:
    """:class:`SweepInputError` naming ``field`` when a value is listed twice: its cases would
    run twice, their rows alike (``params`` echoing it once); 10,000 times ``square`` was
    refused as too many cases naming the GCRs. So no list passes its bound (at most 5
    layouts and 3 strategies exist)."""
    seen: set[Any] = set()
    for v in values:
        if v in seen:
            raise SweepInputError(field, f"{v!s} is listed twice: list each once")
        seen.add(v)


def _custom_layout(layouts: Sequence[str],
                   custom: tuple[float | None, float | None, float | None] | None
                   ) -> tuple[float, float, float] | None:
    """Layout custom's (aspect ratio, offset, rotation [°]) when ``layouts`` holds it: all
    three, else :class:`SweepInputError` naming the first missing; given without layout
    custom, refused naming the first given (they apply to no other layout)."""
    names = ("aspect_ratio", "offset", "rotation_deg")
    values = custom or (None, None, None)
    if "custom" not in layouts:
        given = [k for k, v in zip(names, values, strict=True) if v is not None]
        if given:
            raise SweepInputError(given[0], "{aspect_ratio}, {offset} and {rotation_deg} "
                                  "apply only to layout custom, which {layouts} ("
                                  f"{','.join(layouts)}) does not hold")
        return None
    a, o, r = values
    if a is None and o is None and r is None:
        raise SweepInputError("layouts", "layout custom needs {aspect_ratio}, {offset} "
                              "and {rotation_deg}")
    if a is None or o is None or r is None:
        missing = [k for k, v in zip(names, values, strict=True) if v is None]
        raise SweepInputError(missing[0], "layout custom takes {aspect_ratio}, {offset} "
                              "and {rotation_deg} together: give all three")
    return (a, o, r)


def sweep_params(spec: SweepSpec, cases: Sequence[SweepCase], given: dict[str, Any]
                 ) -> dict[str, Any]:
    """A sweep's parameters by request key as it runs them: ``given`` (the request) with the
    values used — the place, zone and step; a regular field's layouts, field size, ground
    and altitude with their defaults; for a plant's sweep its place and altitude, and null
    for what it does not take (layouts, field, slope)."""
    regular = spec.plant is None
    return {**given, "latitude_deg": spec.latitude, "longitude_deg": spec.longitude,
            "altitude_m": spec.altitude, "timezone": spec.timezone, "step_s": spec.step_s,
            "gcr": sorted({c.gcr for c in cases}),
            "strategies": list(dict.fromkeys(c.strategy for c in cases)),
            "layouts": list(dict.fromkeys(c.layout for c in cases)) if regular else None,
            "field_size": f"{spec.rows}x{spec.columns}" if regular else None,
            "slope_azimuth_deg": spec.slope_azimuth_deg if regular else None,
            "slope_tilt_deg": spec.slope_tilt_deg if regular else None}


def _case_field(problem: str, layout: str, from_plant: bool) -> str:
    """The parameter a case's field refuses (:mod:`sim.plant.fields` names it first: ``gcr
    0.6 outside …``, ``offset must be …``; layout custom's own three only for that layout),
    else the one the problem mentions (gcr), else the plant (too few trackers to scale it)
    or the layouts."""
    first = problem.split(" ", 1)[0]
    if first in SWEEP_FIELDS and (layout == "custom" or first not in
                                  ("aspect_ratio", "offset", "rotation_deg")):
        return first
    if "gcr" in problem:
        return "gcr"
    return "plant_id" if from_plant else "layouts"


__all__ = ["MAX_CASES", "MAX_CASE_STEPS", "MAX_GCRS", "MAX_LAYOUTS", "MAX_STRATEGIES",
           "SWEEP_FIELDS", "SweepCancelled", "SweepFailed", "SweepInputError", "case_steps",
           "expected_cost",
           "parse_gcr",
           "parse_polygon", "parse_size", "prepare_sweep", "run_sweep", "sweep_params",
           "sweep_task"]
