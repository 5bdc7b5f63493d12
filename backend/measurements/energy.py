"""Energy per local hour, day or month of a site, measured beside the twin.

Periods are the site's local calendar hours/days/months clipped to ``[start, end)``;
energy comes from the hourly rollups (:mod:`backend.measurements.queries`, the
rule of :mod:`backend.measurements.rollups`), the twin's from series stored on
demand (``TwinService.ensure``). ``gain_pct`` is ``100·(tracker/fixed − 1)`` from
measured energy, null when either is missing or their readings cover the period unalike
(:func:`sim.energy.measured_gain_pct`); ``twin_gain_pct`` the same from the twin,
``twin_matched_gain_pct`` from the twin over the minutes both loggers' readings cover
(``twin_shared_wh``; null where they share none, ``gain_note`` says why). A
period whose readings miss part of the twin's energy (a half-day) is ``partial``
and is compared with ``twin_matched_wh``, never with the whole-period twin.
"""

from __future__ import annotations

import datetime as dt
import threading
from collections import OrderedDict
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from backend.errors import InputError
from backend.measurements.queries import (
    energy_table,
    matched_twin_wh,
    period_edges,
    shared_minutes_wh,
)
from backend.sites import SiteInfo
from sim.energy import SAME_MINUTES, gain_pct, measured_gain_pct, same_minutes

if TYPE_CHECKING:
    from backend.context import ServiceContext

MAX_PERIODS = 50_000
_SHORTEST_S = {"hour": 3600.0, "day": 82800.0, "month": 28 * 86400.0}  # DST days: 23 h


#: A period whose readings cover less of the twin's energy than this is ``partial`` [%].
PARTIAL_BELOW_PCT = 95.0
#: Why a period whose twin made no energy has no twin gain (a polar night, a night hour; a
#: tester's Svalbard December read ``twin_gain_pct`` and ``twin_note`` both null)
NO_SUN_NOTE = "no sun: the twin made no energy over the period (the sun stayed below the horizon)"
#: Per array of a period: its twin over the minutes its own readings cover, and over those
#: both loggers' readings cover (:func:`backend.measurements.queries.shared_minutes_wh`);
#: summed like the energies. Whether the two read the same minutes:
#: :func:`sim.energy.same_minutes`
COVERED, SHARED = "twin_covered_wh", "twin_shared_wh"
#: Where each array's readings cover at least this share of its twin's energy [%], the two
#: loggers are taken to read the same minutes without reading them (:func:`_coverage`):
#: what either misses is then under half the same-minutes tolerance
#: (:data:`sim.energy.SAME_MINUTES`). It was :data:`PARTIAL_BELOW_PCT`: a fixed logger
#: silent since 12:25 beside a tracker read on to 12:31 (3 % of the day so far, not
#: partial) gave a gain of +39.5 % beside the twin's +35.4 % (a tester's finding).
SAME_WITHOUT_READING_PCT = 100.0 * (1.0 - SAME_MINUTES / 2)


def _ratio(num: float | None, den: float | None) -> float | None:
    return None if num is None or den is None or den <= 0 else num / den


def compare(arrays: dict[str, dict[str, Any]], tracker: str | None,
            fixed: str | None, ratings_w: tuple[float, float] | None = None) -> dict[str, Any]:
    """Per array: coverage and performance ratio; per period: partial flag and gains
    (``ratings_w``: the two arrays' STC ratings, :func:`sim.energy.gain_pct`)."""
    for a in arrays.values():
        a["performance_ratio"] = _ratio(a["measured_wh"], a["twin_matched_wh"])
        cov = _ratio(a["twin_matched_wh"], a["twin_wh"]) if a["readings"] else None
        a["coverage_pct"] = None if cov is None else min(100.0, 100.0 * cov)
    # an array without a reading covers none of a positive twin: a day the fixed logger
    # was silent beside the tracker's was partial null (an empty cell in the report's CSV)
    covs: list[float | None] = [
        a["coverage_pct"] if a["readings"] else 0.0 if (a["twin_wh"] or 0.0) > 0 else None
        for a in arrays.values()]
    known = [c for c in covs if c is not None]
    out: dict[str, Any] = {
        "partial": None if not arrays or len(known) < len(covs)
        or not any(a["readings"] for a in arrays.values()) else min(known) < PARTIAL_BELOW_PCT,
        "gain_pct": None, "twin_gain_pct": None, "twin_matched_gain_pct": None}
    out["gain_note"] = None
    if tracker is not None and fixed is not None:
        tr, fx = arrays[tracker], arrays[fixed]
        same = same_minutes([tr.get(COVERED), fx.get(COVERED)],
                            [tr.get(SHARED), fx.get(SHARED)])
        out["gain_pct"] = measured_gain_pct(tr["measured_wh"], fx["measured_wh"], same,
                                            ratings_w)
        out["twin_gain_pct"] = gain_pct(tr["twin_wh"], fx["twin_wh"], ratings_w)
        # the twin over the minutes BOTH loggers cover (one rule with the measured gain):
        # each array's twin over its own minutes read a tracker's day beside a fixed
        # array's silent one as +167 % (a tester's finding)
        out["twin_matched_gain_pct"] = gain_pct(tr.get(SHARED), fx.get(SHARED), ratings_w)
        if out["gain_pct"] is None:
            out["gain_note"] = _gain_note(tr, fx, same)
    return out


