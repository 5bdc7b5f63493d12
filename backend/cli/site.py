"""``heliotwin site create|show|validate|from-weather|schema``: sites you define.

A site is a JSON file of the format in ``docs/sites.md`` (JSON Schema:
``docs/site.schema.json``, generated from ``sim.site_config.SiteConfig``).
User sites live in ``HELIOTWIN_SITES_DIR`` (default ``data/user-sites/``) and add
to the built-in ``sim/data/sites/``; a user file with a built-in id replaces it.

- ``create --id ID --latitude-deg --longitude-deg --timezone [--like SITE]`` writes a
  site at a new place with the tracker and arrays of ``--like`` (default
  ``tehuantepec``); what the place decides is not copied but taken from the new place
  and marked ``assumed`` (``sim.sites.relocated_config``: fixed tilt from the latitude,
  facing the equator; the tracker's azimuth range, ``--like``'s span, centred on the
  equator side; the altitude, unless given, the ground's there from pvlib's terrain table;
  air temperature and wind the site format's stated defaults);
  ``--from-file FILE`` writes a hand-written config after validating it (keys it leaves
  out that the place decides are filled in the same way).
- ``from-weather FILE --id ID`` writes a site at a TMY3/EPW station's or a PVGIS TMY's
  place and zone (the format read from the file's first line,
  ``sim.sky.sniff_weather_format``; any other file refused saying so;
  ``pvlib.iotools.read_tmy3`` / ``read_epw`` metadata, ``sim.sky.read_typical_year`` for
  PVGIS's, ``sim.sky.nsrdb_header`` for an NSRDB download's; the file's fixed UTC offset
  becomes the ``Etc/GMT±N`` zone the typical year is recorded in — a PVGIS file, in UTC,
  the longitude's whole hour, said on stderr; an NSRDB file its ``Local Time Zone``; the
  clear-sky air temperature and wind are the file's annual means, the fixed tilt from the
  latitude; each marked ``assumed``).
- ``show ID [--json]`` prints a site's config and which file it comes from.
- ``validate FILE…`` checks files; a malformed one gets a message naming the field (exit 2).
- ``schema`` prints the JSON Schema.

``create`` and ``from-weather`` also write the site's rows to the database of
``HELIOTWIN_DATABASE_URL``: a running service on it shows the site within a second, no
restart (``backend.sites.Registry.rescan``); ``PUT /api/v1/sites/{site_id}`` (the
dashboard's Sites page) applies a config at once. A zone whose standard time is more than
3 h from the longitude / 15 is written with a warning on stderr naming both
(``sim.site_config.site_zone_warning``), as ``PUT`` answers it in ``warnings``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from backend.cli import fail, site_or_fail


def _not_json(exc: json.JSONDecodeError) -> str:
    """A file that is not JSON, said as what it is (the parser's bare "Expecting value:
    line 1 column 1 (char 0)" named nothing: a tester's finding)."""
    return f"not a JSON site file ({exc.msg} at line {exc.lineno}, column {exc.colno})"


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add the ``site`` subcommand."""
    p = subparsers.add_parser("site", help="define sites: create, show, validate, from-weather")
    sub = p.add_subparsers(dest="site_command", metavar="ACTION", required=True)
    c = sub.add_parser("create", help="write a new site to HELIOTWIN_SITES_DIR")
    c.add_argument("--id", dest="site_id", required=True, help="site id, e.g. my-roof")
    c.add_argument("--name", help="name shown on the dashboard (default: the id)")
    c.add_argument("--latitude-deg", type=float, help="latitude [°], north positive")
    c.add_argument("--longitude-deg", type=float, help="longitude [°], east positive")
    c.add_argument("--altitude-m", type=float,
                   help="height above sea level [m] (default: the ground's there, "
                        "pvlib.location.lookup_altitude, marked as assumed)")
    c.add_argument("--timezone", help="IANA zone, e.g. America/New_York")
    c.add_argument("--like", default="tehuantepec",
                   help="copy tracker and arrays from this site (default tehuantepec); the "
                        "fixed tilt, air temperature and wind come from the new place, "
                        "marked as assumed")
    c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a config value by its dotted key, e.g. arrays.fixed.surface_tilt_deg=45, "
                        "arrays.fixed.dc_loss_pct=14, arrays.tracker.inverter_limit_w=600 "
                        "(docs/sites.md; a JSON value, else text); repeat per key. A key so "
                        "given is no longer marked assumed")
    c.add_argument("--from-file", type=Path, metavar="FILE",
                   help="write this hand-written config instead (validated first)")
    c.add_argument("--force", action="store_true",
                   help="overwrite a user site, or replace a built-in one")
    c.set_defaults(func=create)
    w = sub.add_parser("from-weather",
                       help="a site at the place and zone of a weather file (TMY3, EPW, "
                            "PVGIS, NSRDB)")
    w.add_argument("file", type=Path, metavar="FILE",
                   help="TMY3 CSV, EPW file, PVGIS TMY (CSV or JSON) or NSRDB download, "
                        "told apart by its first line")
    w.add_argument("--id", dest="site_id", required=True, help="site id to create")
    w.add_argument("--format", choices=("tmy3", "epw", "pvgis", "nsrdb"),
                   help="default: from the file's first line; given, the file must be it")
    w.add_argument("--timezone", help="IANA zone instead of the file's fixed UTC offset")
    w.add_argument("--like", default="tehuantepec",
                   help="tracker and array modules like this site (default tehuantepec)")
    w.add_argument("--force", action="store_true",
                   help="overwrite a user site, or replace a built-in one")
    w.set_defaults(func=from_weather)
    s = sub.add_parser("show", help="print a site's config and where it comes from")
    s.add_argument("site_id", metavar="ID")
    s.add_argument("--json", action="store_true", help="print only the config, as JSON")
    s.set_defaults(func=show)
    v = sub.add_parser("validate", help="check site files against the documented format")
    v.add_argument("files", nargs="+", type=Path, metavar="FILE")
    v.set_defaults(func=validate)
    sc = sub.add_parser("schema", help="print the JSON Schema of a site file")
    sc.set_defaults(func=schema)


def _sites_dir() -> Path:
    from backend.settings import get_settings

    return get_settings().sites.user_dir


def _write(config: dict[str, Any], force: bool, flags: dict[str, str] | None = None) -> int:
    """Validate, refuse to overwrite without ``force``, write, say where. ``flags``: the
    config keys made from flags, by flag (:data:`_FLAG_KEYS`), which a refusal names."""
    from backend.sites import config_value, write_site_file
    from sim.site_config import site_zone_warning, validate_site_config
    from sim.sites import builtin_site_ids

    try:
        validate_site_config(config, where="site")
    except ValueError as exc:
        msg = str(exc)
        for flag, key in (flags or {}).items():
            msg = msg.replace(f"site: {key}:", f"{flag}:")
        fail(msg)
    directory = _sites_dir()
    target = directory / f"{config['site_id']}.json"
    builtin = config["site_id"] in builtin_site_ids()
    if not force and (target.exists() or builtin):
        what = "a built-in site" if builtin else f"a site in {directory}"
        fail(f"--id {config['site_id']!r} is already {what}; --force replaces it "
             "(a user file wins over a built-in one)")
    path = write_site_file(directory, config)
    where = _sync_database(config)
    arrays = config.get("arrays") or {}
    from sim.twin import has_twin_arrays

    runs = has_twin_arrays({n: a.get("mount") for n, a in arrays.items()
                            if isinstance(a, dict)})
    what = (f"`heliotwin simulate --site {config['site_id']}` runs it" if runs else
            "it has no arrays named tracker and fixed, so no twin to simulate (a camera "
            "site: it takes sky frames)")
    print(f"wrote {path}; {what}; {where}")
    for key, why in config.get("assumed", {}).items():
        print(f"  assumed {key} = {config_value(config, key)}: {why}")
    if (warning := site_zone_warning(config)) is not None:
        print(f"warning: {warning}", file=sys.stderr)
    return 0


def _sync_database(config: dict[str, Any]) -> str:
    """Write the site's rows to the database of ``HELIOTWIN_DATABASE_URL`` (as the service
    does at start-up), so a running service on it takes the site at once
    (``backend.sites.Registry.rescan``); says what happened. One write transaction that
    takes the write lock first (:func:`backend.cli.db.with_db`): the running service adds
    the new file's rows too, and its loggers commit meanwhile."""
    from sqlalchemy.exc import SQLAlchemyError

    from backend.cli import CliError
    from backend.cli.db import with_db
    from backend.sites import sync_sites
    from backend.storage.engine import SchemaTooNewError
    from sim.sites import site_from_dict

    site = site_from_dict(config)
    try:
        with_db(lambda conn: sync_sites(conn, [site]))
    except CliError as exc:  # the file is written; another one in the folder is broken
        return f"not added to the database: {exc}"
    except SQLAlchemyError as exc:
        return (f"the database could not take it now ({type(exc).__name__}): the service "
                "adds it at its next start")
    except SchemaTooNewError as exc:  # the file is written all the same: say both
        return f"not added to the database: {exc}"
    return "a running service on the same database shows it within a second, no restart"


