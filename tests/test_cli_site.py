"""``heliotwin site create|show|validate|from-weather|schema`` as a user runs them: ``site
schema`` as a real process (the entry point), the others through ``backend.cli.main`` in this
process (``heliotwin_cli``: the same parser, output and exit code, a second of imports less).

User sites go to a temporary ``HELIOTWIN_SITES_DIR``; the repository's ``data/`` is never
written. Weather stations: pvlib's own TMY3 file (Greensboro NC, 723170) and an EPW file
written here by hand for a southern-hemisphere station, so both readers and both
hemispheres are exercised.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from sim.sky import pvlib_tmy3_path

ROOT = Path(__file__).resolve().parents[1]


def sites_env(sites_dir: Path) -> dict[str, str]:
    """The user sites in ``sites_dir``, and a database there (``site create`` syncs it)."""
    return {"HELIOTWIN_SITES_DIR": str(sites_dir),
            "HELIOTWIN_DATABASE_URL": f"sqlite:///{sites_dir / 'cli.sqlite'}"}


@pytest.fixture
def heliotwin(heliotwin_cli: Callable[..., Any]) -> Callable[..., Any]:
    """``heliotwin ARGS`` in process with the user sites of ``sites_dir``."""
    return lambda sites_dir, *args: heliotwin_cli(*args, env=sites_env(sites_dir))


def test_schema_prints_the_shipped_file(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("HELIOTWIN_")}
    p = subprocess.run([sys.executable, "-m", "backend", "site", "schema"], capture_output=True,
                       text=True, cwd=ROOT, timeout=120, env={**env, **sites_env(tmp_path)})
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout) == json.loads((ROOT / "docs" / "site.schema.json").read_text())


def test_create_writes_a_site_that_simulate_runs(tmp_path: Path, heliotwin) -> None:
    p = heliotwin(tmp_path, "site", "create", "--id", "madrid-roof", "--latitude-deg", "40.45",
                  "--longitude-deg", "-3.73", "--altitude-m", "667", "--timezone", "Europe/Madrid",
                  "--name", "Madrid roof")
    assert p.returncode == 0, p.stderr
    written = json.loads((tmp_path / "madrid-roof.json").read_text())
    assert (written["latitude_deg"], written["timezone"]) == (40.45, "Europe/Madrid")
    assert set(written["arrays"]) == {"tracker", "fixed"}  # from --like tehuantepec
    run = heliotwin(tmp_path, "simulate", "--site", "madrid-roof", "--start", "2024-06-21",
                    "--end", "2024-06-22", "--step-s", "600", "--json")
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout)
    assert summary["site_id"] == "madrid-roof"
    assert summary["tracker_energy_wh"] > summary["fixed_energy_wh"] > 0
    show = heliotwin(tmp_path, "site", "show", "madrid-roof")
    assert show.returncode == 0 and f"{tmp_path / 'madrid-roof.json'} (user)" in show.stdout
    again = heliotwin(tmp_path, "site", "create", "--id", "madrid-roof", "--latitude-deg", "40",
                      "--longitude-deg", "-3", "--timezone", "Europe/Madrid")
    assert again.returncode == 2 and "--force" in again.stderr
    assert "`heliotwin simulate --site madrid-roof` runs it" in p.stdout
    # a camera site has no twin: the command it suggested then failed
    cam = heliotwin(tmp_path, "site", "create", "--id", "cam", "--like", "guadalajara_fisheye",
                    "--latitude-deg", "20.7", "--longitude-deg", "-103.4", "--timezone",
                    "America/Mexico_City")
    assert cam.returncode == 0 and "simulate --site" not in cam.stdout
    assert "no twin to simulate" in cam.stdout


def test_missing_place_flags_are_named(tmp_path: Path, heliotwin) -> None:
    p = heliotwin(tmp_path, "site", "create", "--id", "nowhere", "--latitude-deg", "10")
    assert p.returncode == 2
    assert "--longitude-deg, --timezone required" in p.stderr
    assert not (tmp_path / "nowhere.json").exists()


def test_a_user_file_replaces_a_built_in_only_with_force(tmp_path: Path, heliotwin) -> None:
    args = ("site", "create", "--id", "tehuantepec", "--latitude-deg", "16.3",
            "--longitude-deg", "-95.24", "--altitude-m", "60", "--timezone",
            "America/Mexico_City")
    refused = heliotwin(tmp_path, *args)
    assert refused.returncode == 2 and "already a built-in site" in refused.stderr
    forced = heliotwin(tmp_path, *args, "--force")
    assert forced.returncode == 0, forced.stderr
    show = heliotwin(tmp_path, "site", "show", "tehuantepec")
    assert "replacing the built-in site of the same id" in show.stdout
    assert json.loads(show.stdout.split("\n", 1)[1])["altitude_m"] == 60.0



def test_a_broken_file_beside_a_new_site_is_named_not_a_traceback(tmp_path: Path,
                                                                   heliotwin) -> None:
    """A draft in the sites folder whose site_id is not its file's name (a tester's copy):
    ``site create`` writes its file and says the database did not take it, naming the draft;
    a command that needs the database refuses naming it (it printed a traceback, exit 1)."""
    (tmp_path / "draft.json").write_text(json.dumps({
        "site_id": "other", "name": "x", "latitude_deg": 40, "longitude_deg": -105,
        "timezone": "America/Denver"}))
    made = heliotwin(tmp_path, "site", "create", "--id", "hamburg", "--latitude-deg", "53.52",
                     "--longitude-deg", "10.1", "--timezone", "Europe/Berlin")
    assert made.returncode == 0, made.stderr
    assert (tmp_path / "hamburg.json").is_file()
    assert "not added to the database: HELIOTWIN_SITES_DIR: " in made.stdout
    assert "draft.json: site_id 'other' does not match the file name: fix or move that file" \
        in made.stdout
    token = heliotwin(tmp_path, "token", "create", "--site", "hamburg")
    assert token.returncode == 2 and "draft.json: site_id 'other'" in token.stderr


def test_create_sets_any_key_and_drops_its_assumed_mark(tmp_path: Path, heliotwin) -> None:
    """A real array's orientation, losses and inverter, and its logger's stamps, in one
    command (a tester edited the JSON by hand for each: SERF East at 45°/158°, 14 %): each
    ``--set`` key is written and no longer marked assumed; a bad value or an unknown key is
    refused naming it, as the schema says."""
    made = heliotwin(tmp_path, "site", "create", "--id", "serf", "--latitude-deg", "39.742",
                     "--longitude-deg", "-105.1727", "--timezone", "Etc/GMT+7",
                     "--set", "arrays.fixed.surface_tilt_deg=45",
                     "--set", "arrays.fixed.surface_azimuth_deg=158",
                     "--set", "arrays.fixed.dc_loss_pct=14",
                     "--set", "arrays.tracker.inverter_limit_w=600",
                     "--set", "readings_stamped=interval_end")
    assert made.returncode == 0, made.stderr
    config = json.loads((tmp_path / "serf.json").read_text())
    fixed = config["arrays"]["fixed"]
    assert (fixed["surface_tilt_deg"], fixed["surface_azimuth_deg"], fixed["dc_loss_pct"]) == (
        45, 158, 14)
    assert config["arrays"]["tracker"]["inverter_limit_w"] == 600
    assert config["readings_stamped"] == "interval_end"
    assert "arrays.fixed.surface_tilt_deg" not in config["assumed"]
    assert "arrays.fixed.surface_azimuth_deg" not in config["assumed"]
    assert "altitude_m" in config["assumed"]  # what was not set stays marked
    bad = heliotwin(tmp_path, "site", "create", "--id", "bad", "--latitude-deg", "39.742",
                    "--longitude-deg", "-105.1727", "--timezone", "Etc/GMT+7",
                    "--set", "arrays.fixed.surface_tilt_deg=145",
                    "--set", "arrays.fixed.colour=red")
    assert bad.returncode == 2
    assert "--set arrays.fixed.surface_tilt_deg: Input should be less than or equal to 90" \
        in bad.stderr and "arrays.fixed.colour: unknown key" in bad.stderr
    assert not (tmp_path / "bad.json").exists()
    malformed = heliotwin(tmp_path, "site", "create", "--id", "m", "--latitude-deg", "1",
                          "--longitude-deg", "1", "--timezone", "UTC", "--set", "tilt")
    assert malformed.returncode == 2 and "--set: 'tilt' is not KEY=VALUE" in malformed.stderr

def test_validate_names_the_bad_field(tmp_path: Path, heliotwin) -> None:
    good = ROOT / "sim" / "data" / "sites" / "tehuantepec.json"
    bad = tmp_path / "broken.json"
    bad.write_text(json.dumps({"site_id": "broken", "latitude_deg": 16, "longitude_deg": -95,
                               "timezone": "America/Mexico_City",
                               "arrays": {"fixed": {"surface_tilt_deg": 16, "modules": 4}}}))
    p = heliotwin(tmp_path, "site", "validate", str(good), str(bad))
    assert p.returncode == 2
    assert f"{good}: ok (site tehuantepec, 2 arrays)" in p.stdout
    assert "arrays.fixed.modules: unknown key" in p.stderr


def test_from_weather_tmy3_puts_the_site_at_the_station(tmp_path: Path, heliotwin) -> None:
    p = heliotwin(tmp_path, "site", "from-weather", str(pvlib_tmy3_path()), "--id", "greensboro")
    assert p.returncode == 0, p.stderr
    site = json.loads((tmp_path / "greensboro.json").read_text())
    # the TMY3 header of 723170TYA.CSV: 36.1 N, 79.95 W, 273 m, UTC-5
    assert (site["latitude_deg"], site["longitude_deg"], site["altitude_m"]) == (36.1, -79.95, 273)
    assert site["timezone"] == "Etc/GMT+5"
    # Landau's rule (GSEE optimal_tilt) for 25° < 36.1° <= 50°: 0.76 x 36.1 + 3.1 = 30.5°
    assert site["arrays"]["fixed"]["surface_tilt_deg"] == 30.5
    assert site["arrays"]["fixed"]["surface_azimuth_deg"] == 180.0
    assert site["assumed"]["temp_air_c"] == "annual mean of 723170TYA.CSV"
    assert "Landau" in site["assumed"]["arrays.fixed.surface_tilt_deg"]
    assert 10 < site["temp_air_c"] < 20  # Greensboro's annual mean, not Tehuantepec's 27 °C
    run = heliotwin(tmp_path, "simulate", "--site", "greensboro", "--start", "1990-03-01",
                    "--end", "1990-03-03", "--step-s", "900", "--json")
    assert run.returncode == 0, run.stderr


def _epw(path: Path) -> None:
    """A one-day EPW file (EnergyPlus format) for a station at Santiago de Chile (UTC-4)."""
    head = [
        "LOCATION,Santiago,RM,CHL,hand-written,855740,-33.45,-70.67,-4.0,520.0",
        "DESIGN CONDITIONS,0", "TYPICAL/EXTREME PERIODS,0", "GROUND TEMPERATURES,0",
        "HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0", "COMMENTS 1,written by tests/test_cli_site.py",
        "COMMENTS 2,", "DATA PERIODS,1,1,Data,Sunday, 1/ 1,12/31",
    ]
    rows = []
    for hour in range(1, 25):
        sun = max(0, 900 - 120 * abs(hour - 13))
        fields = [2001, 1, 1, hour, 60, "?9?9?9?9E0?9?9?9?9*9?9?9?9?9?9?9?9?9*_*9*9*9?9?9",
                  20.0 + hour / 4, 8.0, 45, 95500, 0, 1415, 350, sun, int(sun * 0.8),
                  int(sun * 0.2), 0, 0, 0, 0, 200, 2.5, 5, 5, 20.0, 77777, 9, 999999999, 0,
                  0.1, 0, 88, 0.2, 0.0, 0.0]
        rows.append(",".join(str(f) for f in fields))
    path.write_text("\n".join(head + rows) + "\n")


def test_from_weather_epw_in_the_southern_hemisphere_faces_north(tmp_path: Path, heliotwin) -> None:
    epw = tmp_path / "santiago.epw"
    _epw(epw)
    p = heliotwin(tmp_path, "site", "from-weather", str(epw), "--id", "santiago")
    assert p.returncode == 0, p.stderr
    site = json.loads((tmp_path / "santiago.json").read_text())
    assert (site["latitude_deg"], site["longitude_deg"], site["altitude_m"]) == (-33.45, -70.67,
                                                                                520.0)
    assert site["timezone"] == "Etc/GMT+4"
    assert site["arrays"]["fixed"]["surface_azimuth_deg"] == 0.0  # the equator is north
    assert site["arrays"]["fixed"]["surface_tilt_deg"] == 28.5  # 0.76 x 33.45 + 3.1
    assert site["wind_speed_m_s"] == 2.5 and site["name"] == "Santiago, RM, CHL"
    # the tracker's azimuth range is the place's too: centred on the equator (north)
    assert (site["tracker"]["azimuth_min_deg"], site["tracker"]["azimuth_max_deg"]) == (-270, 270)
    assert "tracker.azimuth_min_deg" in site["assumed"]


def test_from_weather_reads_a_latin1_station_name(tmp_path: Path, heliotwin) -> None:
    """An EPW written on Windows names its station in Latin-1: refused with "'utf-8' codec
    can't decode byte 0xd1" (the same file uploaded ran); now read as the service reads it
    (``sim.sky.weather_text``)."""
    epw = tmp_path / "nunoa.epw"
    _epw(epw)
    epw.write_bytes(epw.read_bytes().replace(b"Santiago,RM", "Ñuñoa,RM".encode("latin-1")))
    p = heliotwin(tmp_path, "site", "from-weather", str(epw), "--id", "nunoa")
    assert p.returncode == 0, p.stderr
    assert json.loads((tmp_path / "nunoa.json").read_text())["name"] == "Ñuñoa, RM, CHL"


def test_from_weather_warns_of_a_zone_off_the_files_clock(tmp_path: Path, heliotwin) -> None:
    """``--timezone`` for a zone whose standard time is not the file's UTC offset was written
    silently, its notes saying the zone was the file's offset; now a warning names both."""
    epw = tmp_path / "santiago.epw"  # UTC-4
    _epw(epw)
    same = heliotwin(tmp_path, "site", "from-weather", str(epw), "--id", "scl",
                     "--timezone", "America/Santiago")  # -4 in standard time, -3 in summer
    assert same.returncode == 0 and "warning" not in same.stderr, same.stderr
    off = heliotwin(tmp_path, "site", "from-weather", str(epw), "--id", "aep",
                    "--timezone", "America/Argentina/Buenos_Aires")
    assert off.returncode == 0, off.stderr
    assert "UTC-3 h in standard time, the file's hours UTC-4 h" in off.stderr
    notes = json.loads((tmp_path / "aep.json").read_text())["notes"]
    assert notes.startswith("zone America/Argentina/Buenos_Aires (--timezone)") and "-4" in notes


