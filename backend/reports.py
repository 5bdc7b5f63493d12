"""Reports of a site over a date range: totals, monthly and annual tables, CSV, a one-page PNG.

Everything comes from :func:`backend.measurements.energy.energy_rows` (the same
numbers as the energy endpoint and the Overview): per local day, month and year
the measured energy, the clear-sky twin's, the twin over the same minutes as the
readings (``twin_matched_wh``), the tracking gain measured and expected, and the
performance ratio ``measured_wh / twin_matched_wh`` (measured over the clear-sky
twin over the same minutes; it is below 1 on cloudy days, by design: the loggers
record no irradiance, so IEC 61724's reference yield is not available).

The PNG (matplotlib, Agg backend) is an A4 page at 150 dpi a researcher can put
in a paper: a header with the site and range, the totals table, the daily
energy chart with the gain, and the monthly (or annual) table.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import textwrap
from typing import TYPE_CHECKING, Any

from backend.errors import InputError
from backend.measurements.energy import COVERED, SHARED, compare, energy_rows
from backend.sites import SiteInfo

if TYPE_CHECKING:
    from backend.context import ServiceContext

#: Longest range a report covers [days] (its daily chart has one bar per day).
MAX_REPORT_DAYS = 3700
_SUMMED = ("measured_wh", "twin_wh", "twin_matched_wh", "readings", COVERED, SHARED)


def _by_year(months: list[dict[str, Any]], names: list[str], tracker: str | None,
             fixed: str | None, ratings_w: tuple[float, float] | None
             ) -> list[dict[str, Any]]:
    """Monthly rows summed into local calendar years (null stays null when no month had it)."""
    years: dict[str, dict[str, Any]] = {}
    for row in months:
        year = row["period_start"][:4]
        y = years.setdefault(year, {"period_start": row["period_start"], "arrays": {
            n: dict.fromkeys(_SUMMED) for n in names}, "notes": set()})
        y["period_end"] = row["period_end"]
        if row.get("twin_note"):
            y["notes"].add(row["twin_note"])
        for n in names:
            for k in _SUMMED:
                v = row["arrays"][n].get(k)
                if v is not None:
                    y["arrays"][n][k] = (y["arrays"][n][k] or 0) + v
    out = []
    for y in years.values():
        notes = sorted(y.pop("notes"))
        out.append({**y, **compare(y["arrays"], tracker, fixed, ratings_w),
                    "twin_note": "; ".join(notes) or None})
    return out


def report(ctx: ServiceContext, info: SiteInfo, start: dt.datetime,
           end: dt.datetime) -> dict[str, Any]:
    """Totals, days, months and years of ``[start, end)`` for the site."""
    if (end - start).total_seconds() > MAX_REPORT_DAYS * 86400:
        raise InputError(422, f"end: a report covers at most {MAX_REPORT_DAYS} days")
    days = energy_rows(ctx, info, start, end, "day")
    months = energy_rows(ctx, info, start, end, "month")
    tracker = info.array_of_kind("tracker")
    fixed = info.array_of_kind("fixed")
    tr_name = tracker.name if tracker is not None else None
    fx_name = fixed.name if fixed is not None else None
    years = _by_year(months["rows"], list(info.arrays), tr_name, fx_name,
                     info.site.gain_ratings_w(tr_name, fx_name))
    s = info.site
    start_local, end_local = start.astimezone(info.zone), end.astimezone(info.zone)
    return {
        "site_id": s.site_id, "name": s.name, "latitude_deg": s.latitude,
        "longitude_deg": s.longitude, "timezone": s.timezone,
        # in the site's zone, as every period: a range given in UTC was titled by its UTC
        # dates and its CSV total row carried +00:00 among −06:00 rows (a tester's finding)
        "start": start_local.isoformat(), "end": end_local.isoformat(),
        "arrays": list(info.arrays),
        "readings_note": readings_note(days["totals"], start_local, end_local),
        "partial_below_pct": days["partial_below_pct"], "max_gap_s": days["max_gap_s"],
        "totals": days["totals"], "days": days["rows"], "months": months["rows"],
        "years": years,
    }


def readings_note(totals: dict[str, Any], start: dt.datetime, end: dt.datetime) -> str | None:
    """"No readings between START and END" when no array has a reading in ``[start, end)``
    (a range to come says so), else None; None for a site without arrays, which has
    nothing to read. The report's one rule for an empty range: the JSON carries it, the
    PNG draws it over its empty chart (which said nothing: a tester's finding)."""
    arrays = totals["arrays"]
    if not arrays or any(a["readings"] for a in arrays.values()):
        return None
    note = (f"No readings between {_title_time(start.isoformat())} and "
            f"{_title_time(end.isoformat())} (end exclusive)")
    return note + (": the range has not begun" if start > dt.datetime.now(dt.UTC) else "")


def _array_columns(names: list[str]) -> list[tuple[str, str]]:
    keys = ("measured_wh", "twin_wh", "twin_matched_wh", "coverage_pct", "performance_ratio")
    return [(n, k) for n in names for k in keys]


def report_csv(rep: dict[str, Any]) -> str:
    """The report's day, month, year and total rows as one CSV table (units in the names)."""
    cols = _array_columns(rep["arrays"])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["period", "period_start", "period_end", *[f"{n}_{k}" for n, k in cols],
                "gain_pct", "twin_gain_pct", "twin_matched_gain_pct", "partial", "gain_note",
                "twin_note"])
    total = {**rep["totals"], "period_start": rep["start"], "period_end": rep["end"],
             "twin_note": None}
    for kind, rows in (("day", rep["days"]), ("month", rep["months"]), ("year", rep["years"]),
                       ("total", [total])):
        for r in rows:
            arrays = r["arrays"]
            w.writerow([kind, r["period_start"], r["period_end"],
                        *[_cell(arrays[n].get(k)) for n, k in cols],
                        *[_cell(r.get(k)) for k in ("gain_pct", "twin_gain_pct",
                                                    "twin_matched_gain_pct", "partial",
                                                    "gain_note", "twin_note")]])
    return buf.getvalue()


