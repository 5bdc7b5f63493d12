"""``heliotwin simulate``: the tracker-vs-fixed twin run for a site (DESIGN.md, CLI contract).

    heliotwin simulate --site tehuantepec --start 2024-03-15 --end 2024-03-16 --json
    heliotwin simulate --site tehuantepec --start 2024-01-01 --end 2025-01-01 --csv year.csv
    heliotwin simulate --site tehuantepec --start 2024-01-01 --end 2025-01-01 --tmy3 FILE --force

``start`` is inclusive, ``end`` exclusive; a bare date means midnight in the
site's time zone, a date-time must carry a UTC offset. A progress bar (tqdm)
goes to stderr when stderr is a terminal and the run is long: 20,000 steps or more, or
expected to take a few seconds (:func:`backend.twin.cost.table_cost_s`: a camera loop's
few days, at few steps).
Bad input exits with status 2 and a message naming the problem. Heavy imports
happen inside the command.

A run of more steps than the service allows one request
(``HELIOTWIN_MAX_SIMULATION_STEPS``) is refused (:func:`check_step_count`).

``--tmy3``/``--epw``: a file whose first line is of the other format is refused naming
the flag that reads it. A typical year is laid onto the run's calendar in its
station's standard time, wrapping at the year's ends (:mod:`sim.sky`); a
station more than 100 km from the site is refused unless ``--force``
(:func:`backend.twin.scenario.check_station`). ``--weather-csv``: measured weather of its
own dates (:func:`sim.sky.read_measured`; ``--weather-stamped``, ``--weather-timezone``); a
run outside them is refused naming them.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
from pathlib import Path
from typing import Any

from backend.cli import CliError, fail, site_or_fail
from backend.twin.parameters import MACHINE_PARAMETERS

_BAR_MIN_STEPS = 20_000  # a progress bar for long runs (two weeks at 1 min and up) …
_BAR_MIN_S = 3.0  # … and for runs expected to take this long [s] (a camera loop's day)


class InputError(CliError, ValueError):
    """Bad command-line input: :func:`backend.cli.main` reports it and exits 2."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` subcommand."""
    p = subparsers.add_parser(
        "simulate",
        help="simulate the tracker and the fixed array side by side for a site",
        description="Twin run for a site: sun, tracker joint angles, both arrays' irradiance, "
        "cell temperature and maximum-power-point current/voltage/power at every step "
        "(clear sky unless --tmy3 is given). start inclusive, end exclusive; a bare date is "
        "midnight in the site's time zone.",
    )
    p.add_argument("--site", default="tehuantepec", help="site id (default tehuantepec)")
    p.add_argument("--start", required=True, help="YYYY-MM-DD or ISO date-time with offset")
    p.add_argument(
        "--end", required=True, help="YYYY-MM-DD or ISO date-time with offset (exclusive)"
    )
    p.add_argument("--step-s", type=float, default=60.0,
                   help="time step [s] (default 60; a run has at most "
                        "HELIOTWIN_MAX_SIMULATION_STEPS steps, 1,100,000 by default)")
    p.add_argument(
        "--controller",
        default="ideal",
        help="tracking controller: ideal, open_loop_spa, open_loop_duffie_beckman, "
        "chronological, closed_loop_camera, hybrid, open_loop_model (default ideal)",
    )
    p.add_argument(
        "--pointing-model-terms", metavar="JSON_OR_PATH",
        help="open_loop_model's mount terms: a JSON object or a file holding one — the answer "
        "of GET /api/v1/sites/ID/pointing-model (its 'terms' are read) or {name: degrees}, "
        'e.g. \'{"azimuth_zero_deg": 1.5, "elevation_zero_deg": -0.8}\' (default a perfect '
        "mount)",
    )
    p.add_argument(
        "--receiver", default="flat",
        help="flat (PV, default), or cpv: a receiver that loses the beam outside "
        "--acceptance-angle-deg",
    )
    machine = p.add_argument_group("machine (disturbances; default a perfect machine)")
    for param in MACHINE_PARAMETERS:
        machine.add_argument(
            "--" + param.name.replace("_", "-"), type=float, default=param.default,
            metavar="X", help=f"{param.help} (default {param.default:g})",
        )
    weather = p.add_mutually_exclusive_group()
    weather.add_argument(
        "--tmy3", metavar="PATH", help="use the typical year of a TMY3 file instead of clear sky"
    )
    weather.add_argument(
        "--epw", metavar="PATH", help="use the typical year of an EPW file instead of clear sky"
    )
    weather.add_argument(
        "--pvgis", metavar="PATH",
        help="use the typical year of a PVGIS TMY download (CSV or JSON; its EPW goes to "
             "--epw) instead of clear sky"
    )
    weather.add_argument(
        "--nsrdb", metavar="PATH",
        help="use the typical year of an NSRDB TMY download (PSM CSV; an NSRDB actual year "
             "goes to --weather-csv) instead of clear sky"
    )
    weather.add_argument(
        "--weather-csv", metavar="PATH",
        help="use measured weather of its own dates: a CSV with columns time (ISO 8601 with "
        "a UTC offset), ghi, dni, dhi [W m-2], optionally temp_air [°C] and wind_speed "
        "[m/s], rows 1 min to 1 h apart; the run must lie within its dates",
    )
    p.add_argument("--weather-stamped", choices=("interval_end", "interval_start", "instant"),
                   default="interval_end",
                   help="what --weather-csv's times mark: the end (default) or the start of "
                   "the interval each value averages, or the instant of the value")
    p.add_argument("--weather-timezone", metavar="ZONE",
                   help="IANA zone --weather-csv's times were read in, when they carry no "
                   "UTC offset (Etc/GMT-10 for a fixed UTC+10)")
    p.add_argument(
        "--force", action="store_true",
        help="run on a weather file whose station is more than 100 km from the site",
    )
    p.add_argument(
        "--sites-dir",
        default=os.environ.get("HELIOTWIN_SITES_DIR"),
        help="a folder of user site JSON files, added to the built-in sim/data/sites "
        "(default $HELIOTWIN_SITES_DIR or data/user-sites; docs/sites.md)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--csv", metavar="PATH", help="write the per-step series to PATH as CSV")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    p.set_defaults(func=run)


