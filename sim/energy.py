"""The energy of a power series and the tracking gain: one rule for every consumer.

**The energy rule.** The energy of a series of power readings (one array, one source)
is the trapezoid integral of power over time between consecutive readings. An
interval longer than ``max_gap_s`` is not bridged: it adds nothing, so a logger
outage shows as missing energy — never as an invented straight line, never as zero
power read into the gap. A range ``[start, end)`` clips the intervals that cross its
edges, the power at an edge interpolated linearly, so the energies of adjacent
ranges add up exactly to the energy of their union. Readings without a power value
(NaN) are dropped before the intervals are formed.

The rule does not depend on the logger's cadence: 1-, 5- or 15-minute loggers and
irregular ones integrate the same way, so the energy of a day does not change when a
logger reports less often (only its accuracy does). ``max_gap_s`` must be longer than
the slowest logger's interval; the service's default (``energy_max_gap_s``,
:data:`DEFAULT_MAX_GAP_S`) bridges every common cadence up to 15 minutes with room for
jitter, and a 1-minute logger's outage of up to that long is bridged by a line.

:func:`on_grid` puts a series on a regular grid by the same rule (linear between
readings at most ``max_gap_s`` apart, NaN elsewhere): the diagnosis's minute grid,
so a 5-minute logger's minutes are interpolated, not missing. :func:`gain_pct` is
the one tracking-gain formula.

Every consumer uses these functions: the hourly rollups and the energy endpoint
(``backend/measurements``), the diagnosis and the weather-aware twin
(``backend/diagnosis``), the alerts and reports through them, and the twin's own
summaries (:mod:`sim.twin`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

#: The service's default longest interval between two readings that energy bridges [s]:
#: a 15-minute logger (900 s) with a reading up to 5 minutes late is still bridged.
DEFAULT_MAX_GAP_S = 1200


def trapezoid_wh(t0: Any, p0: Any, t1: Any, p1: Any, lo: Any, hi: Any) -> Any:
    """Energy [Wh] of the part ``[lo, hi]`` of the straight line from power ``p0`` [W]
    at ``t0`` [s] to ``p1`` [W] at ``t1`` [s] (``t0 ≤ lo ≤ hi ≤ t1``).

    Plain arithmetic, so it takes Python floats and NumPy arrays alike; callers drop
    intervals longer than the gap (:func:`energy_wh` does).
    """
    slope = (p1 - p0) / (t1 - t0)
    return 0.5 * (2.0 * p0 + slope * (lo - t0 + hi - t0)) * (hi - lo) / 3600.0


def _finite(ts_s: Any, power_w: Any) -> tuple[np.ndarray, np.ndarray]:
    ts = np.asarray(ts_s, np.float64).reshape(-1)
    p = np.asarray(power_w, np.float64).reshape(-1)
    if ts.shape != p.shape:
        raise ValueError(f"ts_s and power_w differ in length ({ts.size} vs {p.size})")
    ok = np.isfinite(p) & np.isfinite(ts)
    return ts[ok], p[ok]


def energy_per_period_wh(ts_s: Any, power_w: Any, max_gap_s: float, edges_s: Any
                         ) -> np.ndarray:
    """Energy [Wh] of a power series in each period ``[edges_s[i], edges_s[i+1])``.

    Parameters
    ----------
    ts_s : array_like
        Reading times [s], increasing (Unix seconds or any origin).
    power_w : array_like
        Power at those times [W]; NaN readings are dropped.
    max_gap_s : float
        Longest interval between consecutive readings that is integrated [s].
    edges_s : array_like
        Increasing period edges [s] (±inf allowed). An interval crossing an edge is
        split there; ``ts_s`` must hold the readings within ``max_gap_s`` outside the
        first and last edge, else the outer periods lose what reaches them.
    """
    edges = np.asarray(edges_s, np.float64).reshape(-1)
    ts, p = _finite(ts_s, power_w)
    if ts.size < 2 or edges.size < 2:
        return np.zeros(max(edges.size - 1, 0))
    a, b, pa, pb = ts[:-1], ts[1:], p[:-1], p[1:]
    kept = (b - a) <= max_gap_s
    whole = np.where(kept, trapezoid_wh(a, pa, b, pb, a, b), 0.0)
    at_reading = np.concatenate([[0.0], np.cumsum(whole)])  # energy up to each reading
    i = np.searchsorted(ts, edges, side="right") - 1  # the last reading at or before an edge
    inside = (i >= 0) & (i < ts.size - 1)
    upto = np.where(i < 0, 0.0, at_reading[np.clip(i, 0, ts.size - 1)])
    j = i[inside]
    part = trapezoid_wh(a[j], pa[j], b[j], pb[j], a[j], edges[inside])
    upto[inside] += np.where(kept[j], part, 0.0)
    return np.diff(upto)


def energy_wh(ts_s: Any, power_w: Any, max_gap_s: float, start_s: float = -np.inf,
              end_s: float = np.inf) -> float:
    """Energy [Wh] of a power series over ``[start_s, end_s)``: :func:`energy_per_period_wh`
    of that one period (whole series by default)."""
    return float(energy_per_period_wh(ts_s, power_w, max_gap_s, [start_s, end_s])[0])


def simulation_times(start: Any, end: Any, step_s: float) -> Any:
    """The instants [UTC] a simulation of ``[start, end)`` computes: its steps, one every
    ``step_s`` [s] from ``start`` (the rows it shows), and one more, the first instant of
    the grid at or after ``end``. That last instant closes the last step: the energy of
    the range (:func:`run_energy_wh`) then integrates every step as a stored series that
    goes on past ``end`` would, so a one-step run is not 0 Wh and a range that ends in
    daylight keeps its last step (a sweep at hourly steps ending at noon lost an hour)."""
    import pandas as pd

    step = pd.Timedelta(seconds=float(step_s))
    steps = pd.date_range(pd.Timestamp(start).tz_convert("UTC"),
                          pd.Timestamp(end).tz_convert("UTC"), freq=step, inclusive="left")
    return pd.date_range(steps[0], periods=len(steps) + 1, freq=step)


#: The longest step of a run [s]: an hour, a typical year's own resolution. The energy is
#: the steps' power integrated, so a step that skips the day's shape is no energy (a
#: tester's finding: Hamburg's clear June day read a 5.5 % gain at a 12-hour step against
#: 56.0 % at a minute, and 0 Wh at a day's step; 56.04 % at an hour; a plant sweep's month
#: read +58 % at 12 hours and 0 Wh at a day). The twin's runs and the plant's alike.
MAX_STEP_S = 3600.0


def check_step(start: Any, end: Any, step_s: float) -> None:
    """A run's range and step: ``end`` after ``start``, ``step_s`` positive, no longer
    than the run (a step of 10⁹ s made a day's control loop tick through 31 years) nor
    than :data:`MAX_STEP_S`."""
    if not end > start:
        raise ValueError(f"end ({end.isoformat()}) must be after start ({start.isoformat()})")
    if not step_s > 0:
        raise ValueError(f"step_s must be positive, got {step_s}")
    if step_s > (end - start).total_seconds():
        raise ValueError(f"step_s: {step_s:g} s is longer than the run "
                         f"({(end - start).total_seconds():g} s from start to end)")
    if step_s > MAX_STEP_S:
        raise ValueError(f"step_s: {step_s:g} s is longer than an hour ({MAX_STEP_S:g} s), "
                         f"too coarse to integrate a day's energy")


def step_problem(exc: ValueError) -> str:
    """:func:`check_step`'s refusal without its ``step_s:`` (for a caller naming the field
    its own way: ``--step-s``)."""
    text = str(exc)
    return text.removeprefix("step_s: ").removeprefix("step_s ")


def run_energy_wh(power_w: Any, step_s: float, duration_s: float) -> float:
    """Energy [Wh] of a simulation over its range ``[0, duration_s)`` [s]: its power at
    :func:`simulation_times` (one sample every ``step_s`` [s] from the range's start, the
    last at or after its end), by :func:`energy_wh` clipped at the end — the twin's and
    the plant's summaries integrate as the same series stored and read back would."""
    p = np.asarray(power_w, np.float64).reshape(-1)
    t = np.arange(p.size, dtype=np.float64) * float(step_s)
    if p.size < 2 or t[-1] < float(duration_s) - 1e-6 * float(step_s):
        raise ValueError(f"{p.size} samples every {step_s} s do not reach the range's end "
                         f"({duration_s} s): simulate at simulation_times()")
    return energy_wh(t, p, 1.5 * float(step_s), 0.0, float(duration_s))


