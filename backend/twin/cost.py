"""What a twin run costs the simulation worker, before it runs: the queue's price [s].

A run is priced in seconds of worker time, not in steps: a ``closed_loop_camera`` day
renders ≈ 43,600 camera frames (one per daylight second) and costs ≈ 12 s, as much as
four years of the ``ideal`` controller at one minute. The estimate is

    cost_s = (OVERHEAD_S + STEP_S × steps + LOOP_DAY_S[controller] × days × tick_ratio)
             × factor[controller]

- ``STEP_S``: the vectorised physics of one output step (sun, sky, both arrays' electrics);
- ``LOOP_DAY_S``: the controller's control loop over one simulated day — its ticks and the
  camera frames it renders at its default intervals (``sim.control``); ``ideal`` has no
  loop. ``tick_ratio`` is how many more ticks a step shorter than the loop's default tick
  makes (the tick rule is ``sim.twin``'s);
- ``factor``: learned from finished runs (:meth:`CostModel.learn`): the time the worker
  really took over the table's estimate, per controller (a controller not yet seen uses
  the mean over all), so the estimate follows this machine's speed and load.

The table was measured on 2026-12-03 on the development machine (2 cores shared with
other work; wall time then ran ≈ 4× the CPU time): ``time.process_time()`` around
``backend.twin.scenario.run_scenario`` at Tehuantepec from 2024-03-01, runs of 1 to 365
days at 60, 600 and 3,600 s steps, the coefficients read off the runs' differences
(``ideal`` 365 days at 60 s: 1.66 s; ``closed_loop_camera`` 2, 4 and 8 days: 11.5–13.5 s a
day whatever the step; ``hybrid`` 30–120 days: 0.15–0.17 s a day). ``open_loop_model``
(issue 25) was timed beside ``open_loop_spa`` in one run (30 and 120 days at 60 s, load
10–12): 0.051 s a day against 0.048 s, 7 % more (its ephemeris goes through the pointing
model), so the table's 0.055 × 1.07.
"""

from __future__ import annotations

import math
import threading

from backend.twin.scenario import Scenario
from sim.control import ControlSettings
from sim.twin import _tick_s

#: A run's fixed cost [s]: the worker process, the first ephemeris, packing the series.
OVERHEAD_S = 0.5
#: The vectorised physics of one output step [s].
STEP_S = 2.7e-6
#: The control loop over one simulated day at the controller's default intervals [s].
LOOP_DAY_S: dict[str, float] = {
    "ideal": 0.0,
    "open_loop_spa": 0.055,
    "open_loop_duffie_beckman": 0.075,
    "chronological": 0.025,
    "closed_loop_camera": 12.0,
    "hybrid": 0.16,
    "open_loop_model": 0.059,
}
#: Runs shorter than this [s] teach nothing (their time is the process start's).
_LEARN_MIN_S = 0.5
#: Weight of the newest run in the learned factor (exponential mean of log ratios).
_LEARN_WEIGHT = 0.5
#: A learned factor stays within these (one odd run cannot make the estimate absurd).
_FACTOR_BOUNDS = (0.2, 20.0)


def table_cost_s(params: Scenario) -> float:
    """The table's estimate of ``params`` [s] (before the learned factor)."""
    duration_s = (params.end - params.start).total_seconds()
    steps = duration_s / params.step_s
    loop_s = LOOP_DAY_S.get(params.controller, max(LOOP_DAY_S.values()))
    if loop_s:
        settings = ControlSettings()
        default_tick = _tick_s(params.controller, 60.0, settings)
        tick_ratio = max(1.0, default_tick / _tick_s(params.controller, params.step_s,
                                                     settings))
        loop_s *= duration_s / 86400.0 * tick_ratio
    return OVERHEAD_S + STEP_S * steps + loop_s


class CostModel:
    """The table times factors learned from finished runs; thread-safe."""

    def __init__(self) -> None:
        self._log_factor: dict[str, float] = {}
        self._log_all: float | None = None
        self._lock = threading.Lock()

    def factor(self, controller: str) -> float:
        """What the worker takes over the table's estimate for ``controller`` (1 until a run
        of any controller is learned)."""
        with self._lock:
            log = self._log_factor.get(controller, self._log_all)
        return 1.0 if log is None else math.exp(log)

    def estimate_s(self, params: Scenario) -> float:
        """Expected worker time of ``params`` [s]."""
        return table_cost_s(params) * self.factor(params.controller)

    def learn(self, params: Scenario, elapsed_s: float) -> None:
        """A finished run took ``elapsed_s`` of worker time: move the factors toward it."""
        if elapsed_s < _LEARN_MIN_S:
            return
        lo, hi = (math.log(b) for b in _FACTOR_BOUNDS)
        log_ratio = min(hi, max(lo, math.log(elapsed_s / table_cost_s(params))))
        with self._lock:
            old = self._log_factor.get(params.controller, self._log_all)
            self._log_factor[params.controller] = (
                log_ratio if old is None else old + _LEARN_WEIGHT * (log_ratio - old))
            self._log_all = (log_ratio if self._log_all is None
                             else self._log_all + _LEARN_WEIGHT * (log_ratio - self._log_all))
