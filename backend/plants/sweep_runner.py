"""Sweeps asked over HTTP (``POST /api/v1/plants/sweeps``): queued, one at a time, polled.

A sweep is submitted with its checked spec and cases (:func:`backend.plants.sweep.prepare_sweep`)
and answered at once with an id; it runs when the one before it has ended, as an asyncio
task of the web loop that hands :func:`backend.plants.sweep.run_sweep` to AnyIO's worker
threads (the loop stays free; no thread of this module's own). The cases run on the Dask
scheduler of ``HELIOTWIN_PLANTS_DASK_SCHEDULER``, or on a LocalCluster made for the
sweep. Progress is the cases done over the cases. Only the newest :data:`KEEP` sweeps are
kept, in memory (a sweep is minutes of work, re-run when the service restarts).
"""

from __future__ import annotations

import asyncio
import logging
import secrets
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import anyio

from backend.limits import Busy
from backend.plants.sweep import SweepCancelled, SweepFailed, SweepSetupError, run_sweep
from sim.plant.sweep import SweepCase, SweepSpec

log = logging.getLogger(__name__)

#: The setting of the service's Dask scheduler, named by a sweep that cannot reach it.
SCHEDULER_SETTING = "HELIOTWIN_PLANTS_DASK_SCHEDULER"
#: Sweeps kept for polling (the oldest ended ones are dropped first).
KEEP = 50


@dataclass
class SweepState:
    """One sweep's status, for ``GET /api/v1/plants/sweeps/{sweep_id}``."""

    sweep_id: str
    params: dict[str, Any]
    total: int
    status: str = "queued"              # queued → running → done | failed
    done: int = 0
    result: dict[str, Any] | None = None
    error: str | None = None
    cancel: bool = field(default=False, repr=False)
    spec: SweepSpec | None = field(default=None, repr=False)   # for a case's day of shade
    cases: tuple[SweepCase, ...] = field(default=(), repr=False)  # … of the cases it runs

    def to_dict(self) -> dict[str, Any]:
        """The JSON of the state (``SweepRunRead``)."""
        return {"sweep_id": self.sweep_id, "status": self.status,
                "progress": self.done / self.total if self.total else 0.0,
                "cases_done": self.done, "cases": self.total, "params": self.params,
                "result": self.result, "error": self.error}


class SweepRunner:
    """The service's sweeps: at most one running and ``queue`` waiting."""

    def __init__(self, scheduler: str | None, queue: int) -> None:
        self.scheduler = scheduler
        self.queue = queue
        self._states: OrderedDict[str, SweepState] = OrderedDict()
        self._turn = asyncio.Lock()
        self._tasks: set[asyncio.Task[None]] = set()

    def get(self, sweep_id: str) -> SweepState | None:
        """A sweep's state, or None."""
        return self._states.get(sweep_id)

    def submit(self, spec: SweepSpec, cases: list[SweepCase], params: dict[str, Any]
               ) -> SweepState:
        """Queue a sweep (call on the web loop); :class:`Busy` (503) past the queue."""
        waiting = sum(s.status in ("queued", "running") for s in self._states.values())
        if waiting > self.queue:
            raise Busy(503, f"{waiting} sweeps are queued or running (the queue holds "
                            f"{self.queue} behind the running one); retry later", 30)
        state = SweepState(secrets.token_hex(8), params, len(cases))  # 64 random bits
        self._states[state.sweep_id] = state
        ended = [k for k, s in self._states.items() if s.status in ("done", "failed")]
        for k in ended[:max(0, len(self._states) - KEEP)]:
            del self._states[k]
        task = asyncio.get_running_loop().create_task(self._run(state, spec, cases))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return state

    async def close(self, timeout_s: float = 30.0) -> None:
        """The service stops: every queued or running sweep is cancelled and waited for up
        to ``timeout_s`` (a running one stops within a poll of :func:`run_sweep`, closing
        the Dask cluster it made); past that the tasks are cancelled."""
        for state in self._states.values():
            if state.status in ("queued", "running"):
                state.cancel = True
        tasks = list(self._tasks)
        if not tasks:
            return
        _, late = await asyncio.wait(tasks, timeout=timeout_s)
        for task in late:
            task.cancel()
        await asyncio.gather(*late, return_exceptions=True)

    def cancel(self, sweep_id: str) -> SweepState | None:
        """Stop a queued or running sweep (a running one at once, its running cases dropped)."""
        state = self._states.get(sweep_id)
        if state is not None and state.status in ("queued", "running"):
            state.cancel = True
        return state

    async def _run(self, state: SweepState, spec: SweepSpec, cases: list[SweepCase]) -> None:
        async with self._turn:
            if state.cancel:
                state.status, state.error = "failed", "cancelled"
                return
            state.status = "running"

            def progress(done: int, total: int) -> None:
                state.done = done

            try:
                state.result = await anyio.to_thread.run_sync(
                    lambda: run_sweep(spec, cases, scheduler=self.scheduler, progress=progress,
                                      cancelled=lambda: state.cancel),
                    abandon_on_cancel=True)
                state.status = "done"
            except SweepCancelled as exc:  # the cases done stay to be read
                state.status, state.error = "failed", "cancelled"
                state.result = exc.result
            except SweepFailed as exc:  # the scheduler lost, no worker: the cases done stay
                log.warning("plant sweep %s failed: %s", state.sweep_id, exc)
                state.status, state.error = "failed", str(exc)
                state.result = exc.result
            except SweepSetupError as exc:  # the scheduler is not one (or is down), or its
                # workers lack heliotwin; the setting named where it is the setting's address
                log.warning("plant sweep %s refused by its cluster: %s", state.sweep_id, exc)
                state.status = "failed"
                why = str(exc).removeprefix("scheduler: ")
                state.error = f"{SCHEDULER_SETTING}: {why}" if why.startswith(
                    "cannot reach") or "no Dask scheduler address" in why else why
            except asyncio.CancelledError:          # the service stops: the thread stops too
                state.cancel = True
                state.status, state.error = "failed", "the service stopped"
                raise
            except Exception as exc:  # a worker died, the scheduler went away, bad physics
                log.exception("plant sweep %s failed", state.sweep_id)
                state.status, state.error = "failed", f"{type(exc).__name__}: {exc}"


__all__ = ["KEEP", "SweepRunner", "SweepState"]
