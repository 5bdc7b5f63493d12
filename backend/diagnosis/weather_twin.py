"""The weather-aware twin of a site over a range, minute by minute (issue 13, item 5).

``GET …/measurements?source=twin_weather`` answers it: both arrays' expected power
under the sky the fixed array's measured power says there was
(:func:`sim.sky_sensor.weather_aware_twin`, the same pipeline as the clear-sky twin
and as the diagnosis), beside ``measured`` and the clear-sky ``twin``. Computed on
request (0.71 s of CPU for a day of a 1-minute fixed logger, 2026-12-06; once for the
requests that ask for it while it runs: :func:`weather_twin`), so a range is at most
:data:`MAX_DAYS` long; the per-day energies of the same twin are cached by the diagnosis
(``backend/diagnosis/service.py``).
"""

from __future__ import annotations

import datetime as dt
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from sqlalchemy import Connection

from backend.errors import InputError
from backend.measurements.fields import SENSOR_NAMES
from backend.measurements.queries import iso_utc, raw_rows
from backend.sites import SiteInfo
from sim import sky_sensor
from sim.energy import energy_per_period_wh, gain_pct, interval_middles, on_grid

if TYPE_CHECKING:
    from backend.context import ServiceContext

MAX_DAYS = 31
#: :func:`weather_twin`s being computed, by (service, site, first and end second): a
#: request for one of them waits for its answer instead of computing it again. Callers run
#: on worker threads (the measurements route is a plain ``def``, the energy route's work goes
#: to ``anyio.to_thread``), hence a lock; never call it on the event loop.
_IN_FLIGHT: dict[tuple[int, int, int, int], Future[pd.DataFrame]] = {}
_IN_FLIGHT_LOCK = threading.Lock()


def _rows(conn: Connection, array_id: int, t0: int, t1: int, max_gap_s: int) -> np.ndarray:
    """The array's stored readings with their sensor columns around ``[t0, t1)``: two gaps
    beyond each end, as far as a mean stamped at an interval's edge may stand from it."""
    return raw_rows(conn, array_id, 0, t0 - 2 * max_gap_s, t1 + 2 * max_gap_s, sensors=True)


#: The readings' columns a sky rests on (the power, the plane's POA sensor, a GHI
#: pyranometer), by name, as offsets from the power's column (3) of :func:`_rows`: those
#: whose cadence :func:`minute_grid` reads for each minute
FINE_COLUMNS = {"power_w": 0, **{name: 1 + SENSOR_NAMES.index(name)
                                 for name in ("poa_irradiance_w_m2", "ghi_w_m2")}}


def minute_grid(rows: np.ndarray, t0: int, t1: int, max_gap_s: int,
                stamped: str = "instant"
                ) -> tuple[np.ndarray, np.ndarray, float | None, dict[str, np.ndarray],
                           np.ndarray]:
    """Measured power [W], shape (n,), the :data:`SENSOR_NAMES` columns, shape (n, k), the
    readings' median spacing [s] (None under two readings: a logger slower than the
    energy rule's gap leaves every minute NaN), and per minute whether the readings of each
    column a sky can rest on (:data:`FINE_COLUMNS`) are fine enough to show a clear spell
    (:func:`sim.sky_sensor.readings_fine`), on the minute grid of ``[t0, t1)`` by the
    energy rule's line
    (:func:`sim.energy.on_grid`): linear between readings at most ``max_gap_s`` apart,
    so a 5- or 15-minute logger's minutes between readings are interpolated, never
    missing or zero; NaN outside the readings and inside a longer gap. ``rows``: the
    array's readings (:func:`_rows`). Each reading
    stands at its interval's middle when the readings are means stamped at an
    interval's end or start (``stamped``, :func:`sim.energy.interval_middles`). Last, the
    measured voltage [V], shape (n,), NaN where the readings carry none (power alone)."""
    n = (t1 - t0) // 60
    grid = t0 + 60 * np.arange(n, dtype=np.int64)
    ts = interval_middles(rows[:, 0], stamped, max_gap_s)
    power = on_grid(ts, rows[:, 3], grid, max_gap_s)
    sensors = on_grid(ts, rows[:, 4:], grid, max_gap_s)
    spacing = float(np.median(np.diff(rows[:, 0]))) if len(rows) > 1 else None
    fine = {name: sky_sensor.readings_fine(ts, rows[:, 3 + j], grid)
            for name, j in FINE_COLUMNS.items()}
    return power, sensors, spacing, fine, on_grid(ts, rows[:, 1], grid, max_gap_s)