def parse_when(text: str, timezone: str, field: str) -> Any:
    """A bare date (midnight in ``timezone``) or an ISO date-time with offset → ``pd.Timestamp``
    (the rules of :mod:`backend.timestamps`)."""
    import pandas as pd

    from backend.timestamps import TimestampError, parse_day_or_instant

    try:
        return pd.Timestamp(parse_day_or_instant(text, timezone, f"--{field}"))
    except TimestampError as exc:
        raise InputError(str(exc)) from None


def read_pointing_model_terms(text: str) -> dict[str, Any]:
    """``--pointing-model-terms``: a JSON object, inline or in a file (a saved answer of
    ``GET …/pointing-model`` too: ``sim.pointing_model.PointingModel.from_terms``)."""
    source = text
    if text.lstrip()[:1] in ("[", '"') or text.strip() in ("", "null", "true", "false"):
        raise InputError(f"--pointing-model-terms: {text!r} is not a JSON object of terms "
                         "(or the file of one)")
    if not text.lstrip().startswith("{"):
        try:
            source = Path(text).read_text(encoding="utf-8")
        except OSError as exc:
            raise InputError(f"--pointing-model-terms: cannot read {text!r}: "
                             f"{exc.strerror or exc}") from None
    try:
        value = json.loads(source)
    except json.JSONDecodeError as exc:
        raise InputError(f"--pointing-model-terms: not JSON ({exc})") from None
    if not isinstance(value, dict):
        raise InputError("--pointing-model-terms: expected a JSON object of terms")
    if "detail" in value and "terms" not in value:  # the route's 4xx, saved by curl
        raise InputError("--pointing-model-terms: the service's refusal, not a pointing "
                         f"model: {value['detail']}")
    return value


def _progress_bar(enabled: bool) -> tuple[Any, Any]:
    """A tqdm bar on stderr when it is a terminal; returns (callback, bar)."""
    if not enabled or not sys.stderr.isatty():
        return None, None
    from tqdm import tqdm

    bar = tqdm(total=100, unit="%", file=sys.stderr, desc="simulating", leave=False)

    def callback(fraction: float) -> None:
        bar.update(round(100 * fraction) - bar.n)

    return callback, bar


def check_step_count(start: Any, end: Any, step_s: float) -> None:
    """Refuse a run of more steps than the service allows one request
    (``HELIOTWIN_MAX_SIMULATION_STEPS``, read as the service reads it:
    ``backend.settings.get_settings``): a mistyped ``--step-s 0.001`` would otherwise run
    for hours. The variable raises the bound for the CLI as for the service."""
    from pydantic import ValidationError

    from backend.settings import get_settings, settings_error_text

    try:
        limit = get_settings().simulations.max_steps
    except ValidationError as exc:
        raise InputError(settings_error_text(exc)) from None
    steps = (end - start).total_seconds() / step_s
    if steps > limit:
        raise InputError(f"--step-s: {step_s:g} s from --start to --end is {steps:,.0f} steps; "
                         f"the limit is {limit:,}: use a larger --step-s or a shorter range, "
                         "or raise the limit with HELIOTWIN_MAX_SIMULATION_STEPS=N")