def test_a_southern_site_s_tracker_faces_the_sun_all_afternoon(tmp_path: Path, heliotwin) -> None:
    """A tracker copied from Tehuantepec to 45° S kept its azimuth range centred on south
    (−90°…450°); the December sun there runs east → north → west, so the joint unwound
    from −5° to 167° at 17:54 with the sun 34° up: a perfect machine 1,406 mrad off (a
    tester's finding). The range now comes from the place, marked as assumed."""
    p = heliotwin(tmp_path, "site", "create", "--id", "south45", "--latitude-deg", "-45",
                  "--longitude-deg", "170.5", "--timezone", "Pacific/Auckland")
    assert p.returncode == 0, p.stderr
    assert "assumed tracker.azimuth_min_deg = -270.0" in p.stdout
    site = json.loads((tmp_path / "south45.json").read_text())
    assert (site["tracker"]["azimuth_min_deg"], site["tracker"]["azimuth_max_deg"]) == (-270, 270)
    assert site["tracker"]["d1_m"] == 0.355  # the rest of the machine is --like's
    run = heliotwin(tmp_path, "simulate", "--site", "south45", "--start", "2024-12-21",
                    "--end", "2024-12-22", "--step-s", "300", "--controller", "open_loop_spa",
                    "--json")
    assert run.returncode == 0, run.stderr
    # as a northern site in June (north60: 2.9 mrad rms, 4.4 at most): the dead band's few
    assert json.loads(run.stdout)["pointing_error_max_mrad"] < 5.0


