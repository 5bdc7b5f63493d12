"""``heliotwin sun``: sun position for one place and time (DESIGN.md, CLI contract).

    heliotwin sun --lat 39.742476 --lon -105.1786 --time 2003-10-17T12:30:30-07:00 \\
        --elevation-m 1830.14 --pressure-hpa 820 --temperature-c 11 --delta-t-s 67 --json
    heliotwin sun --site tehuantepec --time now

``--site ID`` takes latitude, longitude and altitude from a configured site (and
the pressure of that altitude, ``pvlib.atmosphere.alt2pres``, unless
``--pressure-hpa`` is given); ``--time now`` is the current instant.

Heavy imports (numpy, pandas, pvlib) happen inside the command so that the
other subcommands do not pay for them.
"""

from __future__ import annotations

import argparse
import json
import os
from datetime import UTC, datetime
from typing import Any

from backend.cli import fail, site_or_fail


def _parse_time(text: str) -> datetime:
    """``now``, or an ISO 8601 time that must carry a UTC offset (:mod:`backend.timestamps`)."""
    from backend.timestamps import TimestampError, parse_instant

    if text.strip().lower() == "now":
        return datetime.now(UTC)
    try:
        return parse_instant(text, "--time")
    except TimestampError as exc:  # argparse names the argument itself
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--time: ")) from None


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``sun`` subcommand."""
    p = subparsers.add_parser(
        "sun",
        help="sun position (NREL SPA or Duffie-Beckman) for one place and time",
        description="Sun position for one place and time. Azimuth clockwise from north; "
        "apparent = with atmospheric refraction (SPA's topocentric zenith).",
    )
    p.add_argument("--site", metavar="ID",
                   help="a configured site: its latitude, longitude, altitude and air "
                        "temperature (the twin's refraction)")
    p.add_argument("--sites-dir", default=os.environ.get("HELIOTWIN_SITES_DIR"),
                   help="a folder of user site JSON files, added to the built-in sim/data/sites "
                        "(default $HELIOTWIN_SITES_DIR or data/user-sites; docs/sites.md)")
    p.add_argument("--lat", type=float, help="latitude [deg], north positive")
    p.add_argument("--lon", type=float, help="longitude [deg], east positive")
    p.add_argument("--time", type=_parse_time, required=True,
                   help="ISO 8601 time with offset, or now")
    p.add_argument("--elevation-m", type=float, help="site elevation [m] (default 0, or the "
                                                     "site's altitude)")
    p.add_argument(
        "--pressure-hpa", type=float,
        help="air pressure [hPa] (default 1013.25, or that of the site's altitude)",
    )
    p.add_argument(
        "--temperature-c", type=float,
        help="air temperature [C] for the refraction (default 12, or the site's, as the twin)"
    )
    p.add_argument("--delta-t-s", type=float, default=67.0, help="TT - UT1 [s] (default 67)")
    p.add_argument(
        "--method", choices=("spa", "duffie-beckman"), default="spa", help="algorithm (default spa)"
    )
    p.add_argument("--json", action="store_true", help="print JSON (default: a short text line)")
    p.set_defaults(func=run)


def compute(args: argparse.Namespace) -> dict[str, Any]:
    """The answer as a JSON-ready dict with units in the keys."""
    import pandas as pd

    from sim.sun import solar_position
    from vision.sphere import enu_from_sky

    when = pd.Timestamp(args.time)
    pos = solar_position(
        when,
        args.lat,
        args.lon,
        altitude=args.elevation_m,
        pressure=args.pressure_hpa * 100.0,
        temperature=args.temperature_c,
        delta_t=args.delta_t_s,
        method=args.method,
    ).iloc[0]
    east, north, up = enu_from_sky(pos["azimuth"], pos["apparent_elevation"]).tolist()
    return {
        "time": when.tz_convert("UTC").isoformat(),
        "method": args.method,
        "latitude_deg": args.lat,
        "longitude_deg": args.lon,
        "elevation_m": args.elevation_m,
        "pressure_hpa": args.pressure_hpa,
        "temperature_c": args.temperature_c,
        **({"site_id": args.site} if args.site else {}),
        "azimuth_deg": float(pos["azimuth"]),
        "zenith_deg": float(pos["zenith"]),
        "apparent_zenith_deg": float(pos["apparent_zenith"]),
        "elevation_deg": float(pos["elevation"]),
        "apparent_elevation_deg": float(pos["apparent_elevation"]),
        "sun_vector_enu": [east, north, up],
    }


def _place(args: argparse.Namespace) -> str | None:
    """Fill ``lat``/``lon``/``elevation_m``/``pressure_hpa``/``temperature_c`` from ``--site``
    (its air temperature, which the twin's refraction takes) and the defaults;
    an error message when the place is missing or given twice, else None."""
    if args.site is not None:
        if args.lat is not None or args.lon is not None:
            return "--site: give either --site or --lat/--lon, not both"
        from pvlib import atmosphere

        site = site_or_fail(args.site, args.sites_dir)
        args.lat, args.lon = site.latitude, site.longitude
        if args.elevation_m is None:
            args.elevation_m = site.altitude
        if args.pressure_hpa is None:
            args.pressure_hpa = float(atmosphere.alt2pres(args.elevation_m)) / 100.0
        if args.temperature_c is None:
            args.temperature_c = site.temp_air
    if args.lat is None or args.lon is None:
        return "--lat and --lon (or --site) are required"
    if args.elevation_m is None:
        args.elevation_m = 0.0
    if args.pressure_hpa is None:
        args.pressure_hpa = 1013.25
    if args.temperature_c is None:
        args.temperature_c = 12.0
    return None


def _check(args: argparse.Namespace) -> str | None:
    """Return an error message for out-of-range input, else None."""
    if not -90.0 <= args.lat <= 90.0:
        return f"--lat {args.lat}: latitude must be within [-90, 90] deg"
    if not -180.0 <= args.lon <= 180.0:
        return f"--lon {args.lon}: longitude must be within [-180, 180] deg"
    if args.pressure_hpa <= 0:
        return f"--pressure-hpa {args.pressure_hpa}: pressure must be positive"
    return None


def run(args: argparse.Namespace) -> int:
    """Print the sun position; exit 2 on bad input."""
    problem = _place(args) or _check(args)
    if problem:
        fail(problem)
    out = compute(args)
    if args.json:
        print(json.dumps(out))
    else:
        print(
            f"{out['time']}  azimuth {out['azimuth_deg']:.5f} deg  "
            f"apparent elevation {out['apparent_elevation_deg']:.5f} deg  "
            f"(apparent zenith {out['apparent_zenith_deg']:.5f} deg, {out['method']})"
        )
    return 0