def execute(args: argparse.Namespace) -> tuple[dict[str, Any], Any]:
    """Run the simulation; returns (summary, TwinResult). Raises InputError on bad input."""
    site = site_or_fail(args.site, args.sites_dir)
    start = parse_when(args.start, site.timezone, "start")
    end = parse_when(args.end, site.timezone, "end")
    if not end > start:
        raise InputError(
            f"--end ({args.end}) must be after --start ({args.start}); end is exclusive"
        )
    if not (args.step_s > 0 and math.isfinite(args.step_s)):
        raise InputError(f"--step-s: must be positive and finite, got {args.step_s}")
    check_step_count(start, end, args.step_s)
    from backend.twin.scenario import (
        MAX_STATION_DISTANCE_KM,
        Scenario,
        StationTooFar,
        check_station,
        run_scenario,
    )

    weather, station = None, None
    flag, path = (("--tmy3", args.tmy3) if args.tmy3 else ("--epw", args.epw) if args.epw
                  else ("--pvgis", args.pvgis) if args.pvgis
                  else ("--nsrdb", args.nsrdb) if args.nsrdb
                  else ("--weather-csv", args.weather_csv))
    if args.weather_csv:
        weather, station = _measured(args, site)
    elif path:
        from sim.sky import read_typical_year, sniff_weather_format

        try:
            found = sniff_weather_format(path)
        except (OSError, ValueError) as exc:
            raise InputError(f"{flag}: cannot read {path!r}: {exc}") from None
        if found != flag[2:]:  # the content decides: name the flag that reads it
            raise InputError(f"{flag}: {path!r} is a {found.upper()} file (by its first "
                             f"line), not {flag[2:].upper()}: pass it as --{found}")
        try:
            weather, meta = read_typical_year(path, found)
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f"{flag}: cannot read {path!r}: {exc}") from None
        try:
            station = check_station(meta, site, args.force, "--force")
        except StationTooFar as exc:
            raise InputError(f"{flag}: {exc}") from None
        if station["forced"] and station["distance_km"] > MAX_STATION_DISTANCE_KM:
            logging.getLogger(__name__).warning("%s: station %s is %.0f km from site %s (--force)",
                                                flag, station["name"], station["distance_km"],
                                                site.site_id)
    machine = {p.name: getattr(args, p.name) for p in MACHINE_PARAMETERS
               if getattr(args, p.name) != p.default}
    terms = None
    if args.pointing_model_terms is not None:
        terms = read_pointing_model_terms(args.pointing_model_terms)
    try:
        scenario = Scenario(site.site_id, start, end, args.step_s, args.controller,
                            args.receiver, machine, weather=weather, station=station,
                            pointing_model_terms=terms)
    except ValueError as exc:
        name, _, problem = str(exc).partition(":")
        raise InputError(f"{flag if name == 'weather' else '--' + name.replace('_', '-')}:"
                         f"{problem}") from None
    from backend.twin.cost import table_cost_s

    steps = (end - start).total_seconds() / args.step_s
    long = steps >= _BAR_MIN_STEPS or table_cost_s(scenario, site) >= _BAR_MIN_S
    callback, bar = _progress_bar(not args.no_progress and long)
    try:
        result = run_scenario(site, scenario, progress=callback)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    finally:
        if bar is not None:
            bar.close()
    summary = result.summary()
    if station is not None:
        summary["weather"] = {**station, "file": path}
    return summary, result


def _measured(args: argparse.Namespace, site: Any) -> tuple[Any, dict[str, Any]]:
    """``--weather-csv``'s measured weather and its description
    (:func:`sim.sky.read_measured`, :func:`backend.twin.scenario.check_station`)."""
    from backend.twin.scenario import StationTooFar, check_station
    from sim.site_config import check_iana_zone
    from sim.sky import read_measured

    if args.weather_timezone is not None:
        try:
            check_iana_zone(args.weather_timezone)
        except ValueError as exc:
            raise InputError(f"--weather-timezone: {exc}") from None
    try:
        weather, meta = read_measured(args.weather_csv, args.weather_stamped,
                                      args.weather_timezone, Path(args.weather_csv).name)
    except (OSError, ValueError) as exc:
        raise InputError(f"--weather-csv: cannot read {args.weather_csv!r}: {exc}") from None
    try:
        return weather, check_station(meta, site, args.force, "--force")
    except StationTooFar as exc:  # an NSRDB year says where it is from
        raise InputError(f"--weather-csv: {exc}") from None