def _template(like: str) -> dict[str, Any]:
    return site_or_fail(like, _sites_dir(), "--like").to_config()


def create(args: argparse.Namespace) -> int:
    """Write a new site (from flags and a template, or from a file)."""
    from sim.sites import place_defaults, relocated_config

    if args.from_file is not None:
        try:
            config = json.loads(args.from_file.read_text())
        except json.JSONDecodeError as exc:
            fail(f"--from-file {args.from_file}: {_not_json(exc)}")
        except OSError as exc:
            fail(f"--from-file {args.from_file}: {exc}")
        if isinstance(config, dict) and config.get("site_id") != args.site_id:
            fail(f"--from-file: its site_id {config.get('site_id')!r} is not --id "
                 f"{args.site_id!r}")
        if isinstance(config, dict):
            config = place_defaults(config)
        if args.set:
            fail("--set: edit the file given to --from-file instead")
        return _write(config, args.force)
    missing = [f"--{n.replace('_', '-')}" for n in ("latitude_deg", "longitude_deg", "timezone")
               if getattr(args, n) is None]
    if missing:
        fail(f"{', '.join(missing)} required (or --from-file FILE)")
    base = _template(args.like)
    config = relocated_config(base, {
        "site_id": args.site_id, "name": args.name or args.site_id,
        "latitude_deg": args.latitude_deg, "longitude_deg": args.longitude_deg,
        **({} if args.altitude_m is None else {"altitude_m": args.altitude_m}),
        "timezone": args.timezone,
        "source": f"heliotwin site create (tracker and arrays as {args.like})", "notes": ""})
    flags = dict(_FLAG_KEYS)
    for spec in args.set:
        key = _set_value(config, spec)
        flags[f"--set {key}"] = key
    return _write(config, args.force, flags=flags)


