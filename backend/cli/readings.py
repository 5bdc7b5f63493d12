"""``heliotwin readings import``: a logger's own export file posted to a running service.

The file is read as its logger wrote it (:mod:`backend.measurements.logger_file`) and
posted over HTTP as any logger posts (``POST /api/v1/sites/{site}/measurements``, the site's
write token), in batches in the file's order, each retried on a lost connection, a 429 or a
5xx. The service's checks stay the one rule: a batch it refuses stops the import, its
problems named by the file's lines. Everything before it is stored; a re-run re-sends it as
duplicates (one reading per array and second), so an import can simply be run again.
"""

from __future__ import annotations

import argparse
import contextlib
import gzip
import json
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from backend.cli import TOKEN_ENV, add_token_argument, fail

if TYPE_CHECKING:
    from backend.measurements.logger_file import LoggerFile

#: Readings a POST carries: about 1.5 MB of JSON, under the service's default body limit
#: (HELIOTWIN_MAX_UPLOAD_BYTES, 10 MB) and batch limit (HELIOTWIN_MAX_BATCH_ROWS, 100,000).
BATCH_READINGS = 10_000
#: A site whose readings_stamped is "instant" is told what a file of means this far apart
#: or more [s] needs: the diagnosis places an hourly mean stamped at its end 30 min late.
MEANS_CADENCE_S = 300.0
#: A refused batch's problems printed (the service lists up to 50, and counts the rest).
MAX_PROBLEMS_SHOWN = 5


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``readings import``."""
    p = subparsers.add_parser("readings", help="import a logger's history from its own file",
                              description="Logger history files posted to a running service.")
    sub = p.add_subparsers(dest="readings_command", metavar="ACTION", required=True)
    i = sub.add_parser(
        "import", help="post a logger's export file (TOA5, CSV, .xlsx) to a running service",
        description="Read a logger's export as it is — a Campbell TOA5 table, a CSV with ',' "
                    "or ';' (decimal commas), a portal's .xlsx workbook, ISO, M/D/Y, Y/M/D, "
                    "D.M.Y or Unix times — map its "
                    "columns to the service's fields, and post it to a site's arrays. "
                    "docs/service.md, 'Importing a logger's file'.")
    i.add_argument("file", type=Path, help="the logger's export file")
    i.add_argument("--site", required=True, help="site id")
    i.add_argument("--array", help="the site's array the file's readings are of (or "
                                    "ARRAY.FIELD in --column, for several arrays)")
    i.add_argument("--column", action="append", default=[], metavar="[ARRAY.]FIELD=NAME[:UNIT]",
                   help="map a field (power_w, voltage_v, current_a, poa_irradiance_w_m2, "
                        "ghi_w_m2, temp_module_c, temp_air_c, wind_speed_m_s, azimuth_deg, "
                        "elevation_deg, …; or instead of power, energy_wh: each interval's "
                        "energy, energy_total_wh: a meter's running total) of --array, or of "
                        "ARRAY, to the file's column, in UNIT (kW, kWh, mA, °F, km/h …) when "
                        "the file does not say it; repeat per field. With one array, a column "
                        "named as a field maps itself")
    i.add_argument("--time-column", help="the column of the times, or DATE+CLOCK for a pair "
                                         "(default: TOA5's TIMESTAMP, else the first column "
                                         "of times, with a clock column beside it)")
    i.add_argument("--timezone", help="the logger's clock, for times without a UTC offset: an "
                                      "IANA zone (America/Denver), Etc/GMT+7 for UTC−7 all "
                                      "year")
    i.add_argument("--date-order", choices=("mdy", "dmy"),
                   help="for slash dates the file cannot tell (every day ≤ 12)")
    i.add_argument("--sensors", type=Path, metavar="FILE",
                   help="a weather station's own file (POA, GHI, air and module temperature, "
                        "wind) whose values are joined to the readings by time")
    i.add_argument("--sensors-column", action="append", default=[], metavar="FIELD=NAME[:UNIT]",
                   help="map a field of the station's file (poa_irradiance_w_m2, ghi_w_m2, "
                        "temp_air_c, wind_speed_m_s, temp_module_c) to its column; repeat per "
                        "field. A column named as a field maps itself")
    i.add_argument("--sensors-array", metavar="ARRAY",
                   help="the array whose readings carry the station's values (default: "
                        "fixed, whose plane a POA sensor shares, or the only array imported)")
    i.add_argument("--sensors-timezone", metavar="ZONE",
                   help="the station's clock, for times without a UTC offset (default: "
                        "--timezone)")
    i.add_argument("--sensors-time-column", metavar="NAME",
                   help="the station's column of times, or DATE+CLOCK (default: found as for "
                        "the readings' file)")
    i.add_argument("--sensors-at-stamps", action="store_true",
                   help="join the station at the readings' stamps even where the site takes "
                        "its stamps as instants and the readings look like interval means")
    i.add_argument("--url", default="http://127.0.0.1:8000", help="service base URL")
    add_token_argument(i, "required unless --dry-run")
    i.add_argument("--dry-run", action="store_true",
                   help="read and summarise the file; post nothing")
    i.add_argument("--json", action="store_true", help="print the summary as JSON")
    i.set_defaults(func=run_import)


def _plans(args: argparse.Namespace) -> dict[str, dict[str, str]]:
    """The ``--column`` flags per array: ``FIELD=NAME[:UNIT]`` for ``--array``,
    ``ARRAY.FIELD=NAME[:UNIT]`` for any array of the site (a logger that writes the tracker's
    and the fixed array's readings in one row). A malformed or twice-mapped flag is refused."""
    plans: dict[str, dict[str, str]] = {}
    for spec in args.column:
        left, eq, name = spec.partition("=")
        array, _, fld = left.strip().rpartition(".")
        array = array or args.array
        if not eq or not fld or not name.strip():
            fail(f"--column: {spec!r} is not FIELD=NAME[:UNIT] (e.g. power_w=P_AC:kW, or "
                 "tracker.power_w=P_trk for one of several arrays)")
        if not array:
            fail(f"--column: {spec!r} names no array: give --array, or write it "
                 f"ARRAY.{fld}=…")
        if fld in plans.setdefault(array, {}):
            fail(f"--column: {array}.{fld} is mapped twice")
        plans[array][fld] = name.strip()
    if args.array:
        plans.setdefault(args.array, {})  # its columns may be named as the fields
    if not plans:
        fail("--array: name the array the file's readings are of (or map ARRAY.FIELD columns)")
    return plans


def run_import(args: argparse.Namespace) -> int:
    """Read, summarise and (unless ``--dry-run``) post the file, array by array."""
    import httpx

    from backend.measurements.logger_file import read_logger_file

    if not args.dry_run and not args.token:
        fail(f"--token: the site's write token is required to post (or set {TOKEN_ENV}, or "
             "--dry-run)")
    if not args.file.is_file():
        fail(f"file: {args.file} is not a file")
    plans = _plans(args)
    files: dict[str, LoggerFile] = {}
    for array, columns in plans.items():
        try:  # read once per array: a CLI's seconds, and one plain reader
            files[array] = read_logger_file(args.file, columns, args.timezone,
                                            args.time_column, args.date_order,
                                            fields_by_name=len(plans) == 1)
        except ValueError as exc:
            fail(f"{args.file.name}: {exc}" + (f" (array {array})" if len(plans) > 1 else ""))
    with contextlib.ExitStack() as stack:
        client = None if args.dry_run else stack.enter_context(
            httpx.Client(base_url=args.url, timeout=60.0))
        # the site first: an unknown one is refused before anything is read further, and the
        # station's values are joined as it takes its readings' stamps
        site = None if client is None else _site(client, args.site, list(files))
        summary = _summary(args, files, _join_sensors(args, files, site))
        if client is not None and site is not None:
            stamp_notes = _stamp_note(site, summary)
            if stamp_notes and args.sensors is not None and not args.sensors_at_stamps:
                # a stored reading is never replaced (a re-import sends duplicates): the
                # station's values must be joined as the site will read the stamps
                fail(f"--sensors: {stamp_notes[0]}. The station's values are joined as the site "
                     "takes the stamps (at each stamp, or averaged over each reading's "
                     "interval) and a stored reading is never replaced: set the site's "
                     "readings_stamped first, or give --sensors-at-stamps to join at the "
                     "stamps as they are; nothing was posted")
            summary["notes"].extend(stamp_notes)
            for array, lf in files.items():
                summary["arrays"][array].update(
                    post_readings(client, args.site, array, args.token, lf))
            summary["url"] = args.url
    _print(summary, args.json, args.dry_run)
    return 0


def _summary(args: argparse.Namespace, files: dict[str, LoggerFile],
             sensors: dict[str, Any] | None) -> dict[str, Any]:
    """What the import read: per array its readings, their times, columns and the reading of
    the highest power; the station joined (``sensors``); the notes of both."""
    first = next(iter(files.values()))
    notes = list(dict.fromkeys(n for lf in files.values() for n in lf.notes))
    summary: dict[str, Any] = {
        "file": str(args.file), "layout": first.layout, "time_column": first.time_column,
        "rows": len(first.lines), "site_id": args.site, "notes": notes, "arrays": {}}
    for array, lf in files.items():
        rows = lf.sendable.nonzero()[0]
        if not rows.size:
            fail(f"{args.file.name}: no row has power, or voltage and current, for array "
                 f"{array}: nothing to post")
        stamps = lf.times_utc[rows]
        summary["arrays"][array] = {
            "columns": {k: {"column": c, "unit": u} for k, (c, u) in lf.columns.items()},
            "readings": int(rows.size), "first": f"{stamps.min():%Y-%m-%dT%H:%M:%SZ}",
            "last": f"{stamps.max():%Y-%m-%dT%H:%M:%SZ}", "cadence_s": lf.cadence_s(),
            "power_from": lf.power_from, "peak_reading": _peak(lf, array)}
        if rows.size < len(lf.lines):
            line = int(lf.lines[(~lf.sendable).nonzero()[0][0]])
            notes.append(f"{array}: {len(lf.lines) - rows.size} rows without power or voltage "
                         f"and current (the first at line {line}) are not sent")
    if sensors is not None:
        summary["sensors"] = sensors
    return summary


def _join_sensors(args: argparse.Namespace, files: dict[str, LoggerFile],
                  site: dict[str, Any] | None) -> dict[str, Any] | None:
    """Read ``--sensors`` (a weather station's file) and join its values to one array's
    readings (:func:`backend.measurements.logger_file.join_station`), as the site takes its
    readings' stamps (``site`` None, a dry run: at the stamps, and a note says so); what was
    joined, for the summary. None without ``--sensors``."""
    from backend.measurements.logger_file import join_station, read_logger_file

    if args.sensors is None:
        if args.sensors_column or args.sensors_array:
            fail("--sensors: --sensors-column and --sensors-array need the station's file")
        return None
    if not args.sensors.is_file():
        fail(f"--sensors: {args.sensors} is not a file")
    array = args.sensors_array or ("fixed" if "fixed" in files else
                                   next(iter(files)) if len(files) == 1 else None)
    if array not in files:
        fail(f"--sensors-array: name the array whose readings carry the station's values, one "
             f"of {', '.join(files)}" + (f" (not {array!r})" if array else ""))
    columns = {}
    for spec in args.sensors_column:
        fld, eq, name = spec.partition("=")
        if not eq or not fld.strip() or not name.strip():
            fail(f"--sensors-column: {spec!r} is not FIELD=NAME[:UNIT] (e.g. "
                 "poa_irradiance_w_m2=POA_Avg)")
        columns[fld.strip()] = name.strip()
    stamped = "instant" if site is None or args.sensors_at_stamps \
        else site.get("readings_stamped", "instant")
    try:
        station = read_logger_file(args.sensors, columns, args.sensors_timezone or args.timezone,
                                   args.sensors_time_column, args.date_order, station=True)
        notes = join_station(files[array], station, stamped, args.sensors.name)
    except ValueError as exc:  # in the station's flags' words
        message = re.sub(r"^(time_column|timezone|column):",
                         lambda m: "--sensors-" + m.group(1).replace("_", "-") + ":", str(exc))
        message = message.replace("--time-column", "--sensors-time-column").replace(
            "with --timezone", "with --sensors-timezone")
        fail(f"{args.sensors.name}: {message}")
    if site is None and stamped == "instant":
        notes.append("a dry run does not read the site: the station's values were taken at the "
                     "readings' stamps; posted to a site whose readings are interval means "
                     "(readings_stamped), each reading takes the station's mean over its "
                     "interval")
    files[array].notes.extend(notes)
    return {"file": str(args.sensors), "array": array, "layout": station.layout,
            "rows": len(station.lines),
            "columns": {k: {"column": c, "unit": u} for k, (c, u) in station.columns.items()}}


def _peak(lf: LoggerFile, array: str) -> dict[str, Any]:
    """The reading of the highest power (sent, else V·I) as it is sent: a unit or a column
    mapped wrong shows at a glance (207,500 W for a 207-kW plant, not 207.5)."""
    import numpy as np

    v = lf.values[lf.sendable]
    power = v["power_w"] if "power_w" in v else v["voltage_v"] * v["current_a"]
    k = int(np.nanargmax(power.to_numpy())) if power.notna().any() else 0
    return lf.readings(array, k, k + 1)[0]


def _stamp_note(site: dict[str, Any], summary: dict[str, Any]) -> list[str]:
    """What a file of means needs from the site: one that takes its stamps as instants is
    told to set them (readings made from energy are means whatever their spacing), and one
    that reads them as interval starts is told a meter's totals end their intervals."""
    where = ("the Sites page's 'Readings stamped', or PUT /api/v1/sites/{id} "
             "(docs/diagnosis.md, 'Cadence')")
    arrays = summary["arrays"]
    if site.get("readings_stamped") == "interval_start" and any(
            a["power_from"] == "energy_total_wh" for a in arrays.values()):
        return [f"a meter's totals end their intervals and site {summary['site_id']} takes its "
                "readings' stamps as their intervals' starts (readings_stamped "
                "interval_start): each would be placed an interval early — set it to "
                "interval_end, " + where]
    if site.get("readings_stamped") != "instant":
        return []
    if metered := {a["power_from"] for a in arrays.values() if a["power_from"]}:
        ends = "energy_total_wh" in metered and len(metered) == 1
        return [f"the readings are means made from energy ({', '.join(sorted(metered))}) and "
                f"site {summary['site_id']} takes their stamps as instants "
                "(readings_stamped): set it to interval_end"
                + (" (a meter's total ends each interval)" if ends else
                   " or interval_start, as the export stamps its intervals")
                + " — " + where]
    cadence = min((a["cadence_s"] for a in arrays.values() if a["cadence_s"]), default=None)
    if cadence is None or cadence < MEANS_CADENCE_S:
        return []
    return [f"the readings are {cadence / 60:g} min apart and site {summary['site_id']} takes "
            "their stamps as instants (readings_stamped): if they are means stamped at their "
            "interval's end, set readings_stamped to interval_end — " + where]


def post_readings(client: Any, site_id: str, array: str, token: str, lf: LoggerFile,
                  sleep: Callable[[float], None] = time.sleep) -> dict[str, Any]:
    """Post the file's readings of ``array`` to ``site_id`` through ``client`` (an
    ``httpx.Client`` on the service) in batches of :data:`BATCH_READINGS`, gzip-compressed;
    the answers' counts. A batch is tried 5 times, 1, 2, 4, 8 s apart (``sleep``); a refused
    or undelivered one stops it: :func:`backend.cli.fail` naming the file's lines."""
    import httpx
    from tenacity import Retrying, retry_if_exception_type, stop_after_attempt
    from tqdm import tqdm

    from backend.retry import backoff

    class Retry(Exception):
        pass

    def once(body: bytes) -> httpx.Response:
        try:
            r = client.post(f"/api/v1/sites/{site_id}/measurements", content=body,
                            headers={"Authorization": f"Bearer {token}",
                                     "Content-Type": "application/json",
                                     "Content-Encoding": "gzip"})
        except httpx.TransportError as exc:
            raise Retry(f"{type(exc).__name__}: {exc}") from exc
        if r.status_code >= 500 or r.status_code == 429:
            raise Retry(f"{r.status_code} {r.text[:200]}")
        return r

    retrying = Retrying(stop=stop_after_attempt(5), wait=backoff(1.0, 10.0),
                        retry=retry_if_exception_type(Retry), reraise=True, sleep=sleep)
    lines = lf.lines[lf.sendable]
    accepted = duplicates = 0
    stored_through = None
    with tqdm(total=lines.size, unit="reading", disable=None, file=sys.stderr,
              desc=array) as bar:
        for k in range(0, lines.size, BATCH_READINGS):
            chunk = lf.readings(array, k, k + BATCH_READINGS)
            body = gzip.compress(json.dumps({"readings": chunk}).encode(), compresslevel=5)
            try:
                r = retrying(once, body)
            except Retry as exc:
                fail(f"the service did not take {array}'s lines {lines[k]}–"
                     f"{lines[k + len(chunk) - 1]} after 5 tries ({exc}); {accepted} of its "
                     "readings were stored — run again to resume (what is stored comes back "
                     "as duplicates)", code=1)
            if r.status_code != 200:
                fail(_refusal(r, lines, k, array, accepted), code=1)
            answer = r.json()
            accepted += answer["accepted"]
            duplicates += answer["duplicates"]
            stored_through = answer.get("stored_through")
            bar.update(len(chunk))
    return {"accepted": accepted, "duplicates": duplicates, "stored_through": stored_through}


def _site(client: Any, site_id: str, arrays: list[str]) -> dict[str, Any]:
    """The site as the service describes it; an unknown site or array is refused before
    anything is posted."""
    import httpx

    try:
        r = client.get(f"/api/v1/sites/{site_id}")
    except httpx.TransportError as exc:
        fail(f"--url: {client.base_url} does not answer ({type(exc).__name__}: {exc})", code=1)
    if r.status_code == 404:
        fail(f"--site: the service at {client.base_url} has no site {site_id!r}")
    if r.status_code != 200:
        fail(f"--site: GET /api/v1/sites/{site_id} answered {r.status_code} {r.text[:200]}",
             code=1)
    site: dict[str, Any] = r.json()
    for array in arrays:
        if array not in site.get("arrays", {}):
            fail(f"--array: site {site_id} has no array {array!r}; its arrays are "
                 f"{', '.join(site.get('arrays', {}))}")
    return site


def _refusal(r: Any, lines: Any, start: int, array: str, accepted: int) -> str:
    """A refused batch's answer in the file's terms: each problem with its line."""
    try:
        detail = r.json().get("detail")
    except ValueError:
        detail = r.text[:300]
    if r.status_code in (401, 403):
        return f"--token: the service refuses it ({r.status_code} {detail})"
    problems = []
    if isinstance(detail, list):
        for d in detail[:MAX_PROBLEMS_SHOWN]:
            row = d.get("row") if isinstance(d, dict) else None
            where = f"line {lines[start + row]}: " if isinstance(row, int) else ""
            problems.append(where + (d.get("msg", str(d)) if isinstance(d, dict) else str(d)))
        if len(detail) > MAX_PROBLEMS_SHOWN:
            problems.append(f"and {len(detail) - MAX_PROBLEMS_SHOWN} more problems listed")
    else:
        problems.append(str(detail))
    return (f"the service refused {array}'s readings ({r.status_code}): "
            + "; ".join(problems) + f". {accepted} of its readings before them were stored; "
            "mend the file or the mapping and run again (what is stored comes back as "
            "duplicates)")


def _print(summary: dict[str, Any], as_json: bool, dry_run: bool) -> None:
    if as_json:
        print(json.dumps(summary, indent=2))
        return
    print(f"read: {Path(summary['file']).name} ({summary['layout']}), {summary['rows']} rows")
    for array, a in summary["arrays"].items():
        every = "" if a["cadence_s"] is None else f", every {a['cadence_s']:g} s"
        print(f"  {summary['site_id']}/{array}: {a['readings']} readings from {a['first']} to "
              f"{a['last']}{every}")
        for fld, c in a["columns"].items():
            made = " (power_w: each interval's mean)" if fld == a["power_from"] else ""
            print(f"    {fld} ← {c['column']!r} [{c['unit']}]{made}")
        print(f"    its highest power as sent: {json.dumps(a['peak_reading'])}")
    if sensors := summary.get("sensors"):
        print(f"  sensors: {Path(sensors['file']).name} ({sensors['layout']}), {sensors['rows']} "
              f"rows, beside {sensors['array']}'s readings")
        for fld, c in sensors["columns"].items():
            print(f"    {fld} ← {c['column']!r} [{c['unit']}]")
    for note in summary["notes"]:
        print(f"note: {note}")
    if dry_run:
        print("dry run: nothing posted")
        return
    for array, a in summary["arrays"].items():
        print(f"posted {array} to {summary['url']}: {a['accepted']} accepted, "
              f"{a['duplicates']} duplicates, stored through {a['stored_through']}")