def test_a_weather_file_is_known_by_its_content(tmp_path: Path, heliotwin) -> None:
    """pvlib's TMY2 file (12839.tm2) was read as TMY3 for its suffix and refused with
    pvlib's bare KeyError, ``'altitude'``; the first line now decides, and a file of
    another format is refused saying what is read."""
    tmy2 = Path(pvlib_tmy3_path()).with_name("12839.tm2")
    p = heliotwin(tmp_path, "site", "from-weather", str(tmy2), "--id", "miami")
    assert p.returncode == 2 and "'altitude'" not in p.stderr
    assert "neither TMY3 nor EPW" in p.stderr and "TMY2" in p.stderr
    wrong = heliotwin(tmp_path, "site", "from-weather", str(pvlib_tmy3_path()), "--id", "gb",
                      "--format", "epw")
    assert wrong.returncode == 2 and "--format epw" in wrong.stderr
    assert "is a TMY3 file" in wrong.stderr
    renamed = tmp_path / "greensboro.epw"  # a TMY3 CSV under an EPW name: read as TMY3
    renamed.write_bytes(pvlib_tmy3_path().read_bytes())
    ok = heliotwin(tmp_path, "site", "from-weather", str(renamed), "--id", "greensboro")
    assert ok.returncode == 0, ok.stderr
    assert json.loads((tmp_path / "greensboro.json").read_text())["source"].startswith("TMY3")