def write_csv(series: Any, timezone: str, path: str) -> None:
    """Write the per-step series as CSV: ``time_utc``, ``time_local`` (the site's zone, with
    offset) and every column with its unit in the name (:mod:`backend.twin.export`)."""
    from backend.twin.export import series_csv

    series_csv(series, timezone, path)


def _tracking_costs(summary: dict[str, Any]) -> list[str]:
    """What tracking cost, for a controller other than ``ideal`` (which has no drive and
    no error): the receiver, the pointing error, its energy loss, the actuators' energy and
    the gain after it, units in the words (the text summary had left them out, a tester's
    finding; ``docs/control.md`` says what each is)."""
    if summary["controller"] == "ideal":
        return []

    def num(value: float | None, fmt: str, unit: str) -> str:
        return "n/a" if value is None else f"{value:{fmt}}{unit}"

    net = summary["net_gain_pct"]
    lines = [
        f"receiver: {summary['receiver']}",
        f"pointing: error {num(summary['pointing_error_rms_mrad'], '.2f', ' mrad')} RMS "
        f"(max {num(summary['pointing_error_max_mrad'], '.2f', ' mrad')}) over "
        f"{summary['pointing_error_minutes']:,} minutes with the sun above "
        f"{summary['pointing_min_elevation_deg']:g}°; pointing loss "
        f"{summary['pointing_loss_wh']:.2f} Wh",
        f"actuators: {summary['actuator_energy_wh']:.2f} Wh (motion "
        f"{summary['actuator_move_energy_wh']:.3f} Wh in {summary['moves']:,} moves, standby "
        f"{summary['actuator_standby_energy_wh']:.2f} Wh); net gain "
        + ("n/a" if net is None else f"{net:.1f} %"),
    ]
    if summary.get("actuator_warning"):
        lines.append(f"warning: {summary['actuator_warning']}")
    return lines


def _stow_lines(summary: dict[str, Any]) -> list[str]:
    """The wind stow's cost (``sim.stow``), for a site that stows: its daylight minutes and
    the energy lost, or why there is none (a sky without wind)."""
    if "stow_wind_speed_m_s" not in summary:
        return []
    over = f"wind over {summary['stow_wind_speed_m_s']:g} m/s"
    if summary["stow_min"] is None:
        return [f"wind stow: n/a (the run's sky has no wind speed; it stows at {over})"]
    loss = summary["stow_loss_wh"]
    if loss < 0:  # under cloud the flat panel sees more of the sky than one facing a low sun
        return [f"wind stow: {summary['stow_min']:,} daylight minutes, {-loss:.2f} Wh gained, "
                f"not lost: a cloudy sky's light is best caught flat ({over})"]
    return [f"wind stow: {summary['stow_min']:,} daylight minutes, {loss:.2f} Wh lost ({over})"]


def _text(summary: dict[str, Any]) -> str:
    gain = summary["gain_pct"]
    return "\n".join(
        [
            f"site {summary['site_id']}  {summary['start']} .. {summary['end']}  "
            f"step {summary['step_s']:g} s  controller {summary['controller']}  "
            f"sky {summary['sky']}",
            f"tracker: {summary['tracker_energy_wh'] / 1000:.3f} kWh, "
            f"peak {summary['tracker_peak_w']:.1f} W",
            f"fixed:   {summary['fixed_energy_wh'] / 1000:.3f} kWh, "
            f"peak {summary['fixed_peak_w']:.1f} W",
            f"gain:    {gain:.1f} %"
            if gain is not None
            else "gain:    n/a (no fixed-array energy)",
        ]
        + _stow_lines(summary)
        + _tracking_costs(summary)
        + (
            [
                f"weather: measured {w['name']} ({w['stamped']} stamps), {w['start']} .. "
                f"{w['end']}" + (f", {w['distance_km']:.0f} km from the site"
                                 if "distance_km" in w else "")
                if w["format"] == "measured" else
                f"weather: {w['format'].upper()} {w['name']} ({w['latitude_deg']:.2f}, "
                f"{w['longitude_deg']:.2f}), {w['distance_km']:.0f} km from the site"
            ]
            if (w := summary.get("weather"))
            else []
        )
        + ([f"warning: {summary['weather_warning']}"] if summary.get("weather_warning")
           else [])
    )


def run(args: argparse.Namespace) -> int:
    """Entry point of ``heliotwin simulate``; exit 2 on bad input."""
    summary, result = execute(args)  # bad input: InputError, a CliError main reports
    if args.csv:
        try:
            write_csv(result.series, result.site.timezone, args.csv)
        except OSError as exc:
            fail(f"--csv: cannot write {args.csv!r}: {exc}")
        summary["csv"] = args.csv
    print(json.dumps(summary) if args.json else _text(summary))
    return 0