def _gain_note(tr: dict[str, Any], fx: dict[str, Any], same: bool | None) -> str:
    """Why a period has no measured gain (and, for want of shared minutes, no
    ``twin_matched_gain_pct``): every empty gain says why."""
    def which(test: Any) -> str:  # "the tracker has", "the tracker and the fixed array have"
        names = [what for what, a in (("the tracker", tr), ("the fixed array", fx)) if test(a)]
        return " and ".join(names) + (" have" if len(names) > 1 else " has") if names else ""

    if missing := which(lambda a: a["measured_wh"] is None):
        return missing + " no readings: the loggers share no minutes"
    # readings came, but none within the gap of the next: no minute counted
    if unbridged := which(lambda a: a["readings"] and a.get("coverage_pct") == 0.0):
        return (unbridged + " readings but none within max_gap_s of the next: the energy "
                "rule counts no minute between them (raise HELIOTWIN_ENERGY_MAX_GAP_S to the "
                "logger's interval and restart)")
    if same is False:
        return (f"the two loggers read different minutes: of the minutes each covers, both "
                f"cover {_share(tr)} of the tracker's expected energy and {_share(fx)} of the "
                f"fixed array's")
    return "the fixed array measured no energy"


def _share(a: dict[str, Any]) -> str:
    covered = a.get(COVERED) or 0.0
    return "all" if covered <= 0 else f"{100.0 * (a.get(SHARED) or 0.0) / covered:.0f} %"


def _coverage(conn: Any, table: Any, matched: dict[int, np.ndarray], tracker_id: int,
              fixed_id: int, edges_s: np.ndarray, gap: int, database: str
              ) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Per array, its twin over the minutes its readings cover and over those both cover,
    per period (:func:`backend.measurements.queries.shared_minutes_wh`). Read only for a
    period where an array's readings cover under :data:`SAME_WITHOUT_READING_PCT` of its
    twin's energy (a partial one, a logger silent for some minutes, a day in progress
    whose logger stopped: its twin is stored up to now): in any other both loggers read
    all but a few minutes' worth, taken as the same
    (both: ``twin_matched_wh``; reading a year of gappy months at 1 % cost 15× the
    year's answer, a tester measured); one where a logger has no reading has none in
    common (a gain is not measured there anyway). Read periods are cached like
    :func:`_matched`'s."""
    ids = (tracker_id, fixed_id)
    has = {aid: np.asarray(table.readings[(aid, 0)]) > 0 for aid in ids}
    full = np.ones(edges_s.size - 1, bool)
    for aid in ids:
        twin = np.asarray(table.energy_wh[(aid, 1)], float)
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(twin > 0, np.asarray(matched[aid], float) / twin, 1.0)
        full &= share >= SAME_WITHOUT_READING_PCT / 100.0
    both = has[tracker_id] & has[fixed_id]
    out = {aid: (np.array(matched[aid], float), np.where(both, matched[aid], 0.0))
           for aid in ids}
    uncached, keys = [], {}
    for p in np.flatnonzero(both & ~full).tolist():  # read once, then cached like _matched
        key = _period_key(table, ids, edges_s, p, gap, database, "shared")
        if key is not None and (hit := _MATCHED.get(key)) is not None:
            for j, aid in enumerate(ids):
                out[aid][0][p], out[aid][1][p] = hit[2 * j], hit[2 * j + 1]
            continue
        keys[p] = key
        uncached.append(p)
    if uncached:
        read = shared_minutes_wh(conn, ids, edges_s, gap, np.array(uncached, np.int64))
        for p in uncached:
            for aid in ids:
                for k in (0, 1):
                    out[aid][k][p] = read[aid][k][p]
            if (key := keys[p]) is not None:
                _MATCHED.put(key, tuple(float(out[aid][k][p]) for aid in ids for k in (0, 1)))
    return out


def _period_key(table: Any, array_ids: Sequence[int], edges_s: np.ndarray, p: int, gap: int,
                database: str, what: str) -> tuple[Any, ...] | None:
    """What decides a period's values read from raw minutes (:class:`_MatchedCache`): the
    database, the arrays, the period's edges, the gap, and the readings and energy of both
    sources of each array in the period and the periods on either side; None for the first
    and last period, whose outer neighbours are unknown."""
    if not 0 < p < edges_s.size - 2:
        return None
    around = slice(p - 1, p + 2)
    return (what, database, *array_ids, int(edges_s[p]), int(edges_s[p + 1]), gap,
            *(v for aid in array_ids for src in (0, 1)
              for v in (*table.readings[(aid, src)][around].tolist(),
                        *table.energy_wh[(aid, src)][around].tolist())))


class _MatchedCache:
    """``twin_matched_wh`` (and the two loggers' shared minutes, :func:`_coverage`) of
    periods already computed from raw minutes, by what decides it (:func:`_period_key`):
    the database, the arrays, the period's edges, and the readings and energy of both
    sources in the period and in the periods on either side (the energy rule reaches
    ``max_gap_s`` ≤ an hour past a period's edges). Stored readings never change (a
    re-sent one is a duplicate), they are only added or deleted, and either changes a
    count or an energy of the key: a period read again unchanged costs no raw minutes.
    Bounded (oldest entries dropped first)."""

    def __init__(self, size: int = 20_000) -> None:
        self.size = size
        self._data: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: tuple[Any, ...]) -> Any:
        with self._lock:
            value = self._data.get(key)
            if value is not None:
                self._data.move_to_end(key)
            return value

    def put(self, key: tuple[Any, ...], value: Any) -> None:
        with self._lock:
            self._data[key] = value
            while len(self._data) > self.size:
                self._data.popitem(last=False)