@pytest.mark.parametrize("offset", [5.5, -3.5])
def test_a_half_hour_offset_has_no_etc_zone(offset: float) -> None:
    from backend.cli.site import fixed_offset_zone

    with pytest.raises(ValueError, match="--timezone"):
        fixed_offset_zone(offset)
    assert fixed_offset_zone(-6) == "Etc/GMT+6" and fixed_offset_zone(1) == "Etc/GMT-1"


def test_the_etc_zones_run_from_utc_minus_12_to_utc_plus_14() -> None:
    """Tonga's UTC+13 (and Kiribati's +14) had no zone, "pass --timezone", while a −13 (no
    place keeps it) was written as ``Etc/GMT+13``, which is no zone."""
    from zoneinfo import ZoneInfo

    from backend.cli.site import fixed_offset_zone

    for offset in (-12, 13, 14):
        ZoneInfo(fixed_offset_zone(offset))  # a zone that exists
    assert fixed_offset_zone(13) == "Etc/GMT-13" and fixed_offset_zone(-12) == "Etc/GMT+12"
    for offset in (-13, 15):
        with pytest.raises(ValueError, match="--timezone"):
            fixed_offset_zone(offset)


def test_the_library_and_the_service_default_to_the_same_user_folder(monkeypatch) -> None:
    from backend.settings import get_settings
    from sim.sites import default_user_sites_dir

    monkeypatch.delenv("HELIOTWIN_SITES_DIR", raising=False)
    assert get_settings().sites.user_dir == default_user_sites_dir()