def _cell(v: Any) -> Any:
    if v is None:
        return ""
    return round(v, 4) if isinstance(v, float) else v


def _kwh(v: float | None) -> str:
    return "—" if v is None else f"{v / 1000:.2f}"


def _pct(v: float | None) -> str:
    return "—" if v is None else f"{v:+.1f} %"


def _pr(v: float | None) -> str:
    return "—" if v is None else f"{v:.2f}"


def _title_time(iso: str) -> str:
    """A range end in the title, in the site's zone: its date at local midnight, else the
    date and time with the offset (2026-12-02 18:00 −06:00)."""
    t = dt.datetime.fromisoformat(iso)
    if t.time() == dt.time(0):
        return f"{t:%Y-%m-%d}"
    return f"{t:%Y-%m-%d %H:%M} {t:%z}"[:-2] + ":" + f"{t:%z}"[-2:]


def report_png(rep: dict[str, Any], version: str) -> bytes:
    """A one-page A4 PNG of the report (matplotlib, Agg); its ``Title`` text chunk names the
    site and range, its ``Description`` the readings note (:func:`readings_note`) if any."""
    buf = io.BytesIO()
    meta = {"Title": f"{rep['name']}: report {_title_time(rep['start'])} to "
                     f"{_title_time(rep['end'])} (end exclusive)"}
    if rep.get("readings_note"):
        meta["Description"] = rep["readings_note"]
    report_figure(rep, version).savefig(buf, format="png", metadata=meta)
    return buf.getvalue()


