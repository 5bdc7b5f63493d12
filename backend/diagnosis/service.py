"""The diagnosis endpoint's service: per local day, the tracker against the weather-aware twin.

For each local day of ``[start, end)`` (``GET /api/v1/sites/{site_id}/diagnosis``):
the measured readings of both arrays (:func:`backend.measurements.queries.raw_rows`)
on a minute grid, the sky behind the loggers' irradiance sensors or else the fixed
array's power, and both arrays' expected power under it
(:func:`sim.sky_sensor.weather_aware_twin`), then energy,
performance ratio, gains and the day's fault features
(:func:`backend.diagnosis.faults.judged_features`). Each day's result is cached in
``diagnosis_days`` (written through the one writer) and deleted by the writer when
readings of that day arrive, and ignored when it was computed by another version of this
code (:data:`CACHE_VERSION`) or under another config of the site (:func:`site_key`); the
faults across days (``since``, steps) are recomputed from the cached days on every
request. A day not yet over (``complete`` false: today, or a day to come) is judged on its
minutes before now only — the minutes still to come are not missing readings — with no
shape fault (half a day does not show one), and it is never stored in ``diagnosis_days``:
its answer is kept in the service's memory (``ServiceContext.diagnosis_today``, one per
site) while what it rests on is unchanged (:func:`in_progress_key`: the current minute
and the count of readings among it), so repeated reads of today do not re-run the fits.

``expected_wh_low``/``expected_wh_high``: the spread of the two decompositions of the
same POA (GTI-DIRINT, clear-sky ratio + Erbs) widened by
:data:`backend.diagnosis.faults.INVERSION_UNCERTAINTY`, or by
:data:`~backend.diagnosis.faults.GHI_UNCERTAINTY` on a day whose sky rests on a GHI
pyranometer (:func:`~backend.diagnosis.faults.band_wh`, ``band_uncertainty``).

The tracker logger's history starts at its first reading ever (:func:`history_start_s`):
minutes before it have no data and are no ``dropout``; a cached day computed with another
history start that changes its answer is computed again.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import math
import time
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson
import pandas as pd
from sqlalchemy import Connection, delete, func, insert, select

from backend.diagnosis.faults import (
    band_uncertainty,
    band_wh,
    day_expected_wh,
    faults_over_days,
    judged_features,
    judged_whole,
    shape_untested,
)
from backend.diagnosis.mount import mount_faults, read_observations
from backend.diagnosis.weather_twin import STAMP_LOOKBACK_S, site_minutes, sky_source
from backend.errors import InputError
from backend.measurements.queries import count_rows, energy_table, period_edges
from backend.sites import SiteInfo
from backend.storage.tables import SOURCE_CODES, DiagnosisDay, Measurement
from sim import sky_sensor
from sim.energy import energy_wh, gain_pct, measured_gain_pct, same_minutes
from sim.sites import Site

if TYPE_CHECKING:
    from backend.context import ServiceContext

MAX_DAYS = 400
#: Raised whenever a day's payload or the way it is computed changes: cached days of
#: another version are computed again (2: the sky from irradiance sensors; 3: ``complete``,
#: and a day not yet over judged up to now and never cached; 4: every energy by
#: :mod:`sim.energy`'s rule and a logger's minutes interpolated within its gap rule;
#: 5: no dropout before the logger's first reading, the energy against the band,
#: ``partial``; 6: the band ±4.5 % beyond the two skies, from the real-sky days; 7: the
#: measured wind speed, where a logger reads one, in the cells' temperature; 8: the stuck
#: fit's power under the site's transposition model, not Hay-Davies always; 9: a sky from a
#: GHI pyranometer alone gets its own, wider band, faults.GHI_UNCERTAINTY; 10: the beam where
#: the sun is behind or grazing the fixed plane capped by the minutes around,
#: sky_sensor._unseen_beam_capped; 11: each cached day keeps its site config's digest,
#: site_key; 12: a tracker making next to nothing gets no shape fits, faults.DEAD_SHARE; a day
#: in progress judged on its minutes so far for its measured sky too; 13: a coarse or slow
#: logger's held values are not a frozen logger, sky_sensor._stale; 14: a range that cuts
#: a day makes it ``partial``, without shape fits, and is not cached; 15: the sky's clock,
#: faults.sky_clock; 18: a slow logger's stamp convention read from its readings where the
#: site leaves the default, weather_twin.readings_stamped; 19: a shape fit needs 10 readings
#: under the sun per fitted parameter, a slow logger's readings counted by their spacing,
#: faults.SHAPE_READINGS_PER_PARAMETER: an hourly logger's day is not fitted; 20: that
#: convention read over the run and the month before it, weather_twin.STAMP_LOOKBACK_S;
#: 21: ``stuck`` also as a stop part-way through the day, faults._stopped; 22: that
#: convention read on the days the logger was slow only, sim.sky_sensor.inferred_stamped;
#: 23: the second sky's clear beam in the clear spells that readings 5 minutes apart or
#: closer show, minute by minute, sim.sky_sensor.readings_fine; 24: the expected gain over
#: the minutes of the measured one; 25: the beam where the fixed plane is blind to it, the
#: one its seen minutes make likely, and the band widened by that guess,
#: sim.sky_sensor._unseen_beam, faults.blind_beam_sd_wh; 26: the shape fits' clearness
#: gate read where the fixed plane sees the beam, ``beam_seen``; 27: ``soiling`` over a
#: week of days at least, faults.SOILING_MIN_DAYS; 28: the blind beam's spread on a minute
#: without a reading, a day without a seen minute and a run without one; u at most 1;
#: 29: the fixed array's power before a GHI pyranometer, sim.sky_sensor.weather_from_fixed;
#: 30: a day's sky source and valid share over the minutes a reading can give a sky,
#: sim.sky_sensor.measurable; 31: a dead-looking day that is the expected curve at a
#: thousandth, ``power_in_kw``, faults.KW_SCALE; 32: the day's share of the expected tracker
#: energy from minutes the sky instrument did not see the beam in, ``beam_unseen_expected_pct``,
#: and an underperformance's detail saying it; 33: the fixed array judged under a sensor's sky,
#: ``fixed_underperformance``; 34: the gains per watt of each array's rating, sim.energy.gain_pct;
#: 35: the fixed array's band without the tracker's blind beam, faults.sky_uncertainty;
#: 36: the fixed array's back-of-module temperature, sim.sky_sensor.module_air_temperature;
#: 37: where a loss lies, the arrays' voltage and current ratios, faults.electrical_ratios;
#: 38: the fixed array's IEC 61724-1 performance ratio under a POA sensor; 39: each array's
#: configured dc_loss_pct beside its energy, for a steady shortfall's advice,
#: faults._steady_loss; 40: a fixed array's readings at its inverter's limit read as at
#: least the sky that gives it, sim.sky_sensor.invert_poa).
CACHE_VERSION = 40
#: A day is ``partial`` when an array's readings cover under this share of its expected
#: energy (a logger that began or stopped that day, a dropout) [-]
PARTIAL_COVERAGE = 0.99


def history_start_s(conn: Connection, array_id: int) -> int | None:
    """The array logger's first measured reading ever [Unix s], None without one: its
    history starts there (DESIGN: sites state no commissioning date)."""
    value = conn.execute(select(func.min(Measurement.ts_s)).where(
        Measurement.array_id == array_id, Measurement.source == SOURCE_CODES["measured"])).scalar()
    return None if value is None else int(value)


def site_key(site: Site) -> str:
    """A digest of the site's whole config (``Site.to_dict``), kept with each cached day: a
    day computed under another config is computed again. ``backend.sites.drop_twin_cache``
    deletes a changed site's cached days, but a request that began under the old config can
    store its days after that, and a site file edited while the service runs is read again
    without it."""
    return hashlib.sha256(orjson.dumps(site.to_dict(),
                                       option=orjson.OPT_SORT_KEYS)).hexdigest()[:16]


def _cache_usable(payload: dict[str, Any], day_start_s: int, day_end_s: int,
                  first_s: int | None, site: str) -> bool:
    """A cached day is this version's, of the site's config as it is now (``site``,
    :func:`site_key`), and its history start gives the same answer: the start it was
    computed with and today's lie on the same side of the whole day."""
    if payload.get("cache_version") != CACHE_VERSION or payload.get("site_key") != site:
        return False
    if "history_start_s" not in payload:  # written without one (by hand): the version rules
        return True
    inf = float("inf")  # no reading yet: every day lies before the history
    old, new = payload.get("history_start_s"), first_s
    lo = min(inf if old is None else old, inf if new is None else new)
    hi = max(inf if old is None else old, inf if new is None else new)
    return lo == hi or day_end_s <= lo or day_start_s >= hi


