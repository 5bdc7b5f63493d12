"""``heliotwin plant``: plants of dual-axis trackers (seed 004) — list and simulate.

    heliotwin plant list
    heliotwin plant simulate --plant penarroya --start 2021-01-01 --end 2022-01-01 --json
    heliotwin plant simulate --plant penarroya --start 2021-01-01 --end 2021-02-01 \\
        --strategy sky_scan --tmy3 PATH --step-s 600

``start`` inclusive, ``end`` exclusive; a bare date is midnight in the plant's
time zone, a date-time must carry an offset. A progress bar (tqdm) goes to
stderr when it is a terminal. Bad input exits with status 2 and a message.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

from backend.cli import fail
from backend.cli.simulate import InputError, parse_when

STRATEGIES = ("sun", "backtrack", "sky_scan")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``plant`` subcommand with ``list`` and ``simulate``."""
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
    sim.add_argument("--tmy3", metavar="PATH",
                     help="weather from a TMY3 file (moved to the plant by mean solar time)")
    sim.add_argument("--plants-dir", default=plants_dir, help="directory of plant JSON files")
    sim.add_argument("--json", action="store_true", help="print the summary as JSON")
    sim.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    sim.set_defaults(func=run_simulate)


def run_list(args: argparse.Namespace) -> int:
    """``heliotwin plant list``."""
    from sim.plant import list_plants

    try:
        plants = list_plants(args.plants_dir)
    except ValueError as exc:
        fail(str(exc))
    if args.json:
        print(json.dumps([{"plant_id": p.plant_id, "name": p.name, "trackers": p.n_trackers}
                          for p in plants]))
    else:
        for p in plants:
            print(f"{p.plant_id}\t{p.n_trackers} trackers\t{p.name}")
    return 0


def execute(args: argparse.Namespace) -> dict[str, Any]:
    """Run ``plant simulate``; returns the summary. Raises InputError on bad input."""
    from sim.plant import UnknownPlantError, load_plant

    if args.strategy not in STRATEGIES:
        raise InputError(f"--strategy: must be one of {', '.join(STRATEGIES)}, "
                         f"got {args.strategy!r}")
    try:
        plant = load_plant(args.plant, args.plants_dir)
    except UnknownPlantError as exc:
        raise InputError(f"--plant: {exc}") from None
    except ValueError as exc:
        raise InputError(f"--plant: bad plant file: {exc}") from None
    start = parse_when(args.start, plant.timezone, "start")
    end = parse_when(args.end, plant.timezone, "end")
    if not end > start:
        raise InputError(f"--end ({args.end}) must be after --start ({args.start}); "
                         "end is exclusive")
    if not args.step_s > 0 or args.step_s != args.step_s:
        raise InputError(f"--step-s: must be positive, got {args.step_s}")
    if (end - start).total_seconds() / args.step_s > 5_000_000:
        raise InputError("--step-s: too many steps (more than 5,000,000); use a larger step")
    weather = None
    if args.tmy3:
        from sim.plant.simulate import weather_for_plant
        from sim.sky import read_tmy3

        try:
            tmy, meta = read_tmy3(args.tmy3, coerce_year=start.year)
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f"--tmy3: cannot read {args.tmy3!r}: {exc}") from None
        weather = weather_for_plant(tmy, float(meta["longitude"]), plant, start, end)
    from sim.plant.simulate import simulate_plant

    bar = None
    callback = None
    if not args.no_progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=100, unit="%", file=sys.stderr, desc="simulating", leave=False)

        def callback(fraction: float) -> None:
            bar.update(round(100 * fraction) - bar.n)

    try:
        result = simulate_plant(plant, start, end, step_s=args.step_s, strategy=args.strategy,
                                weather=weather, progress=callback)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    finally:
        if bar is not None:
            bar.close()
    summary = result.summary()
    if args.tmy3:
        summary["tmy3"] = args.tmy3
    return summary


def _text(s: dict[str, Any]) -> str:
    def pct(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.2f} %"

    return "\n".join([
        f"plant {s['plant_id']} ({s['trackers']} trackers)  {s['start']} .. {s['end']}  "
        f"step {s['step_s']:g} s  strategy {s['strategy']}  sky {s['sky']}",
        f"daylight steps {s['daylight_steps']}, any collector shaded in "
        f"{100 * (s['fraction_of_daylight_any_shaded'] or 0):.2f} % of them; "
        f"DNI-weighted shaded fraction {s['dni_weighted_shaded_fraction']:.4f}",
        f"plant energy {s['plant_energy_wh'] / 1000:.1f} kWh (bypass-diode model); "
        f"shading loss {pct(s['shading_loss_electrical_pct'])} electrical, "
        f"{pct(s['shading_loss_area_pct'])} by area",
        f"fixed plant  {s['fixed_energy_wh'] / 1000:.1f} kWh; gain {pct(s['gain_vs_fixed_pct'])}",
    ])


def run_simulate(args: argparse.Namespace) -> int:
    """``heliotwin plant simulate``; exit 2 on bad input."""
    summary = execute(args)  # bad input: InputError, a CliError main reports
    print(json.dumps(summary) if args.json else _text(summary))
    return 0