_MATCHED = _MatchedCache()


def _matched(conn: Any, table: Any, array_id: int, edges_s: np.ndarray, gap: int,
             database: str) -> np.ndarray:
    """``twin_matched_wh`` per period: where the logger and the twin both have a reading
    in every minute of the period the minutes are the same, and the matched twin is the
    twin's energy from the rollups; raw minutes are read only for the other periods not
    in :data:`_MATCHED` (and for the first and last, whose outer neighbours are unknown)."""
    m_n, t_n = table.readings[(array_id, 0)], table.readings[(array_id, 1)]
    t_wh = table.energy_wh[(array_id, 1)]
    minutes = np.round(np.diff(edges_s) / 60.0).astype(np.int64)
    complete = (m_n == minutes) & (t_n == minutes)
    out = np.where(complete, t_wh, 0.0)
    rest = np.flatnonzero(~complete & (m_n > 0) & (t_n > 0)).tolist()
    keys: dict[int, tuple[Any, ...]] = {}
    uncached = []
    for p in rest:
        key = _period_key(table, (array_id,), edges_s, p, gap, database, "matched")
        if key is not None:
            keys[p] = key
            if (hit := _MATCHED.get(key)) is not None:
                out[p] = hit
                continue
        uncached.append(p)
    computed = matched_twin_wh(conn, array_id, edges_s, gap, np.array(uncached, np.int64))
    for p in uncached:
        out[p] = computed[p]
        if p in keys:
            _MATCHED.put(keys[p], float(computed[p]))
    return out