def in_progress_key(conn: Connection, info: SiteInfo, day_s: tuple[int, int], now_s: float,
                    first_s: int | None, site: str) -> tuple[Any, ...]:
    """What the answer of a day in progress (``day_s``: its ``[start, end)`` [Unix s], as
    asked) rests on, beside the code (:data:`CACHE_VERSION`) and the site's config
    (``site``, :func:`site_key`): the tracker's history start (``first_s``), the current
    minute — the day is judged on the minutes before now, so its missing and expected
    minutes move each minute even without a reading — and the measured readings of both
    arrays from :data:`~backend.diagnosis.weather_twin.STAMP_LOOKBACK_S` before the day
    (what a slow logger's stamps mark is read there) to its end, by their count: readings
    are only ever added (``ON CONFLICT DO NOTHING``), so any new one changes it. Counted
    from the hourly rollups and the raw rows of the partial hours
    (:func:`~backend.measurements.queries.count_rows`)."""
    lo, hi = day_s[0] - STAMP_LOOKBACK_S, day_s[1] + 60
    counts = [count_rows(conn, info.arrays[name].array_id, SOURCE_CODES["measured"], lo, hi,
                         info.phase_s)[0] for name in ("tracker", "fixed")]
    return (CACHE_VERSION, site, first_s, *day_s, int(now_s // 60), *counts)


def _day_payload(info: SiteInfo, date: str, day_s: tuple[int, int], e: pd.DataFrame,
                 tracker_w: np.ndarray, fixed_w: np.ndarray,
                 measured_wh: dict[str, float | None], voltages: dict[str, np.ndarray],
                 elapsed_min: int | None = None, first_s: int | None = None,
                 cut: bool = False, spacing_s: float | None = None) -> dict[str, Any]:
    """One day's answer (without faults) and its fault features
    (:func:`backend.diagnosis.faults.judged_features`).

    ``day_s``: the day's ``[start, end)`` [s since the epoch] (``cut``: the range asked
    for covers only part of the day: it is ``partial`` and gets no shape fits, which
    need a whole day); ``e``, ``tracker_w`` and
    ``fixed_w`` hold its minutes and, when the run goes on, the next day's first minute,
    so the day's last minute is integrated up to midnight. Every energy is
    :mod:`sim.energy`'s rule: ``measured_wh`` (keyed ``tracker``/``fixed``, None without
    readings) comes from :func:`backend.measurements.queries.energy_table`, the
    ``/energy`` endpoint's own numbers; the expectations integrate the twin's minutes,
    the matched ones only the minutes the measured series covers (the minute grid is
    NaN where the gap rule bridges no reading). ``elapsed_min``: the minutes of a day not
    yet over that lie before now (None: the day is over); ``first_s``: the tracker
    logger's first reading ever [Unix s] (None: it has none) — no dropout before it;
    ``spacing_s``: the tracker's readings' median spacing [s] (the shape fits rest on its
    readings, not on the minutes interpolated between them: ``faults.day_features``).
    ``voltages``: the arrays' measured voltage on the same minutes (``tracker``, ``fixed``;
    where a loss lies, ``faults.electrical_ratios``)."""
    t0, t1 = day_s
    ts = e.index.as_unit("s").asi8
    day = ts < t1
    e_day = e[day]
    daylight = sky_sensor.measurable(e)[day]  # the minutes a reading can give a sky
    if elapsed_min is not None:  # the minutes still to come are not missing readings
        daylight[elapsed_min:] = False
    valid = e["valid"].to_numpy(bool)[day]
    share = float(valid[daylight].mean()) if daylight.any() else 0.0
    # under sky_sensor.MIN_SENSOR_SHARE of the daylight measured, the day's sky is the clear
    # sky's own GHI/DNI/DHI: the expectation is the clear-sky twin's
    source, sensor = sky_source(e_day)
    poa, clear = e["poa_global"].to_numpy()[day], e["poa_clear"].to_numpy()[day]
    k_t = float(poa[daylight].sum() / clear[daylight].sum()) if daylight.any() else None
    exp = day_expected_wh(e, day_s, tracker_w, fixed_w)
    exp_a, exp_b, exp_fixed = exp.tracker, exp.tracker_alt, exp.fixed
    matched, matched_f = exp.tracker_matched, exp.fixed_matched
    measured_tr, measured_fx = measured_wh["tracker"], measured_wh["fixed"]
    # the logger's history: its minutes before the first reading are not missing
    first_min = 1440 if first_s is None else max(0, -(-(first_s - t0) // 60))
    features = judged_features(info.site, e, day_s, tracker_w, fixed_w, voltages, measured_wh,
                               exp, first_min, spacing_s, elapsed_min, cut)
    ratios = features["electrical"]
    unseen_pct = features.get("beam_unseen_pct")
    # IEC 61724-1's performance ratio of the fixed array (its final yield over the reference
    # yield of the POA sensor in its plane), model-free, on the minutes both read validly
    seen = e_day["valid"].to_numpy(bool) & (e_day["sky_source"].to_numpy() == "sensor_poa") \
        & np.isfinite(fixed_w[day])
    poa_sum = float(e_day["poa_global"].to_numpy()[seen].sum())  # W m⁻² × minutes
    whole = judged_whole(e_day, elapsed_min, cut)
    iec_pr = None if not whole or seen.sum() < 60 or poa_sum <= 0 else float(
        fixed_w[day][seen].sum() / (info.site.arrays["fixed"].stc_power_w * poa_sum / 1000.0))
    low, high = band_wh(exp_a, exp_b, band_uncertainty(e_day))
    # readings that miss part of the day's expected energy: its gain is not the day's (a
    # day without any reading has no measured gain at all: not partial, no data)
    short = any(m is not None and x > 0 and got < PARTIAL_COVERAGE * x
                for m, got, x in ((measured_tr, matched, exp_a), (measured_fx, matched_f,
                                                                  exp_fixed)))
    both = np.isfinite(tracker_w) & np.isfinite(fixed_w)  # the minutes both loggers cover
    shared = [energy_wh(ts, np.where(both, e[c].to_numpy(), np.nan), 60, t0, t1)
              for c in ("tracker_power_w", "fixed_power_w")]
    ratings_w = info.site.gain_ratings_w()
    gain_measured = measured_gain_pct(measured_tr, measured_fx,
                                      same_minutes([matched, matched_f], shared), ratings_w)
    # the gain expected beside a measured one is the twin's over the same minutes (the
    # /energy rule, twin_matched_gain_pct): both loggers silent 12:00-15:00 on a clear
    # April day at Tehuantepec read 49.8 % measured beside the whole day's 32.4 % (a
    # tester's finding); with no measured gain, the whole day's
    gain_expected = gain_pct(shared[0], shared[1], ratings_w) \
        if gain_measured is not None and both.any() \
        else gain_pct(exp_a, exp_fixed, ratings_w)
    return {
        "date": date,
        "complete": elapsed_min is None,
        "partial": elapsed_min is not None or short or cut,
        "sky": {"clearness_index": None if k_t is None else round(k_t, 4), "source": source,
                "sensor": sensor, "valid_minutes_pct": round(100.0 * share, 1),
                "beam_unseen_expected_pct": unseen_pct},
        "tracker": {
            "measured_wh": measured_tr, "expected_wh": exp_a,
            "expected_wh_low": low, "expected_wh_high": high,
            "performance_ratio": None if measured_tr is None or matched <= 0
            else measured_tr / matched, **(ratios["tracker"] or {})},
        "fixed": {"measured_wh": measured_fx, "expected_wh": exp_fixed,
                  "performance_ratio": None if measured_fx is None or matched_f <= 0
                  else measured_fx / matched_f, "iec_performance_ratio": iec_pr,
                  **(ratios["fixed"] or {})},
        "gain_measured_pct": gain_measured,
        "gain_expected_pct": gain_expected,
        "features": features,
        "history_start_s": first_s,
    }


def _compute(ctx: ServiceContext, info: SiteInfo, edges: list[dt.datetime],
             uncached_days: list[int], now_s: float, first_s: int | None
             ) -> dict[int, dict[str, Any]]:
    """Payloads of the days ``uncached_days`` (indices into ``edges``), run by contiguous
    stretches;
    days ending after ``now_s`` [s since the epoch] are judged up to it; ``first_s``: the
    tracker logger's first reading (:func:`history_start_s`)."""
    if not info.has_twin():
        raise InputError(422, f"site {info.site_id!r}: the diagnosis needs arrays named "
                              "'tracker' (mount tracker) and 'fixed' (mount fixed), the ones "
                              f"the twin simulates; it has {sorted(info.arrays)}")
    tracker, fixed = info.arrays["tracker"], info.arrays["fixed"]
    out: dict[int, dict[str, Any]] = {}
    runs: list[list[int]] = []
    for i in uncached_days:
        if runs and runs[-1][-1] == i - 1:
            runs[-1].append(i)
        else:
            runs.append([i])
    edges_s = np.array([int(x.timestamp()) for x in edges], np.int64)
    for run in runs:
        t0, t1 = int(edges_s[run[0]]), int(edges_s[run[-1] + 1])
        with ctx.engine.connect() as conn:
            table = energy_table(conn, [tracker.array_id, fixed.array_id],
                                 edges_s[run[0]:run[-1] + 2], info.phase_s,
                                 ctx.settings.ingest.energy_max_gap_s)
        # one minute past the run, so the last day's last minute reaches midnight
        tr, fx, sensors, tr_spacing, fine, volts = site_minutes(ctx, info, t0, t1 + 60)
        gap = ctx.settings.ingest.energy_max_gap_s
        start = pd.Timestamp(t0, unit="s", tz="UTC")
        e = sky_sensor.weather_aware_twin(info.site, start, start + pd.Timedelta(
            seconds=(t1 + 60 - t0) // 60 * 60), fx, sensors=sensors,
            now=pd.Timestamp(now_s, unit="s", tz="UTC") if t1 > now_s else None, fine=fine)
        for j, i in enumerate(run):
            day_start_s, day_end_s = int(edges_s[i]), int(edges_s[i + 1])
            a, b = (day_start_s - t0) // 60, (day_end_s - t0) // 60 + 1
            measured = {kind: float(table.energy_wh[(arr.array_id, 0)][j])
                        if table.readings[(arr.array_id, 0)][j] else None
                        for kind, arr in (("tracker", tracker), ("fixed", fixed))}
            date = edges[i].astimezone(info.zone).date().isoformat()
            elapsed = None if day_end_s <= now_s else max(0, int(now_s - day_start_s) // 60)
            out[i] = _day_payload(info, date, (day_start_s, day_end_s), e.iloc[a:b], tr[a:b],
                                  fx[a:b], measured, {k: v[a:b] for k, v in volts.items()},
                                  elapsed, first_s,
                                  cut=not _whole_day(edges[i], edges[i + 1], info.zone),
                                  spacing_s=tr_spacing)
            if tr_spacing is not None and tr_spacing > gap:  # its readings bridge nothing
                out[i]["features"]["slow_logger"] = {"spacing_s": tr_spacing, "max_gap_s": gap}
    return out


#: Without a token, a request computes at most this many days that are not cached yet
#: (each a day of minutes of the sky inversion, the twin and the fault fits); more is a 422
#: naming ``end``. A month: 31 realistic days of both arrays measured 3.8 s of CPU and a
#: 42 MB peak of Python allocation in process (31 days without readings, the clear-sky
#: twin: 0.8 s, 42 MB; load 7-9), far under issue 23's minute of CPU and gigabyte. Cached
#: days and days to come cost nothing and do not count.
ANONYMOUS_MAX_COMPUTED_DAYS = 31


def computed_days_cap(caller: object | None) -> int | None:
    """The most uncached days a request may diagnose: :data:`ANONYMOUS_MAX_COMPUTED_DAYS`
    without a token (``caller`` None), no bound with one."""
    return None if caller is not None else ANONYMOUS_MAX_COMPUTED_DAYS


def _whole_day(start: dt.datetime, end: dt.datetime, zone: dt.tzinfo) -> bool:
    """Whether ``[start, end)`` is a whole local day: from a midnight to the next."""
    def midnight(d: dt.date) -> float:  # as period_edges makes it (a missing one too)
        return dt.datetime(d.year, d.month, d.day, tzinfo=zone).timestamp()

    day = start.astimezone(zone).date()
    return (start.timestamp() == midnight(day)
            and end.timestamp() == midnight(day + dt.timedelta(days=1)))


def _future_day(date: str) -> dict[str, Any]:
    """The answer of a day still to come: nothing is computed (no reading can exist yet)."""
    return {"date": date, "status": "future", "complete": False, "partial": True,
            "sky": {"clearness_index": None, "source": "none", "sensor": None,
                    "valid_minutes_pct": 0.0, "beam_unseen_expected_pct": None},
            "tracker": {"measured_wh": None, "expected_wh": None, "expected_wh_low": None,
                        "expected_wh_high": None, "performance_ratio": None},
            "fixed": {"measured_wh": None, "expected_wh": None, "performance_ratio": None},
            "gain_measured_pct": None, "gain_expected_pct": None, "faults": []}


def diagnosis(ctx: ServiceContext, info: SiteInfo, start: dt.datetime,
              end: dt.datetime, now_s: float | None = None,
              max_computed_days: int | None = None) -> dict[str, Any]:
    """The diagnosis answer of DESIGN.md for a validated range; ``now_s`` [s since the
    epoch] (default: the clock) ends the days not yet over.

    Each day has a ``status``: ``complete`` (over), ``in_progress`` (today: judged on its
    minutes so far) or ``future`` (it starts after now: answered without computing anything,
    its numbers null). ``max_computed_days``: the most days not cached yet this request may
    compute (None: no bound), else :class:`InputError` 422 naming ``end``. ``mount``: the
    mount faults from the tracker camera's offsets in the range
    (:func:`backend.diagnosis.mount.mount_faults`), null without camera observations."""
    now = time.time() if now_s is None else now_s
    if (end - start).total_seconds() > (MAX_DAYS + 1) * 86400:
        raise InputError(422, f"end: the range spans over {MAX_DAYS} days; ask for less")
    edges = period_edges(start, end, "day", info.zone)
    starts = [int(e.timestamp()) for e in edges[:-1]]
    edges_s = [int(e.timestamp()) for e in edges]
    dates = [e.astimezone(info.zone).date().isoformat() for e in edges[:-1]]
    future = [s >= now for s in starts]
    past = [s for s, f in zip(starts, future, strict=True) if not f]
    tracker = info.array_of_kind("tracker")
    with ctx.engine.connect() as conn:
        rows = conn.execute(select(DiagnosisDay.day_start_s, DiagnosisDay.day_end_s,
                                   DiagnosisDay.payload_json).where(
            DiagnosisDay.site_id == info.site_id,
            DiagnosisDay.day_start_s.in_(past))).all() if past else []
        first_s = None if tracker is None or not past else history_start_s(
            conn, tracker.array_id)
        obs = read_observations(conn, info, edges_s[0], min(edges_s[-1], math.ceil(now)))
        key = site_key(info.site)
        # a day in progress (today) is kept in memory, one per site, while what it rests on
        # is unchanged: a reading, the next minute or another config computes it again
        progress = {i: in_progress_key(conn, info, (edges_s[i], edges_s[i + 1]), now,
                                       first_s, key)
                    for i in range(len(starts)) if not future[i] and edges_s[i + 1] > now
                    and info.has_twin()}
    held = ctx.diagnosis_today.get(info.site_id)
    cached = {r[0]: p for r in rows
              if r[1] == int(edges[starts.index(r[0]) + 1].timestamp())
              and _cache_usable(p := orjson.loads(r[2]), r[0], r[1], first_s, key)}
    cached.update({starts[i]: orjson.loads(held[1]) for i, k in progress.items()
                   if held is not None and held[0] == k})
    # only days that are over are cached; days to come are not computed
    uncached_days = [i for i, s in enumerate(starts) if s not in cached and not future[i]]
    if max_computed_days is not None and len(uncached_days) > max_computed_days:
        raise InputError(422, f"end: the range holds {len(uncached_days)} days not computed "
                              f"yet; without a token a request computes at most "
                              f"{max_computed_days} (ask for less, or send 'Authorization: "
                              "Bearer <token>')")
    fresh = _compute(ctx, info, edges, uncached_days, now, first_s) if uncached_days else {}
    for i, k in progress.items():
        if i in fresh:
            ctx.diagnosis_today[info.site_id] = (k, orjson.dumps(fresh[i]))
    values = [{"site_id": info.site_id, "day_start_s": starts[i],
               "day_end_s": int(edges[i + 1].timestamp()),
               "payload_json": orjson.dumps({**p, "cache_version": CACHE_VERSION,
                                             "site_key": key}).decode()}
              for i, p in fresh.items()
              if p["complete"] and _whole_day(edges[i], edges[i + 1], info.zone)]
    if values:

        def store(conn: Connection) -> None:
            conn.execute(delete(DiagnosisDay).where(
                DiagnosisDay.site_id == info.site_id,
                DiagnosisDay.day_start_s.in_([v["day_start_s"] for v in values])))
            conn.execute(insert(DiagnosisDay), values)

        ctx.writer.call(store).result()
    days = [fresh[i] if i in fresh else cached[s] for i, s in enumerate(starts)
            if not future[i]]
    found = faults_over_days(days)
    out_days = []
    for d, f in zip(days, found, strict=True):
        untested = shape_untested(d.get("features") or {})
        d = {k: v for k, v in d.items()
             if k not in ("features", "cache_version", "site_key", "history_start_s")}
        d.setdefault("partial", not d.get("complete", True))
        d["status"] = "complete" if d.get("complete", True) else "in_progress"
        d["faults"] = f
        d["shape_untested"] = untested
        out_days.append(d)
    out_days += [_future_day(dates[i]) for i in range(len(starts)) if future[i]]
    return {"site_id": info.site_id, "timezone": info.site.timezone,  # both in the site's
            "start": start.astimezone(info.zone).isoformat(),  # zone (start came back in UTC)
            "end": end.astimezone(info.zone).isoformat(), "days": out_days,
            "mount": mount_faults(obs, edges_s, dates)}