def sky_fine(fixed_fine: dict[str, np.ndarray], tracker_fine: dict[str, np.ndarray],
             fixed_sensors: np.ndarray) -> dict[str, np.ndarray]:
    """The ``fine`` of :func:`sim.sky_sensor.weather_aware_twin` from the two loggers'
    (:func:`minute_grid`), by the sources :func:`sky_sensors` reads: the fixed array's
    power, its plane's POA sensor, and the GHI of the fixed logger where it reads one, else
    the tracker's."""
    fixed_ghi = np.isfinite(fixed_sensors[:, SENSOR_NAMES.index("ghi_w_m2")])
    return {"fixed_power_w": fixed_fine["power_w"],
            "fixed_poa_w_m2": fixed_fine["poa_irradiance_w_m2"],
            "ghi_w_m2": np.where(fixed_ghi, fixed_fine["ghi_w_m2"], tracker_fine["ghi_w_m2"])}


def sky_sensors(fixed: np.ndarray, tracker: np.ndarray | None) -> pd.DataFrame | None:
    """The ``sensors`` frame of :func:`sim.sky_sensor.weather_aware_twin` from the two
    loggers' sensor columns (:func:`minute_grid`): ``fixed_poa_w_m2`` from the fixed
    array's ``poa_irradiance_w_m2`` (a cell on the tracker shares its pointing: not a sky
    sensor), ``fixed_temp_module_c`` from its ``temp_module_c`` (the fixed array's back-of-module
    temperature), ``ghi_w_m2``, ``temp_air_c`` and ``wind_speed_m_s`` from either logger, the
    fixed one's first. None when neither reports any of them."""
    col = {name: j for j, name in enumerate(SENSOR_NAMES)}
    out = {"fixed_poa_w_m2": fixed[:, col["poa_irradiance_w_m2"]],
           "fixed_temp_module_c": fixed[:, col["temp_module_c"]]}
    for name in ("ghi_w_m2", "temp_air_c", "wind_speed_m_s"):
        v = fixed[:, col[name]]
        if tracker is not None:
            v = np.where(np.isfinite(v), v, tracker[:, col[name]])
        out[name] = v
    if not any(np.isfinite(v).any() for v in out.values()):
        return None
    return pd.DataFrame(out)