def _set_value(config: dict[str, Any], spec: str) -> str:
    """Put ``--set KEY=VALUE`` into ``config`` (a dotted key into its objects; the value read
    as JSON, else as text) and drop the key's ``assumed`` mark: the user gave it. Its key."""
    key, eq, text = spec.partition("=")
    key = key.strip()
    parts = key.split(".")
    if not eq or not key or not all(parts):
        fail(f"--set: {spec!r} is not KEY=VALUE (e.g. arrays.fixed.surface_tilt_deg=45)")
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        value = text
    node = config
    for i, part in enumerate(parts[:-1]):
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            fail(f"--set {key}: {'.'.join(parts[:i + 1])} is a value, not an object")
    node[parts[-1]] = value
    config.get("assumed", {}).pop(key, None)
    return key


#: The config keys ``site create`` takes from its flags, by flag: a refusal of a config made
#: from flags names the flag (it named the key, ``site: latitude_deg: …`` for
#: ``--latitude-deg 95``: a tester's finding)
_FLAG_KEYS = {"--id": "site_id", "--name": "name", "--latitude-deg": "latitude_deg",
              "--longitude-deg": "longitude_deg", "--altitude-m": "altitude_m",
              "--timezone": "timezone"}


def _station(path: Path, fmt: str) -> dict[str, Any]:
    """Place, zone offset and name of a weather file of format ``fmt`` (pvlib.iotools
    metadata); a file lacking a field is refused saying so, not with pvlib's bare
    KeyError of the field."""
    from pvlib import iotools

    from sim.sky import (
        nsrdb_header,
        nsrdb_is_typical_year,
        pvgis_epw_offset_h,
        read_measured,
        read_typical_year,
        weather_buffer,
    )

    if fmt == "nsrdb":  # a typical or an actual year: its place and zone from its header
        head = nsrdb_header(weather_buffer(path))
        weather = (read_typical_year if nsrdb_is_typical_year(path) else read_measured)(path)[0]
        return {"latitude_deg": head["latitude"], "longitude_deg": head["longitude"],
                "altitude_m": head["altitude"], "tz_h": head["local_utc_offset_h"],
                "name": "", "code": f"NSRDB location {head['location_id']}",
                "temp_air_c": round(float(weather["temp_air"].mean()), 1),
                "wind_speed_m_s": round(float(weather["wind_speed"].mean()), 1)}
    if fmt == "pvgis" or (fmt == "epw" and pvgis_epw_offset_h(weather_buffer(path)) is not None):
        weather, station = read_typical_year(path, fmt)  # a PVGIS year: UTC, no zone named
        return {"latitude_deg": station["latitude"], "longitude_deg": station["longitude"],
                "altitude_m": station["altitude"], "tz_h": None, "name": "",
                "code": f"PVGIS {station['name']}",
                "temp_air_c": round(float(weather["temp_air"].mean()), 1),
                "wind_speed_m_s": round(float(weather["wind_speed"].mean()), 1)}
    try:
        if fmt == "epw":
            data, meta = iotools.read_epw(weather_buffer(path))
            name = ", ".join(str(meta.get(k)) for k in ("city", "state-prov", "country")
                             if meta.get(k) not in (None, "", "-"))
            code = meta.get("WMO_code", "")
        else:
            data, meta = iotools.read_tmy3(weather_buffer(path), map_variables=True)
            name = ", ".join(str(meta.get(k)).strip('"') for k in ("Name", "State")
                             if meta.get(k))
            code = meta.get("USAF", "")
        return {
            "latitude_deg": float(meta["latitude"]), "longitude_deg": float(meta["longitude"]),
            "altitude_m": float(meta["altitude"]), "tz_h": float(meta["TZ"]),
            "name": name, "code": str(code),
            "temp_air_c": round(float(data["temp_air"].mean()), 1),
            "wind_speed_m_s": round(float(data["wind_speed"].mean()), 1)}
    except (KeyError, IndexError) as exc:
        raise ValueError(f"not a readable {fmt.upper()} file: no {exc} in it") from None