@pytest.mark.parametrize(("flags", "words"), [
    (["--latitude-deg", "95", "--timezone", "UTC"], "--latitude-deg: Input should be less"),
    (["--latitude-deg", "45", "--timezone", "Mars/Base"], "--timezone: 'Mars/Base' is not"),
])
def test_a_bad_flag_is_named_by_its_flag(tmp_path: Path, heliotwin, flags: list[str],
                                         words: str) -> None:
    """A tester's finding: ``--latitude-deg 95`` was refused as ``site: latitude_deg: …``,
    the config's key, not the flag that was typed."""
    p = heliotwin(tmp_path, "site", "create", "--id", "bad", "--longitude-deg", "10", *flags)
    assert p.returncode == 2 and words in p.stderr, p.stderr
    assert "site: " not in p.stderr


def test_demo_logger_names_a_site_without_the_twins_arrays(tmp_path: Path, heliotwin) -> None:
    """A tester's site of strings (no arrays named tracker and fixed): demo-logger crashed
    with a traceback and exited 0; the twin it posts needs both."""
    site = json.loads((ROOT / "sim" / "data" / "sites" / "tehuantepec.json").read_text())
    site["site_id"] = "strings"
    site["arrays"] = {"east_string": site["arrays"]["tracker"],
                      "west_string": site["arrays"]["fixed"]}
    (tmp_path / "strings.json").write_text(json.dumps(site))
    p = heliotwin(tmp_path, "demo-logger", "--site", "strings", "--token", "t", "--once",
                  "--url", "http://127.0.0.1:9")
    assert p.returncode == 2, (p.returncode, p.stderr)
    assert p.stderr.strip().splitlines() == [
        "heliotwin demo-logger: error: --site: 'strings' has arrays east_string, west_string; "
        "the demo logger posts the twin's readings and needs arrays 'tracker' and 'fixed' "
        "(mounts tracker and fixed)"], p.stderr