def site_minutes(ctx: ServiceContext, info: SiteInfo, t0: int, t1: int
                 ) -> tuple[np.ndarray, np.ndarray, pd.DataFrame | None, float | None,
                            dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The tracker's and the fixed array's measured power [W] on the minute grid of
    ``[t0, t1)`` (:func:`minute_grid`: NaN where the energy rule bridges no reading), the
    loggers' sky sensors (:func:`sky_sensors`), the tracker's readings' median spacing [s],
    where each sky source's readings show a clear spell (:func:`sky_fine`), and the two
    arrays' measured voltage [V] (``tracker``, ``fixed``; NaN without a voltage). The site
    has the twin's arrays (:meth:`SiteInfo.has_twin`)."""
    # the arrays the twin simulates (SiteInfo.has_twin), not merely the first of each mount
    tracker, fixed = info.arrays["tracker"], info.arrays["fixed"]
    gap = ctx.settings.ingest.energy_max_gap_s
    with ctx.engine.connect() as conn:
        fx_rows = _rows(conn, fixed.array_id, t0, t1, gap)
        tr_rows = _rows(conn, tracker.array_id, t0, t1, gap)
        stamped = readings_stamped(info, fx_rows, gap, lambda: _rows(
            conn, fixed.array_id, t0 - STAMP_LOOKBACK_S, t1, gap))
    fx, fx_s, _, fx_fine, fx_v = minute_grid(fx_rows, t0, t1, gap, stamped)
    tr, tr_s, tr_spacing, tr_fine, tr_v = minute_grid(tr_rows, t0, t1, gap, stamped)
    return (tr, fx, sky_sensors(fx_s, tr_s), tr_spacing, sky_fine(fx_fine, tr_fine, fx_s),
            {"tracker": tr_v, "fixed": fx_v})


#: How far before a run the fixed array's readings are read to tell what a slow logger's
#: stamps mark [s]: a month holds clear days (a cloudy day alone shows no convention, and
#: asked for alone it was read as instants where its month said interval ends)
STAMP_LOOKBACK_S = 30 * 86400


def readings_stamped(info: SiteInfo, fixed_rows: np.ndarray, max_gap_s: int,
                     lookback_rows: Callable[[], np.ndarray]) -> str:
    """What the loggers' stamps mark for the diagnosis: the site's ``readings_stamped``, or
    where the site leaves the default ``"instant"`` and the fixed array's readings
    (``fixed_rows``, the run's) are :data:`sim.sky_sensor.STAMP_INFER_MIN_SPACING_S` or
    more apart on a local day at least (:func:`sim.sky_sensor.on_slow_days`), what the
    clear days' shape says over the run and the :data:`STAMP_LOOKBACK_S` before it
    (``lookback_rows``, read only then)
    (:func:`sim.sky_sensor.inferred_stamped`: an hourly logger's means stamped at the end
    of their hour read as instants matched the sky to the sun half an hour later, and every
    clear day was a ``sky_clock_offset``). The fixed plane's sensor where the logger reads
    one, else its power."""
    if info.site.readings_stamped != "instant" or not sky_sensor.on_slow_days(
            info.site, fixed_rows[:, 0], max_gap_s).any():
        return info.site.readings_stamped
    fixed_rows = lookback_rows()
    col = 4 + SENSOR_NAMES.index("poa_irradiance_w_m2")
    poa = fixed_rows[:, col] if fixed_rows.shape[1] > col else np.full(len(fixed_rows), np.nan)
    values = poa if np.isfinite(poa).sum() * 2 > len(fixed_rows) else fixed_rows[:, 3]
    return sky_sensor.inferred_stamped(info.site, fixed_rows[:, 0], values, max_gap_s,
                                       info.site.readings_stamped)


def sky_source(e: pd.DataFrame) -> tuple[str, str | None]:
    """What most of the daylight minutes of ``e`` (:func:`weather_twin`) rest on:
    ``"sensor"``, ``"fixed_array"`` or ``"clear_sky"``, and the sensor's reading
    (``"poa_irradiance_w_m2"`` on the fixed plane, ``"ghi_w_m2"``) or None."""
    top = sky_sensor.main_sky_source(e)
    return {"sensor_poa": ("sensor", "poa_irradiance_w_m2"),
            "sensor_ghi": ("sensor", "ghi_w_m2")}.get(top, (top, None))


def _need_twin(info: SiteInfo) -> None:
    """422 naming ``source`` for a site the twin cannot simulate (:meth:`SiteInfo.has_twin`)."""
    if not info.has_twin():
        raise InputError(422, f"source: site {info.site_id!r} has no arrays named 'tracker' "
                              "and 'fixed' (mounts tracker and fixed) for the twin to read the "
                              "sky from and simulate; use source=twin (clear sky)")


def weather_twin(ctx: ServiceContext, info: SiteInfo, t0: int, t1: int) -> pd.DataFrame:
    """:func:`sim.sky_sensor.weather_aware_twin` over ``[t0, t1)`` (whole minutes), from
    the fixed array's stored readings and the loggers' sky sensors; 422 without a fixed
    array or past ``MAX_DAYS``."""
    _need_twin(info)
    if t1 - t0 > MAX_DAYS * 86400:
        raise InputError(422, f"source=twin_weather is computed on request: at most {MAX_DAYS} "
                              "days (the diagnosis gives its daily energy for longer ranges)")
    t0, t1 = t0 // 60 * 60, -(-t1 // 60) * 60
    # one computation for the requests that ask for the same twin while it runs: the
    # Overview asks for both arrays' day at once, and each answer is one column of the
    # same frame (in flight only, no cache: a later request reads the readings afresh;
    # an edited site is a new Site object, so a new key)
    key = (id(ctx), id(info.site), t0, t1)
    with _IN_FLIGHT_LOCK:
        running = _IN_FLIGHT.get(key)
        if running is None:
            _IN_FLIGHT[key] = mine = Future[pd.DataFrame]()
    if running is not None:
        return running.result()
    try:
        _, fx, sensors, _, fine, _ = site_minutes(ctx, info, t0, t1)
        start, now = pd.Timestamp(t0, unit="s", tz="UTC"), pd.Timestamp.now(tz="UTC")
        end = pd.Timestamp(t1, unit="s", tz="UTC")
        twin = sky_sensor.weather_aware_twin(info.site, start, end, fx, sensors=sensors,
                                             now=now if end > now else None, fine=fine)
    except BaseException as exc:
        mine.set_exception(exc)
        raise
    else:
        mine.set_result(twin)
        return twin
    finally:
        with _IN_FLIGHT_LOCK:
            del _IN_FLIGHT[key]


def weather_twin_columns(ctx: ServiceContext, info: SiteInfo, array: str, t0: int,
                         t1: int) -> tuple[dict[str, list[Any]], dict[str, Any]]:
    """Columns of a measurements answer (``ts``, ``power_w``, voltage and current null:
    the weather-aware twin models power; ``sky_valid``: the sky sensor's reading or the
    fixed array's inversion held that minute, else the clear-sky index was carried over
    from valid neighbours, or on a day without a measured sky the clear sky itself) and
    what most of the range's sky rests on (:func:`sky_source`)."""
    e = weather_twin(ctx, info, t0, t1)
    kind = info.arrays[array].kind
    ts = e.index.as_unit("s").asi8
    keep = (ts >= t0) & (ts < t1)
    e = e[keep]
    power = e[f"{kind}_power_w"].to_numpy()
    daylight = sky_sensor.measurable(e)
    valid = e["valid"].to_numpy(bool)
    share = float(valid[daylight].mean()) if daylight.any() else 0.0
    cols: dict[str, list[Any]] = {
        "ts": iso_utc(ts[keep]), "voltage_v": [None] * power.size,
        "current_a": [None] * power.size, "power_w": np.round(power, 3).tolist(),
        "sky_valid": valid.tolist(),
    }
    source, sensor = sky_source(e)
    sky = {"source": source, "sensor": sensor,
           "valid_daylight_minutes_pct": round(100.0 * share, 1)}
    return cols, sky


def weather_twin_energy(ctx: ServiceContext, info: SiteInfo, data: dict[str, Any],
                        max_computed_days: int | None = None) -> None:
    """Add the weather-aware twin's energy to an energy answer (``energy_rows``), in place:
    ``twin_weather_wh`` per array and period (and in the totals), ``twin_weather_gain_pct``
    and ``twin_weather_note`` per period.

    Periods of whole local days take the diagnosis's per-day energies (cached in
    ``diagnosis_days``, so a year costs one diagnosis of it); other periods (hours, a
    range not starting at midnight) the minute twin, at most :data:`MAX_DAYS` days. A day
    whose sky fell back to clear sky (under half its daylight minutes inverted) is
    counted and named in the note. ``max_computed_days``: the most of those days not
    cached yet the request may diagnose (:func:`backend.diagnosis.service.diagnosis`:
    422 naming ``end`` past it; None: no bound).
    """
    from backend.diagnosis.service import diagnosis  # it imports this module's neighbours

    _need_twin(info)
    rows = data["rows"]
    edges = [dt.datetime.fromisoformat(r["period_start"]) for r in rows]
    if not rows:
        return
    edges.append(dt.datetime.fromisoformat(rows[-1]["period_end"]))
    kinds = {name: a.kind for name, a in info.arrays.items()}
    per: list[dict[str, float]] = [dict.fromkeys(kinds, 0.0) for _ in rows]
    notes: list[str | None] = [None] * len(rows)
    midnights = all(e.astimezone(info.zone).time() == dt.time(0) for e in edges)
    if midnights:
        days = diagnosis(ctx, info, edges[0], edges[-1],
                         max_computed_days=max_computed_days)["days"]
        starts = [e.astimezone(info.zone).date().isoformat() for e in edges]
        p = 0
        clear = [0] * len(rows)
        for d in days:
            while p + 1 < len(starts) - 1 and d["date"] >= starts[p + 1]:
                p += 1
            for name, kind in kinds.items():
                wh = d[kind]["expected_wh"] if kind in ("tracker", "fixed") else None
                per[p][name] += wh or 0.0
            clear[p] += d["sky"]["source"] == "clear_sky"
        notes = [f"{c} day(s) without a measured sky: clear sky used" if c else None
                 for c in clear]
    else:
        t0, t1 = int(edges[0].timestamp()), int(edges[-1].timestamp())
        e = weather_twin(ctx, info, t0, t1)
        ts = e.index.as_unit("s").asi8
        edges_s = [int(x.timestamp()) for x in edges]
        for name, kind in kinds.items():
            col = f"{kind}_power_w"
            if col in e:
                wh = energy_per_period_wh(ts, e[col].to_numpy(), 60, edges_s)
                for i in range(len(rows)):
                    per[i][name] = float(wh[i])
    tracker, fixed = info.array_of_kind("tracker"), info.array_of_kind("fixed")
    totals = dict.fromkeys(kinds, 0.0)
    for r, wh, note in zip(rows, per, notes, strict=True):
        for name in kinds:
            r["arrays"][name]["twin_weather_wh"] = wh[name]
            totals[name] += wh[name]
        r["twin_weather_gain_pct"] = _gain_pct(info, wh, tracker, fixed)
        r["twin_weather_note"] = note
    for name in kinds:
        data["totals"]["arrays"][name]["twin_weather_wh"] = totals[name]
    data["totals"]["twin_weather_gain_pct"] = _gain_pct(info, totals, tracker, fixed)


def _gain_pct(info: SiteInfo, wh: dict[str, float], tracker: Any, fixed: Any
              ) -> float | None:
    """:func:`sim.energy.gain_pct` of the tracker's and the fixed array's energies."""
    if tracker is None or fixed is None:
        return None
    return gain_pct(wh[tracker.name], wh[fixed.name],
                    info.site.gain_ratings_w(tracker.name, fixed.name))