def fixed_offset_zone(tz_h: float) -> str:
    """The IANA ``Etc/GMT±N`` zone of a whole-hour UTC offset [h] (POSIX sign: inverted).
    The zones run from UTC−12 (``Etc/GMT+12``) to UTC+14 (``Etc/GMT-14``): Tonga's +13 had
    been refused and a −13 named the zone ``Etc/GMT+13``, which does not exist."""
    if tz_h != int(tz_h) or not -12 <= tz_h <= 14:
        raise ValueError(f"the file's UTC offset {tz_h} h has no Etc/GMT zone: pass --timezone")
    n = -int(tz_h)
    return "Etc/GMT" if n == 0 else f"Etc/GMT{n:+d}"


def from_weather(args: argparse.Namespace) -> int:
    """Write a site at the place of a weather file (TMY3, EPW, PVGIS, NSRDB); a
    ``--timezone`` whose standard time is not the file's offset is written with a warning
    naming both."""
    from sim.site_config import standard_offset_h
    from sim.sites import CLIMATE_KEYS, relocated_config
    from sim.sky import sniff_weather_format

    try:  # the content decides: a TMY2 file named .csv is not read as TMY3
        fmt = sniff_weather_format(args.file)
    except (OSError, ValueError) as exc:
        fail(f"{args.file}: {exc}")
    if args.format is not None and args.format != fmt:
        fail(f"--format {args.format}: {args.file} is a {fmt.upper()} file (by its first "
             "line); leave --format out")
    try:
        st = _station(args.file, fmt)
        utc_file = st["tz_h"] is None  # PVGIS: hours in UTC, no zone named
        solar_h = round(st["longitude_deg"] / 15.0)
        zone = args.timezone or fixed_offset_zone(solar_h if utc_file else st["tz_h"])
        base = _template(args.like)
    except (OSError, ValueError, KeyError) as exc:
        fail(f"{args.file}: {exc}")
    if utc_file:
        clock = (f"zone {zone} (--timezone); the file's typical year is in UTC (PVGIS)"
                 if args.timezone else
                 f"zone {zone}: the longitude's whole hour, {solar_h:+d} h — a PVGIS file is "
                 "in UTC and names no zone; the typical year keeps UTC")
    elif fmt == "nsrdb":  # the NSRDB wrote its zone: its stamps', whatever the site's
        clock = (f"zone {zone}" + (" (--timezone)" if args.timezone else
                                   f": the NSRDB file's Local Time Zone, {st['tz_h']:+g} h"))
    elif args.timezone:
        clock = (f"zone {zone} (--timezone); the file's typical year keeps its own clock, "
                 f"UTC{st['tz_h']:+g} h")
    else:
        clock = (f"zone {zone}: the file's fixed UTC offset {st['tz_h']:+g} h (its typical "
                 "year's clock)")
    config = relocated_config(base, {
        "site_id": args.site_id, "name": st["name"] or args.site_id,
        "latitude_deg": st["latitude_deg"], "longitude_deg": st["longitude_deg"],
        "altitude_m": st["altitude_m"], "timezone": zone,
        "source": f"{fmt.upper()} station {st['code']} {st['name']} ({args.file.name}); "
                  f"tracker and modules as {args.like}",
        "notes": clock},
        climate={k: st[k] for k in CLIMATE_KEYS}, climate_source=args.file.name)
    written = _write(config, args.force)
    if utc_file and not args.timezone:
        print(f"note: {clock}: pass --timezone (Europe/Rome, …) for the site's local clock",
              file=sys.stderr)
    if (args.timezone and not utc_file and fmt != "nsrdb"
            and (std := standard_offset_h(zone)) != st["tz_h"]):
        # Asia/Kathmandu given for a +5.5 h file was written silently, its notes saying
        # the zone was the file's offset (a tester's finding)
        print(f"warning: --timezone {zone} is UTC{std:+g} h in standard time, the file's "
              f"hours UTC{st['tz_h']:+g} h: the run lays the typical year on the file's clock, "
              "the site's days and times are the zone's — another place's zone?",
              file=sys.stderr)
    return written