def test_a_zone_far_from_the_longitude_is_written_with_a_warning(tmp_path: Path,
                                                                   heliotwin) -> None:
    """Alice Springs (133.9° E) in Europe/Berlin was written without a word, its clear-sky
    noon at 04:08 (a tester's finding): now a warning on stderr naming both numbers; Samoa's
    +13 h at 171.8° W (across the date line) is no warning."""
    p = heliotwin(tmp_path, "site", "create", "--id", "alice-berlin", "--latitude-deg",
                  "-23.7", "--longitude-deg", "133.88", "--timezone", "Europe/Berlin")
    assert p.returncode == 0, p.stderr
    assert ("warning: timezone: timezone Europe/Berlin UTC+1 h is 7.9 h from the longitude's "
            "133.9° / 15 = +8.9 h (more than 3 h)") in p.stderr
    assert (tmp_path / "alice-berlin.json").exists()
    samoa = heliotwin(tmp_path, "site", "create", "--id", "samoa", "--latitude-deg", "-13.8",
                      "--longitude-deg", "-171.8", "--timezone", "Pacific/Apia")
    assert samoa.returncode == 0 and "warning" not in samoa.stderr


def test_a_new_sites_altitude_is_the_grounds_and_marked_assumed(tmp_path: Path,
                                                                  heliotwin) -> None:
    """La Paz without --altitude-m was written at 0 m, unmarked: 13 % of a clear day's
    energy (a tester's finding); now pvlib's terrain table's 3,862 m, under ``assumed``."""
    p = heliotwin(tmp_path, "site", "create", "--id", "lapaz", "--latitude-deg", "-16.5",
                  "--longitude-deg", "-68.15", "--timezone", "America/La_Paz")
    assert p.returncode == 0, p.stderr
    written = json.loads((tmp_path / "lapaz.json").read_text())
    assert written["altitude_m"] == 3862.0
    assert "lookup_altitude" in written["assumed"]["altitude_m"]
    assert "assumed altitude_m = 3862" in p.stdout
    given = heliotwin(tmp_path, "site", "create", "--id", "lapaz2", "--latitude-deg", "-16.5",
                      "--longitude-deg", "-68.15", "--timezone", "America/La_Paz",
                      "--altitude-m", "3640")
    written = json.loads((tmp_path / "lapaz2.json").read_text())
    assert given.returncode == 0 and written["altitude_m"] == 3640.0
    assert "altitude_m" not in written["assumed"]


