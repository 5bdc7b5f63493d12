"""``heliotwin plant``: plants of dual-axis trackers (seed 004) — list, simulate, sweep.

    heliotwin plant list
    heliotwin plant simulate --plant penarroya --start 2021-01-01 --end 2022-01-01 --json
    heliotwin plant simulate --plant penarroya --start 2021-01-01 --end 2021-02-01 \\
        --strategy sky_scan --tmy3 PATH --step-s 600
    heliotwin plant sweep --collector-m 12x5 --lat 38.3 --lon -5.3 \\
        --layouts square,diagonal --gcr 0.15:0.35:0.1 --start 2021-01-01 --end 2022-01-01 \\
        [--strategy sun,backtrack] [--scheduler tcp://HOST:8786] --json|--csv

``start`` inclusive, ``end`` exclusive; a bare date is midnight in the plant's
time zone, a date-time must carry an offset. A progress bar (tqdm) goes to
stderr when it is a terminal. Bad input exits with status 2 and a message.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import threading
from typing import Any, cast

from backend.cli import fail
from backend.cli.simulate import InputError, _stow_lines, parse_when

_FORCE_HELP = ("run on a weather station more than 100 km from the place anyway (only the "
               "state of its sky is moved there)")

STRATEGIES = ("sun", "backtrack", "sky_scan")


def json_text(value: Any) -> str:
    """``value`` as strict JSON: a non-finite float (NaN, ±inf: no JSON value) written as
    null, as the service's JSON answers it (orjson), so a parser never meets ``NaN``."""
    def clean(v: Any) -> Any:
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        return v

    return json.dumps(clean(value), allow_nan=False)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``plant`` subcommand with ``list``, ``simulate`` and ``sweep``."""
    p = subparsers.add_parser("plant", help="plants of many trackers: shading and strategies",
                              description="Plants of dual-axis trackers (seed 004): "
                              "inter-shading, backtracking, the sky scan.")
    sub = p.add_subparsers(dest="plant_command", metavar="ACTION", required=True)
    plants_dir = os.environ.get("HELIOTWIN_PLANTS_DIR")

    ls = sub.add_parser("list", help="list the plants")
    ls.add_argument("--plants-dir", default=plants_dir,
                    help="directory of plant JSON files (default $HELIOTWIN_PLANTS_DIR or "
                    "the built-in sim/data/plants)")
    ls.add_argument("--json", action="store_true", help="print JSON")
    ls.set_defaults(func=run_list)

    sim = sub.add_parser("simulate", help="simulate a plant over a time range",
                         description="Plant run: sun, strategy, every collector's shade, "
                         "plant energy under the area and bypass-diode models, and a fixed "
                         "plant of the same collectors (clear sky unless --tmy3).")
    sim.add_argument("--plant", required=True, help="plant id (e.g. penarroya)")
    sim.add_argument("--start", required=True, help="YYYY-MM-DD or ISO date-time with offset")
    sim.add_argument("--end", required=True, help="YYYY-MM-DD or ISO date-time (exclusive)")
    sim.add_argument("--step-s", type=float, default=60.0, help="time step [s] (default 60)")
    sim.add_argument("--strategy", default="sun", help=f"one of {', '.join(STRATEGIES)}")
    sim.add_argument("--tmy3", metavar="PATH", help="weather from a TMY3 file")
    sim.add_argument("--epw", metavar="PATH", help="weather from an EPW file")
    sim.add_argument("--pvgis", metavar="PATH",
                     help="weather from a PVGIS TMY download (CSV or JSON)")
    sim.add_argument("--nsrdb", metavar="PATH",
                     help="weather from an NSRDB TMY download (PSM CSV)")
    sim.add_argument("--force", action="store_true", help=_FORCE_HELP)
    sim.add_argument("--plants-dir", default=plants_dir, help="directory of plant JSON files")
    sim.add_argument("--json", action="store_true", help="print the summary as JSON")
    sim.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    sim.set_defaults(func=run_simulate)

    sw = sub.add_parser(
        "sweep", help="layouts × spacings × strategies of a field, as Dask tasks",
        description="Plant design sweep (issue 26): for each layout, GCR and strategy, the "
        "interior collector's and the field's share of beam lost to shade, the energy per "
        "collector (bypass-diode model) and per hectare — energy_* the finite field's "
        "average, most of whose collectors are on its edge, interior_energy_* the interior "
        "collector's, what a large plant's collectors get —, and the land per collector. Each "
        "case is one Dask task; --scheduler sends them to a running cluster, otherwise a "
        "LocalCluster of one worker per core runs them (one case: in this process). Clear "
        "sky unless --tmy3/--epw. With --lat/--lon a bare date is midnight UTC.")
    sw.add_argument("--layouts",
                    help="comma list of square, diagonal, hexagonal_n_s, hexagonal_e_w, custom "
                    "(default square; refused with --plant)")
    sw.add_argument("--gcr", required=True,
                    help="ground cover ratios: 0.15,0.25 or START:STOP:STEP (STOP included)")
    sw.add_argument("--strategy", default="sun",
                    help=f"comma list of {', '.join(STRATEGIES)} (default sun)")
    sw.add_argument("--collector-m", help="collector WIDTHxHEIGHT [m], e.g. 12x5 (wired like "
                    "Peñarroya's: its modules, as many as fit)")
    sw.add_argument("--collector-polygon", metavar="U,V;U,V;…",
                    help="any collector outline instead of --collector-m: its vertices [m] "
                    "about the pivot in the collector plane (u right, v up when facing it), "
                    "e.g. '--collector-polygon=-6,-2.5;6,-2.5;6,0;0,0;0,2.5;-6,2.5' for an L "
                    "(quoted: a shell ends a command at ';'; the = form when it starts with "
                    "a minus), or a file of them (the same "
                    "text or JSON [[u, v], ...]); strategy sun only")
    sw.add_argument("--lat", type=float, help="latitude [°], north positive")
    sw.add_argument("--lon", type=float, help="longitude [°], east positive")
    sw.add_argument("--altitude-m", type=float,
                    help="altitude [m] (default 0; a --plant has its own)")
    sw.add_argument("--timezone", help="IANA zone of the local days at --lat/--lon (bare "
                    "--start/--end dates; default UTC; a --plant has its own)")
    sw.add_argument("--plant", help="an existing plant scaled in spacing to each GCR "
                    "(instead of --layouts/--collector-m/--lat/--lon)")
    sw.add_argument("--field",
                    help="ROWSxCOLUMNS of the finite regular field around the interior "
                    "collector (default 5x5: twoaxistracking's neighbor_order 2; refused with "
                    "--plant)")
    sw.add_argument("--aspect-ratio", type=float, help="layout custom: aspect ratio")
    sw.add_argument("--offset", type=float, help="layout custom: row offset [-0.5, 0.5)")
    sw.add_argument("--rotation-deg", type=float, help="layout custom: rotation [0, 180)")
    sw.add_argument("--slope-azimuth-deg", type=float,
                    help="ground slope: azimuth of the downhill normal [°] (default 0; "
                    "refused with --plant)")
    sw.add_argument("--slope-tilt-deg", type=float,
                    help="ground slope: tilt [°] (default 0, flat; refused with --plant)")
    sw.add_argument("--start", required=True, help="YYYY-MM-DD or ISO date-time with offset")
    sw.add_argument("--end", required=True, help="YYYY-MM-DD or ISO date-time (exclusive)")
    sw.add_argument("--step-s", type=float, default=600.0, help="time step [s] (default 600)")
    sw.add_argument("--tmy3", metavar="PATH", help="weather from a TMY3 file")
    sw.add_argument("--epw", metavar="PATH", help="weather from an EPW file")
    sw.add_argument("--pvgis", metavar="PATH",
                    help="weather from a PVGIS TMY download (CSV or JSON)")
    sw.add_argument("--nsrdb", metavar="PATH",
                    help="weather from an NSRDB TMY download (PSM CSV)")
    sw.add_argument("--force", action="store_true", help=_FORCE_HELP)
    sw.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                    help="a running Dask scheduler (default: a LocalCluster on this machine)")
    sw.add_argument("--workers", type=int, help="LocalCluster workers (default: the cores)")
    sw.add_argument("--plants-dir", default=plants_dir, help="directory of plant JSON files")
    out = sw.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="print JSON")
    out.add_argument("--csv", action="store_true", help="print the rows as CSV")
    sw.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    sw.set_defaults(func=run_sweep)


def run_list(args: argparse.Namespace) -> int:
    """``heliotwin plant list``."""
    from sim.plant import list_plants

    try:
        plants, skipped = list_plants(args.plants_dir)
    except ValueError as exc:
        fail(f"--plants-dir: {exc}")
    for name, reason in skipped:  # the others are listed all the same
        print(f"heliotwin plant list: warning: {name} left out: {reason}", file=sys.stderr)
    if args.json:
        print(json_text([{"plant_id": p.plant_id, "name": p.name, "trackers": p.n_trackers}
                          for p in plants]))
    else:
        for p in plants:
            print(f"{p.plant_id}\t{p.n_trackers} tracker{'' if p.n_trackers == 1 else 's'}"
                  f"\t{p.name}")
    return 0


def _plant_arg(args: argparse.Namespace) -> Any:
    """The plant of ``--plant`` from ``--plants-dir``; InputError names the flag."""
    from sim.plant import UnknownPlantError, load_plant

    try:
        return load_plant(args.plant, args.plants_dir)
    except UnknownPlantError as exc:
        raise InputError(f"--plant: {exc}") from None
    except ValueError as exc:
        raise InputError(f"--plant: bad plant file: {exc}") from None


def execute(args: argparse.Namespace) -> dict[str, Any]:
    """Run ``plant simulate``; returns the summary. Raises InputError on bad input."""
    if args.strategy not in STRATEGIES:
        raise InputError(f"--strategy: must be one of {', '.join(STRATEGIES)}, "
                         f"got {args.strategy!r}")
    plant = _plant_arg(args)
    start = parse_when(args.start, plant.timezone, "start")
    end = parse_when(args.end, plant.timezone, "end")
    if not end > start:
        raise InputError(f"--end ({args.end}) must be after --start ({args.start}); "
                         "end is exclusive")
    from sim.energy import check_step, step_problem

    try:
        check_step(start, end, args.step_s)
    except ValueError as exc:
        raise InputError(f"--step-s: {step_problem(exc)}") from None
    if (end - start).total_seconds() / args.step_s > 5_000_000:
        raise InputError("--step-s: too many steps (more than 5,000,000); use a larger step")
    weather, station, _, clock = typical_weather(args, plant, start, end)
    from backend.plants import simulate_summary

    bar = None
    callback = None
    if not args.no_progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=100, unit="%", file=sys.stderr, desc="simulating", leave=False)

        def callback(fraction: float) -> None:
            bar.update(round(100 * fraction) - bar.n)

    try:
        summary = simulate_summary(plant, start, end, args.step_s, args.strategy, weather,
                                   station, clock, callback)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    finally:
        if bar is not None:
            bar.close()
    return summary


def _text(s: dict[str, Any]) -> str:
    def pct(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.2f} %"

    dni_f = s["dni_weighted_shaded_fraction"]    # None: no beam in the range (polar night)
    any_f = s["fraction_of_daylight_any_shaded"]  # None: no daylight step
    return "\n".join([
        f"plant {s['plant_id']} ({s['trackers']} trackers)  {s['start']} .. {s['end']}  "
        f"step {s['step_s']:g} s  strategy {s['strategy']}  sky {s['sky']}",
        f"daylight steps {s['daylight_steps']}, any collector shaded in "
        f"{pct(None if any_f is None else 100 * any_f)} of them; "
        f"DNI-weighted shaded fraction {'n/a (no beam)' if dni_f is None else f'{dni_f:.4f}'}",
        f"plant energy {s['plant_energy_wh'] / 1000:.1f} kWh (bypass-diode model); "
        f"shading loss {pct(s['shading_loss_electrical_pct'])} electrical, "
        f"{pct(s['shading_loss_area_pct'])} by area",
        f"fixed plant  {s['fixed_energy_wh'] / 1000:.1f} kWh; gain {pct(s['gain_vs_fixed_pct'])}",
        *([f"warning: {s['weather_warning']}"] if s.get("weather_warning") else []),
        *_stow_lines(s),  # a plant that stows: the twin's line (sim.stow)
    ])


def run_simulate(args: argparse.Namespace) -> int:
    """``heliotwin plant simulate``; exit 2 on bad input."""
    summary = execute(args)  # bad input: InputError, a CliError main reports
    print(json_text(summary) if args.json else _text(summary))
    return 0


#: ``plant sweep``'s flags by the request keys a :class:`backend.plants.sweep.SweepInputError`
#: names (the rest: ``--`` and the key with dashes, e.g. ``--step-s``).
SWEEP_FLAGS = {"strategies": "--strategy", "collector_polygon_m": "--collector-polygon",
               "latitude_deg": "--lat", "longitude_deg": "--lon", "plant_id": "--plant",
               "field_size": "--field"}


def sweep_flag(field: str) -> str:
    """The ``plant sweep`` flag of a sweep parameter (its request key)."""
    return SWEEP_FLAGS.get(field, "--" + field.replace("_", "-"))


def typical_weather(args: argparse.Namespace, place: Any, start: Any, end: Any
                    ) -> tuple[Any, dict[str, Any] | None, str, dict[str, Any]]:
    """(weather on ``[start, end)``, its station, a token naming the file, its clock check)
    from --tmy3/--epw/--pvgis/--nsrdb, or (None, None, "", {}): the twin's rules
    (:func:`backend.twin.scenario.check_station`, a station more than 100 km away refused
    unless --force; :func:`sim.sky.typical_year_at_site` lays the year on the range and,
    far away, moves only the state of the sky; :func:`sim.weather_clock.weather_clock`,
    ``weather_shift_min`` and ``weather_warning``: is the file on the sun's time at the
    place?)."""
    given = [(f"--{f}", getattr(args, f)) for f in ("tmy3", "epw", "pvgis", "nsrdb")
             if getattr(args, f, None)]
    if len(given) > 1:
        raise InputError(f"{' and '.join(f for f, _ in given)}: give one weather file, not "
                         f"{'both' if len(given) == 2 else 'several'}")
    if not given:
        return None, None, "", {}
    flag, path = given[0]
    import hashlib

    from backend.twin.scenario import place_weather
    from sim.sky import read_typical_year

    try:
        typical, meta = read_typical_year(path, flag[2:])
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"{flag}: cannot read {path!r}: {exc}") from None
    try:
        weather, station, clock = place_weather(typical, meta, place, start, end, args.force,
                                                "--force")
    except ValueError as exc:  # StationTooFar too: a distant station, a clock off longitude
        raise InputError(f"{flag}: {exc}") from None
    with open(path, "rb") as f:
        token = f"{flag[2:]}:{hashlib.sha256(f.read()).hexdigest()[:16]}"
    return weather, station, token, clock


def sweep_from_args(args: argparse.Namespace
                    ) -> tuple[Any, list[Any], Any, dict[str, Any]]:
    """(spec, cases, weather, its clock check as :func:`typical_weather`'s) of
    ``plant sweep``; InputError names the flag."""
    from dataclasses import replace

    from backend.plants.sweep import (
        SweepInputError,
        parse_gcr,
        parse_polygon,
        parse_size,
        prepare_sweep,
        sweep_zone,
    )

    plant = None
    if args.plant:
        plant = _plant_arg(args)
    try:
        tz = sweep_zone(plant, args.timezone)
    except SweepInputError as exc:
        raise InputError(exc.message(sweep_flag)) from None
    start = parse_when(args.start, tz, "start")
    end = parse_when(args.end, tz, "end")
    custom = (args.aspect_ratio, args.offset, args.rotation_deg)
    try:
        size = None if args.field is None else tuple(
            int(v) for v in parse_size(args.field, "field_size"))
        spec, cases = prepare_sweep(
            layouts=None if args.layouts is None
            else [s.strip() for s in args.layouts.split(",") if s.strip()],
            gcr=parse_gcr(args.gcr),
            strategies=[s.strip() for s in args.strategy.split(",") if s.strip()],
            start=start, end=end, step_s=args.step_s, latitude_deg=args.lat,
            longitude_deg=args.lon, altitude_m=args.altitude_m,
            collector_m=parse_size(args.collector_m, "collector_m") if args.collector_m
            else None,
            collector_polygon_m=parse_polygon(args.collector_polygon, "collector_polygon_m")
            if args.collector_polygon else None, plant=plant,
            field_size=cast(tuple[int, int] | None, size),
            custom=None if custom == (None, None, None) else custom,
            slope_azimuth_deg=args.slope_azimuth_deg, slope_tilt_deg=args.slope_tilt_deg,
            timezone=args.timezone)
    except SweepInputError as exc:
        raise InputError(exc.message(sweep_flag)) from None
    from sim.plant.sweep import site_plant

    weather, _, token, clock = typical_weather(args, spec.plant or site_plant(spec),
                                               spec.start, spec.end)
    if weather is not None:
        spec = replace(spec, weather_token=token)
    return spec, cases, weather, clock


#: Sweep columns of the CSV and text output, in order.
SWEEP_COLUMNS = ("layout", "gcr", "strategy", "interior_beam_shaded_pct", "field_beam_shaded_pct",
                 "energy_kwh_per_collector", "interior_energy_kwh", "energy_mwh_per_ha",
                 "interior_energy_mwh_per_ha", "land_m2_per_collector", "collectors",
                 "shading_loss_electrical_pct")


def run_sweep(args: argparse.Namespace) -> int:
    """``heliotwin plant sweep``; exit 2 on bad input."""
    import signal

    from backend.plants.sweep import (
        SweepCancelled,
        SweepFailed,
        SweepSetupError,
        runs_in_process,
    )
    from backend.plants.sweep import run_sweep as run

    spec, cases, weather, clock = sweep_from_args(args)
    if not getattr(args, "verbose", False):   # distributed logs its cluster's life at INFO
        import logging

        import distributed  # noqa: F401 - first: its import sets its loggers to INFO again

        logging.getLogger("distributed").setLevel(logging.WARNING)
        for name in ("distributed.client", "distributed.utils"):  # a lost scheduler's
            logging.getLogger(name).setLevel(logging.CRITICAL)      # reconnect tracebacks:
        # the sweep's own error line says it (SweepFailed), --verbose shows them
    bar, callback = None, None
    if not args.no_progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=len(cases), unit="case", file=sys.stderr, desc="sweeping", leave=False)

        def callback(done: int, total: int) -> None:
            bar.update(done - bar.n)

    # Ctrl-C stops the sweep as a cancel does (HTTP DELETE): the cases finished are printed
    # and the rest dropped, exit 130 (it exited 130 with nothing printed); a second Ctrl-C,
    # or one during a single case run in this process, quits at once
    interrupted = threading.Event()

    def on_interrupt(signum: int, frame: Any) -> None:
        if interrupted.is_set():
            raise KeyboardInterrupt
        interrupted.set()

    previous = None
    if not runs_in_process(cases, args.scheduler) and \
            threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGINT, on_interrupt)
    try:
        result = run(spec, cases, weather, scheduler=args.scheduler, n_workers=args.workers,
                     progress=callback, cancelled=interrupted.is_set)
    except KeyboardInterrupt:
        _say_interrupted(0, len(cases))
        return 130
    except SweepCancelled as exc:             # Ctrl-C: the cases finished before it
        if bar is not None:
            bar.close()
        if exc.result is not None:             # None: stopped while reaching the scheduler
            _print_sweep(args, {**exc.result, **clock})
        _say_interrupted(exc.result["cases"] if exc.result is not None else 0, len(cases))
        return 130
    except OSError as exc:                    # no scheduler at that address
        fail(f"--scheduler: cannot reach {args.scheduler!r}: {exc}")
    except SweepSetupError as exc:            # --scheduler unreadable, --workers out of bounds
        fail(f"--{exc}")
    except SweepFailed as exc:                # the cluster could not finish: the cases done
        if exc.result is not None and exc.result["rows"]:
            _print_sweep(args, {**exc.result, **clock})
        fail(str(exc), code=1)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
        if bar is not None:
            bar.close()
    _print_sweep(args, {**result, **clock})
    return 0


def _say_interrupted(done: int, total: int) -> None:
    print(f"heliotwin plant sweep: interrupted after {done} of {total} cases (the cases "
          "finished are printed, the rest dropped)", file=sys.stderr, flush=True)


def _print_sweep(args: argparse.Namespace, result: dict[str, Any]) -> None:
    """A sweep's result on stdout: JSON, CSV or the text table; a weather file's
    ``weather_warning`` also as a ``warning:`` line (on stderr beside the CSV)."""
    if result.get("weather_warning") and not args.json:
        print(f"warning: {result['weather_warning']}",
              file=sys.stderr if args.csv else sys.stdout)
    if args.json:
        print(json_text(result))
    elif args.csv:
        import csv

        w = csv.DictWriter(sys.stdout, fieldnames=SWEEP_COLUMNS, extrasaction="ignore",
                           lineterminator="\n")
        w.writeheader()
        w.writerows(result["rows"])
    else:
        print(f"{result['cases']} cases on {result['engine']} "
              f"({result['workers']} workers, sky computed {result['sky_computations']}x) "
              f"in {result['wall_s']:.1f} s")
        print("\t".join(SWEEP_COLUMNS))
        for r in result["rows"]:
            print("\t".join(sweep_cell(r[c]) for c in SWEEP_COLUMNS))


def sweep_cell(value: Any) -> str:
    """A value of the sweep's text table: an undefined fraction (None) is ``n/a``, as
    docs/plants.md says (it printed ``None``)."""
    return "n/a" if value is None else str(value)