def show(args: argparse.Namespace) -> int:
    """Print one site's config and its file."""
    from sim.sites import is_builtin, load_site, site_path

    try:
        path = site_path(args.site_id, _sites_dir())
        site = load_site(args.site_id, _sites_dir())
    except ValueError as exc:
        fail(str(exc))
    if not args.json:
        origin = "built-in" if is_builtin(path) else "user"
        from sim.sites import builtin_site_ids

        if not is_builtin(path) and args.site_id in builtin_site_ids():
            origin = "user, replacing the built-in site of the same id"
        print(f"# {path} ({origin})")
    print(json.dumps(site.to_config(), indent=2, ensure_ascii=False))
    return 0


def validate(args: argparse.Namespace) -> int:
    """Check every file; exit 2 when one is malformed."""
    from sim.sites import site_from_dict

    bad = 0
    for path in args.files:
        try:
            data = json.loads(path.read_text())
            site = site_from_dict(data, where=str(path))
            if path.stem != site.site_id:
                raise ValueError(f"{path}: site_id {site.site_id!r} does not match the file name")
        except json.JSONDecodeError as exc:
            print(f"{path}: {_not_json(exc)}", file=sys.stderr)
            bad += 1
            continue
        except (OSError, ValueError) as exc:
            print(f"{exc}" if isinstance(exc, ValueError) and str(path) in str(exc)
                  else f"{path}: {exc}", file=sys.stderr)
            bad += 1
            continue
        pair = {"tracker", "fixed"} <= set(site.arrays)
        note = "" if pair else "; no arrays named tracker and fixed: the twin cannot simulate it"
        print(f"{path}: ok (site {site.site_id}, {len(site.arrays)} arrays{note})")
    return 2 if bad else 0


def schema(args: argparse.Namespace) -> int:
    """Print the JSON Schema (the content of docs/site.schema.json)."""
    from sim.site_config import site_json_schema

    print(json.dumps(site_json_schema(), indent=2, ensure_ascii=False))
    return 0