def report_figure(rep: dict[str, Any], version: str) -> Any:
    """The report's A4 matplotlib ``Figure`` (:func:`report_png` draws it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    import matplotlib.ticker as mticker
    from matplotlib.figure import Figure

    names = rep["arrays"]
    fig = Figure(figsize=(8.27, 11.69), dpi=150)
    start, end = _title_time(rep["start"]), _title_time(rep["end"])
    fig.text(0.06, 0.965, f"{rep['name']}", fontsize=13, weight="bold")
    fig.text(0.06, 0.948, f"site {rep['site_id']} · {rep['latitude_deg']:.4f}°, "
             f"{rep['longitude_deg']:.4f}° · {rep['timezone']} · {start} to {end} "
             "(end exclusive)", fontsize=8.5)

    t = rep["totals"]
    head = ["array", "measured [kWh]", "twin [kWh]", "twin, same\nminutes [kWh]",
            "coverage [%]", "PR [-]"]
    body = [[n, _kwh(t["arrays"][n]["measured_wh"]), _kwh(t["arrays"][n]["twin_wh"]),
             _kwh(t["arrays"][n]["twin_matched_wh"]),
             "—" if t["arrays"][n].get("coverage_pct") is None
             else f"{t['arrays'][n]['coverage_pct']:.1f}",
             _pr(t["arrays"][n].get("performance_ratio"))] for n in names]
    ax = fig.add_axes((0.06, 0.82, 0.88, 0.1))
    ax.axis("off")
    if body:
        tab = ax.table(cellText=body, colLabels=head, loc="upper left", cellLoc="center")
        tab.auto_set_font_size(False)
        tab.set_fontsize(8)
        for j in range(len(head)):
            tab[0, j].set_height(tab[0, j].get_height() * 1.8)
    else:
        ax.text(0, 0.5, "This site has no PV arrays (a camera site).", fontsize=9)
    fig.text(0.06, 0.805, f"Tracking gain: measured {_pct(t.get('gain_pct'))}; twin over the "
             f"same minutes {_pct(t.get('twin_matched_gain_pct'))}; twin, whole range "
             f"{_pct(t.get('twin_gain_pct'))}", fontsize=9)

    days = rep["days"]
    ax = fig.add_axes((0.09, 0.5, 0.8, 0.27))
    # each day's bars about its noon: centred on midnight they straddled two dates
    x = [dt.datetime.fromisoformat(r["period_start"][:10]) + dt.timedelta(hours=12)
         for r in days]
    width = 0.8 / max(1, len(names))
    colors = {"tracker": "#f5a400", "fixed": "#3b7dd8"}
    drawn: list[float] = []  # the energies the chart holds (a bar of 0 holds none)
    for i, n in enumerate(names):
        offset = (i - (len(names) - 1) / 2) * width
        xs = [mdates.date2num(v) + offset for v in x]
        m = [(r["arrays"][n]["measured_wh"] or 0) / 1000 for r in days]
        tw = [None if r["arrays"][n]["twin_wh"] is None else r["arrays"][n]["twin_wh"] / 1000
              for r in days]
        drawn += [v for v in (*m, *tw) if v]
        color = colors.get(n, "#777777")
        ax.bar(xs, m, width=width, color=color, alpha=0.8, label=f"{n} measured")
        ax.plot(xs, [float("nan") if v is None else v for v in tw], "_", ms=9, mew=2,
                color=color, label=f"{n} twin (clear sky)")
    ax.set_ylabel("Energy per day [kWh]")
    if len(days) <= 31:  # a label per day (or every few), under its bars: the automatic
        # ticks of a short range fell every 12 hours and repeated each date
        ticks = [mdates.date2num(v) for v in x][::max(1, len(days) // 10)]
        ax.xaxis.set_major_locator(mticker.FixedLocator(ticks))
    ax.xaxis.set_major_formatter(mdates.DateFormatter("%d %b %Y" if len(days) > 60 else "%d %b"))
    ax.tick_params(axis="x", labelsize=7, rotation=30)
    partial = [mdates.date2num(v) for v, r in zip(x, days, strict=True) if r.get("partial")]
    if partial:
        ax.plot(partial, [0] * len(partial), "v", color="red", ms=5, label="partial day")
    ax2 = ax.twinx()
    gains = [float("nan") if r["gain_pct"] is None else r["gain_pct"] for r in days]
    ax2.plot([mdates.date2num(v) for v in x], gains,
             "o-", color="#2e8b57", ms=3, lw=1, label="gain measured")
    ax2.set_ylabel("Tracking gain [%]")
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=7, loc="upper center",
              bbox_to_anchor=(0.5, -0.14), ncols=3, frameon=False)
    ax.set_title("Daily energy, measured (bars) and twin (ticks)", fontsize=9)
    if rep.get("readings_note"):  # said over the chart; when it holds no twin either, why
        why = [] if drawn else sorted({r["twin_note"] for r in days if r.get("twin_note")})
        said = [f"{rep['readings_note']}.", *(f"Twin: {t}." for t in why)]
        ax.text(0.5, 0.5, "\n".join(textwrap.fill(t, 90) for t in said),
                transform=ax.transAxes, ha="center", va="center", fontsize=8.5,
                bbox={"boxstyle": "round,pad=0.6", "fc": "#fff8e6", "ec": "#f5a400"})
    for axis, values in ((ax, drawn), (ax2, gains)):
        if not any(v == v for v in values):  # nothing drawn (NaN != NaN): no ±0.04 scale
            axis.set_yticks([])

    rows = rep["months"] if len(rep["months"]) <= 24 else rep["years"]
    label = "Month" if rows is rep["months"] else "Year"
    head = [label, *[f"{n}\nmeasured [kWh]" for n in names], *[f"{n}\nPR [-]" for n in names],
            "gain\nmeasured", "gain twin,\nsame minutes"]
    # a partial period marked as the dashboard's table marks it (a tester's finding)
    body = [[(r["period_start"][:7] if label == "Month" else r["period_start"][:4])
             + (" (partial)" if r.get("partial") else ""),
             *[_kwh(r["arrays"][n]["measured_wh"]) for n in names],
             *[_pr(r["arrays"][n].get("performance_ratio")) for n in names],
             _pct(r["gain_pct"]), _pct(r["twin_matched_gain_pct"])] for r in rows]
    ax = fig.add_axes((0.06, 0.1, 0.88, 0.3))
    ax.axis("off")
    ax.set_title(f"{'Monthly' if label == 'Month' else 'Annual'} table", fontsize=9, loc="left")
    if body:
        tab = ax.table(cellText=body[:24], colLabels=head, loc="upper left", cellLoc="center")
        tab.auto_set_font_size(False)
        tab.set_fontsize(7)
        for j in range(len(head)):
            tab[0, j].set_height(tab[0, j].get_height() * 1.8)
    fig.text(0.06, 0.05, (
        "Twin: heliotwin's clear-sky digital twin (pvlib Ineichen clear sky, CEC single-diode "
        "model). 'Same minutes': the twin over only the minutes\nwith a measured reading. PR = "
        "measured / twin over the same minutes (below 1 under clouds). Partial: readings cover "
        f"< {rep['partial_below_pct']:.0f} % of\nthe twin's energy. Energy: trapezoids, gaps over "
        f"{rep['max_gap_s']} s not bridged. Generated {dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} "
        f"UTC by heliotwin {version}."), fontsize=6.5, va="bottom")
    return fig