#: What a reading's timestamp marks (a site's ``readings_stamped``): the instant its value
#: belongs to, or the end / the start of the interval it averages.
READING_STAMPS = ("instant", "interval_end", "interval_start")


def interval_middles(ts_s: Any, stamped: str, max_gap_s: float,
                     interval_s: float | None = None) -> np.ndarray:
    """The instants [s] the readings stamped ``ts_s`` (sorted) stand for: as stamped for
    ``"instant"``; for a mean stamped at the end (start) of its interval, the interval's
    middle — half the spacing to the reading before (after) earlier (later), the series'
    median bridged spacing where that spacing is over ``max_gap_s`` (the first reading
    after a gap; the median of all spacings when none is bridged). Where the sun was while
    a logger averaged is the middle of its interval: an hourly mean stamped at its end sits
    30 minutes after the sun it saw, and the diagnosis matched the morning's sky to a
    higher sun (docs/diagnosis.md, "Cadence"). A weather file's values are placed by the
    same rule (:mod:`sim.sky`); ``interval_s``, when given, is every value's interval [s]
    instead of the spacing (a typical year's hour: its rows need not be in order)."""
    ts = np.asarray(ts_s, np.float64).reshape(-1)
    if stamped not in READING_STAMPS:
        raise ValueError(f"stamped must be one of {READING_STAMPS}; got {stamped!r}")
    if interval_s is not None and stamped != "instant":
        return ts + (0.5 if stamped == "interval_start" else -0.5) * float(interval_s)
    if stamped == "instant" or ts.size < 2:
        return ts
    step = np.diff(ts)
    bridged = step <= max_gap_s
    typical = float(np.median(step[bridged] if bridged.any() else step))
    step = np.where(bridged, step, typical)
    if stamped == "interval_end":
        return ts - 0.5 * np.concatenate(([typical], step))
    return ts + 0.5 * np.concatenate((step, [typical]))


