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
  makes (the tick rule is ``sim.twin``'s). ``closed_loop_camera`` renders a frame every
  daylight second, so its loop is scaled by the run's share of daylight at the site over
  the table's (:data:`TABLE_DAYLIGHT_SHARE`): one day took 6.3 s at Tehuantepec on
  15 March (12 h of daylight), 11.0 s at Tromsø (69.65° N) on 21 June (24 h) and 0.24 s
  there on 21 December, on one machine in one session — a fixed price per day refused a
  week of polar night that costs seconds and let a polar summer run twice its estimate;
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
from sim.sites import Site
from sim.sun import daylight_s
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
#: Controllers whose loop costs by the daylight second (a camera frame each).
DAYLIGHT_LOOPS = ("closed_loop_camera",)
#: The table's runs' share of daylight (Tehuantepec from 1 March: 0.494).
TABLE_DAYLIGHT_SHARE = 0.5
#: The daylight share is sampled at most this many times over a run (a year: every 3 h,
#: whose middles drift through the day).
_DAYLIGHT_SAMPLES = 3000
#: Runs shorter than this [s] teach nothing (their time is the process start's).
_LEARN_MIN_S = 0.5
#: Weight of the newest run in the learned factor (exponential mean of log ratios).
_LEARN_WEIGHT = 0.5
#: A learned factor stays within these (one odd run cannot make the estimate absurd).
_FACTOR_BOUNDS = (0.2, 20.0)


def table_cost_s(params: Scenario, site: Site) -> float:
    """The table's estimate of ``params`` at ``site`` [s] (before the learned factor)."""
    duration_s = (params.end - params.start).total_seconds()
    steps = duration_s / params.step_s
    loop_s = LOOP_DAY_S.get(params.controller, max(LOOP_DAY_S.values()))
    if loop_s:
        settings = ControlSettings()
        default_tick = _tick_s(params.controller, 60.0, settings)
        tick_ratio = max(1.0, default_tick / _tick_s(params.controller, params.step_s,
                                                     settings))
        loop_s *= duration_s / 86400.0 * tick_ratio
        if params.controller in DAYLIGHT_LOOPS:
            t0 = params.start.timestamp()
            lit = daylight_s(t0, t0 + duration_s, max(300.0, duration_s / _DAYLIGHT_SAMPLES),
                             site.latitude, site.longitude, site.altitude, site.temp_air)
            loop_s *= lit / duration_s / TABLE_DAYLIGHT_SHARE
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

    def estimate_s(self, table_s: float, controller: str) -> float:
        """Expected worker time [s] of a run of ``controller`` the table prices ``table_s``
        (:func:`table_cost_s`)."""
        return table_s * self.factor(controller)

    def learn(self, controller: str, table_s: float, elapsed_s: float) -> None:
        """A finished run the table priced ``table_s`` took ``elapsed_s`` of worker time:
        move the factors toward it."""
        if elapsed_s < _LEARN_MIN_S:
            return
        lo, hi = (math.log(b) for b in _FACTOR_BOUNDS)
        log_ratio = min(hi, max(lo, math.log(elapsed_s / table_s)))
        with self._lock:
            old = self._log_factor.get(controller, self._log_all)
            self._log_factor[controller] = (
                log_ratio if old is None else old + _LEARN_WEIGHT * (log_ratio - old))
            self._log_all = (log_ratio if self._log_all is None
                             else self._log_all + _LEARN_WEIGHT * (log_ratio - self._log_all))