def energy_rows(ctx: ServiceContext, info: SiteInfo, start: dt.datetime, end: dt.datetime,
                interval: str) -> dict[str, Any]:
    """The energy answer for a validated range (the energy endpoint, status tiles, reports).

    Per period and array: ``measured_wh``, ``twin_wh`` (the whole period),
    ``twin_matched_wh`` (the twin over only the minutes with a measured reading,
    :func:`backend.measurements.queries.matched_twin_wh`), ``coverage_pct`` (that
    share of ``twin_wh``), ``performance_ratio`` (``measured_wh / twin_matched_wh``:
    measured over the clear-sky twin's expectation, the same minutes). Per period:
    ``partial`` (some array's coverage under :data:`PARTIAL_BELOW_PCT`),
    ``twin_matched_gain_pct`` and ``twin_note`` (why there is no twin, or null).
    """
    site_id = info.site_id
    at_least = (end - start).total_seconds() / _SHORTEST_S[interval]
    if at_least > MAX_PERIODS + 2:  # before building millions of period edges
        raise InputError(422, f"over {int(at_least)} periods of one {interval}; the limit is "
                                 f"{MAX_PERIODS}: use a longer interval or a shorter range")
    edges = period_edges(start, end, interval, info.zone)
    if len(edges) - 1 > MAX_PERIODS:
        raise InputError(422, f"{len(edges) - 1} periods of one {interval}; the limit is "
                                 f"{MAX_PERIODS}: use a longer interval or a shorter range")
    edges_s = np.array([int(e.timestamp()) for e in edges], np.int64)
    ctx.twin.ensure(site_id, int(edges_s[0]), int(edges_s[-1]))
    names = list(info.arrays)
    ids = [info.arrays[n].array_id for n in names]
    gap = ctx.settings.ingest.energy_max_gap_s
    tracker = info.array_of_kind("tracker")
    fixed = info.array_of_kind("fixed")
    tr_name = tracker.name if tracker is not None else None
    fx_name = fixed.name if fixed is not None else None
    ratings_w = info.site.gain_ratings_w(tr_name, fx_name)
    with ctx.engine.connect() as conn:
        table = energy_table(conn, ids, edges_s, info.phase_s, gap)
        database = ctx.engine.url.render_as_string(hide_password=True)
        matched = {aid: _matched(conn, table, aid, edges_s, gap, database) for aid in ids}
        coverage = (None if tracker is None or fixed is None else
                    _coverage(conn, table, matched, tracker.array_id, fixed.array_id,
                              edges_s, gap, database))
    rows = []
    sums = {n: {"measured_wh": 0.0, "twin_wh": 0.0, "twin_matched_wh": 0.0, "readings": 0,
                "twin_readings": 0} for n in names}
    cover_sums = {n: [0.0, 0.0] for n in names}
    for p in range(len(edges) - 1):
        arrays: dict[str, dict[str, Any]] = {}
        for n, aid in zip(names, ids, strict=True):
            m_n = int(table.readings[(aid, 0)][p])
            t_n = int(table.readings[(aid, 1)][p])
            m_wh = float(table.energy_wh[(aid, 0)][p])
            t_wh = float(table.energy_wh[(aid, 1)][p])
            mt_wh = float(matched[aid][p])
            # measured: a reading in the period, or one bridged across it (a 15-min
            # logger's 10:50–11:00 holds none, yet the totals counted its 100 Wh while the
            # row said null; a tester's finding)
            measured = bool(m_n) or m_wh != 0.0 or mt_wh != 0.0
            arrays[n] = {"measured_wh": m_wh if measured else None,
                         "twin_wh": t_wh if t_n else None,
                         "twin_matched_wh": mt_wh if measured and t_n else None,
                         "readings": m_n}
            for key, value in (("measured_wh", m_wh), ("twin_wh", t_wh),
                               ("twin_matched_wh", mt_wh), ("readings", m_n),
                               ("twin_readings", t_n)):
                sums[n][key] += value
        if coverage is not None:
            for n, aid in zip(names, ids, strict=True):
                if aid in coverage and arrays[n]["twin_wh"] is not None:
                    for k, key in enumerate((COVERED, SHARED)):
                        arrays[n][key] = float(coverage[aid][k][p])
                        cover_sums[n][k] += arrays[n][key]
        compared = compare(arrays, tr_name, fx_name, ratings_w)
        no_twin = any(a["twin_wh"] is None for a in arrays.values()) or not arrays
        rows.append({
            "period_start": edges[p].astimezone(info.zone).isoformat(),
            "period_end": edges[p + 1].astimezone(info.zone).isoformat(),
            "arrays": arrays, **compared,
            "twin_note": ctx.twin.no_twin_reason(site_id, int(edges_s[p]), int(edges_s[p + 1]))
            if no_twin else NO_SUN_NOTE if compared["twin_gain_pct"] is None
            and not any(a["twin_wh"] for a in arrays.values()) else None,
        })
    totals = {n: {"measured_wh": t["measured_wh"] if t["readings"] else None,
                  "twin_wh": t["twin_wh"] if t["twin_readings"] else None,
                  "twin_matched_wh": t["twin_matched_wh"]
                  if t["readings"] and t["twin_readings"] else None,
                  "readings": t["readings"]} for n, t in sums.items()}
    if coverage is not None:
        for n, aid in zip(names, ids, strict=True):
            if aid in coverage and totals[n]["twin_wh"] is not None:
                totals[n][COVERED], totals[n][SHARED] = cover_sums[n]
    return {
        "site_id": site_id, "interval": interval, "timezone": info.site.timezone,
        # in the site's zone, as the periods (an offset given in the range read back in UTC)
        "start": start.astimezone(info.zone).isoformat(),
        "end": end.astimezone(info.zone).isoformat(),
        "max_gap_s": gap, "partial_below_pct": PARTIAL_BELOW_PCT,
        "rows": rows, "totals": {"arrays": totals, **compare(totals, tr_name, fx_name, ratings_w)},
    }