def on_grid(ts_s: Any, values: Any, grid_s: Any, max_gap_s: float) -> np.ndarray:
    """Values of a series at the times ``grid_s`` [s], by the energy rule's line.

    Linear between consecutive readings at most ``max_gap_s`` apart (a grid time
    equal to a reading's time takes that reading); NaN at grid times outside the
    readings or inside a longer gap. ``values`` may be 1-D ``(n,)`` or 2-D ``(n, k)``
    (each column its own series: a NaN reading of one column is dropped from that
    column only). Integrating the result with :func:`energy_wh` on a grid that holds
    every reading time gives the series' own energy exactly.
    """
    grid = np.asarray(grid_s, np.float64).reshape(-1)
    v = np.asarray(values, np.float64)
    if v.ndim == 2:
        return np.column_stack([on_grid(ts_s, v[:, j], grid, max_gap_s)
                                for j in range(v.shape[1])]) if v.shape[1] \
            else np.empty((grid.size, 0))
    ts, p = _finite(ts_s, v)
    out = np.full(grid.size, np.nan)
    if ts.size == 0:
        return out
    # the reading at or after each grid time, and the one before it
    j = np.searchsorted(ts, grid, side="left")
    exact = (j < ts.size) & (ts[np.minimum(j, ts.size - 1)] == grid)
    out[exact] = p[j[exact]]
    inner = ~exact & (j > 0) & (j < ts.size)
    ji = j[inner]
    t0, t1, p0, p1 = ts[ji - 1], ts[ji], p[ji - 1], p[ji]
    bridged = (t1 - t0) <= max_gap_s
    g = grid[inner]
    out[np.flatnonzero(inner)[bridged]] = (p0 + (p1 - p0) * (g - t0) / (t1 - t0))[bridged]
    return out


#: Two loggers read the same minutes when each array's expected energy over the minutes both
#: read is at least this share short of its expected energy over its own [-]
SAME_MINUTES = 0.01


def same_minutes(own_wh: Sequence[float | None], shared_wh: Sequence[float | None]
                 ) -> bool | None:
    """Whether two loggers read the same minutes: for each array, its expected energy over
    the minutes *both* loggers read (``shared_wh``) within :data:`SAME_MINUTES` of it over
    its own (``own_wh``). None when an energy is unknown (no twin). Amounts over each
    logger's own minutes alone would pass a morning beside an afternoon of equal energy."""
    if any(v is None for v in (*own_wh, *shared_wh)):
        return None
    return all(shared >= (1.0 - SAME_MINUTES) * own  # type: ignore[operator]
               for own, shared in zip(own_wh, shared_wh, strict=True))


def measured_gain_pct(tracker_wh: float | None, fixed_wh: float | None,
                      same: bool | None, ratings_w: tuple[float, float] | None = None
                      ) -> float | None:
    """:func:`gain_pct` of measured energies, None when the two loggers read different
    minutes (``same`` False, :func:`same_minutes`): a fixed-array logger that began at
    15:30 beside a tracker's whole day read +1,540 % (a tester's finding); both over the
    same half-day still give one, and so does an unknown ``same`` (no twin to tell)."""
    return None if same is False else gain_pct(tracker_wh, fixed_wh, ratings_w)


def gain_pct(tracker_wh: float | None, fixed_wh: float | None,
             ratings_w: tuple[float, float] | None = None) -> float | None:
    """The tracking gain [%]: the tracker's energy per watt of its rating over the fixed
    array's, ``100 · ((tracker / P_tracker) / (fixed / P_fixed) − 1)``, ``ratings_w`` =
    ``(P_tracker, P_fixed)`` their STC ratings [W] (:meth:`sim.sites.Site.gain_ratings_w`):
    the ratio of their specific yields (IEC 61724-1's final yield), so arrays of different
    sizes compare by what tracking gains — a tracker of 820 W beside a 24 kW reference read
    −94 % as the energies' ratio. Equal ratings (seed 000's four modules each) or none
    given: the energies' ratio exactly. None when either energy is missing or the fixed
    array's is not positive (no gain is defined against nothing)."""
    if tracker_wh is None or fixed_wh is None or not np.isfinite(tracker_wh) \
            or not np.isfinite(fixed_wh) or fixed_wh <= 0:
        return None
    per_watt = 1.0 if ratings_w is None or ratings_w[0] == ratings_w[1] \
        else ratings_w[1] / ratings_w[0]
    return 100.0 * (tracker_wh / fixed_wh * per_watt - 1.0)