def test_create_holds_the_write_lock_while_a_service_writes(tmp_path: Path, heliotwin,
                                                             monkeypatch) -> None:
    """A running service writes the new file's rows itself (it sees the file within a
    second) while its loggers commit: ``site create`` read the sites in a deferred
    transaction and failed at its write, "the database could not take it now" (a user's
    first ``site from-weather`` beside ``make run``). It now takes the write lock first:
    another writer is refused meanwhile, and the site's row is stored."""
    import sqlite3

    import backend.sites

    real_sync = backend.sites.sync_sites
    others: list[str] = []

    def sync_while_another_writes(conn: Any, sites: list[Any]) -> Any:
        list(conn.exec_driver_sql("SELECT count(*) FROM sites"))  # the CLI has read
        other = sqlite3.connect(tmp_path / "cli.sqlite", timeout=0)
        try:
            other.execute("CREATE TABLE IF NOT EXISTS another_writer (x)")
            other.execute("INSERT INTO another_writer VALUES (1)")
            other.commit()
            others.append("committed")
        except sqlite3.OperationalError as exc:
            others.append(str(exc))
        finally:
            other.close()
        return real_sync(conn, sites)

    monkeypatch.setattr(backend.sites, "sync_sites", sync_while_another_writes)
    p = heliotwin(tmp_path, "site", "create", "--id", "hamburg", "--latitude-deg", "53.52",
                  "--longitude-deg", "10.1", "--timezone", "Europe/Berlin")
    assert p.returncode == 0, p.stderr
    assert "could not take it" not in p.stdout, p.stdout
    assert others == ["database is locked"]
    with sqlite3.connect(tmp_path / "cli.sqlite") as db:
        assert db.execute("SELECT site_id FROM sites WHERE site_id = 'hamburg'").fetchall() \
            == [("hamburg",)]


@pytest.mark.parametrize("args", [
    ["sun", "--site", "my-roof", "--time", "2024-03-15T12:00:00Z"],
    ["simulate", "--site", "my-roof", "--start", "2024-03-15", "--end", "2024-03-16"],
    ["site", "create", "--id", "roof2", "--latitude-deg", "36", "--longitude-deg", "-80",
     "--timezone", "America/New_York", "--like", "my-roof"],
    ["demo-logger", "--site", "my-roof", "--token", "t", "--once"],
], ids=lambda a: a[0] if a[0] != "site" else "site-create")
def test_a_malformed_site_file_is_refused_naming_its_fields(tmp_path: Path, heliotwin,
                                                            args: list[str]) -> None:
    """docs/sites.md's malformed ``my-roof.json`` (latitude 91, a key ``tilt``): ``sun``,
    ``simulate``, ``site create --like`` and ``demo-logger`` printed a ValueError traceback
    (exit 1) where ``site show`` and ``vision detect`` named the fields (exit 2)."""
    (tmp_path / "my-roof.json").write_text(json.dumps({
        "site_id": "my-roof", "latitude_deg": 91, "longitude_deg": -79.95,
        "timezone": "America/New_York",
        "arrays": {"tracker": {"mount": "tracker"},
                   "fixed": {"mount": "fixed", "surface_tilt_deg": 36, "tilt": 36}}}))
    p = heliotwin(tmp_path, *args)
    assert p.returncode == 2, p.stderr
    assert "error: " in p.stderr and "Traceback" not in p.stderr
    assert "latitude_deg: Input should be less than or equal to 90" in p.stderr
    assert "arrays.fixed.tilt: unknown key" in p.stderr
