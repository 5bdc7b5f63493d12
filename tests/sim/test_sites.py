"""Sites: the built-in tehuantepec (seed 000), listing, errors."""

import json
import re
from pathlib import Path

import pytest

from sim.sites import (
    UnknownSiteError,
    default_sites_dir,
    list_sites,
    load_site,
    site_from_dict,
    site_path,
)


def test_tehuantepec_is_seed_000_prototype() -> None:
    site = load_site("tehuantepec")
    # seed 000, section 2.4: 16°17'19.499" N, 95°14'27.135" W
    assert site.latitude == pytest.approx(16 + 17 / 60 + 19.499 / 3600, abs=1e-5)
    assert site.longitude == pytest.approx(-(95 + 14 / 60 + 27.135 / 3600), abs=1e-5)
    assert site.timezone == "America/Mexico_City"
    assert set(site.arrays) == {"tracker", "fixed"}
    assert site.arrays["tracker"].mount == "tracker"
    fixed = site.arrays["fixed"]
    assert (fixed.surface_tilt, fixed.surface_azimuth) == (16.0, 180.0)  # seed 000, eq. 20
    assert site.arrays["tracker"].modules == fixed.modules == 4
    assert (site.tracker.d1_m, site.tracker.a2_m) == (0.355, 0.091)  # seed 002


def test_to_dict_is_json_with_units() -> None:
    d = load_site("tehuantepec").to_dict()
    text = json.dumps(d)
    assert '"latitude_deg"' in text and '"surface_tilt_deg"' in text
    assert d["arrays"]["fixed"]["stc_power_w"] == pytest.approx(4 * 205.086, rel=1e-4)
    assert d["arrays"]["tracker"]["wiring"] == "parallel"


def test_list_and_unknown() -> None:
    ids = [s.site_id for s in list_sites()]
    assert "tehuantepec" in ids
    assert default_sites_dir().name == "sites"
    with pytest.raises(UnknownSiteError, match="tehuantepec"):
        load_site("atlantis")
    with pytest.raises(UnknownSiteError):
        load_site("../sites/tehuantepec")


def test_malformed_site_names_the_key(tmp_path) -> None:
    (tmp_path / "bad.json").write_text(json.dumps({"site_id": "bad", "latitude_deg": 10}))
    with pytest.raises(ValueError, match="longitude_deg"):
        load_site("bad", tmp_path)
    (tmp_path / "tz.json").write_text(
        json.dumps(
            {"site_id": "tz", "latitude_deg": 10, "longitude_deg": 0, "timezone": "Mars/Olympus"}
        )
    )
    with pytest.raises(ValueError, match="timezone"):
        load_site("tz", tmp_path)


def _with_tracker(tmp_path, tracker: dict) -> object:
    d = json.loads((default_sites_dir() / "tehuantepec.json").read_text())
    d["site_id"] = "custom"
    d["tracker"].update(tracker)
    (tmp_path / "custom.json").write_text(json.dumps(d))
    return load_site("custom", tmp_path)


def test_drives_and_inertia_come_from_the_config(tmp_path) -> None:
    site = load_site("tehuantepec")
    assert site.drives["elevation"].supply_voltage_v == 24.0  # seed 000: MD03 drivers at 24 V
    assert site.drives["azimuth"].gear_ratio == 1000.0
    assert site.inertia.m2_kg == pytest.approx(37.73207)  # seed 002, Table 1
    custom = _with_tracker(tmp_path, {"drives": {"elevation": {"standby_power_w": 2.0}},
                                      "inertia": {"m2_kg": 50.0}})
    assert custom.drives["elevation"].standby_power_w == 2.0
    assert custom.drives["elevation"].gear_ratio == 1500.0  # the rest from the defaults
    assert custom.inertia.m2_kg == 50.0
    assert json.loads(json.dumps(custom.to_dict()))["tracker"]["drives"]["elevation"][
        "standby_power_w"] == 2.0


def test_a_site_s_drives_set_the_actuator_energy(tmp_path) -> None:
    import pandas as pd

    from sim.twin import simulate

    start = pd.Timestamp("2024-03-15", tz="America/Mexico_City")
    runs = [simulate(site, start, start + pd.Timedelta(days=1), step_s=300,
                     controller="open_loop_spa").summary()
            for site in (load_site("tehuantepec"),
                         _with_tracker(tmp_path, {"drives": {
                             "azimuth": {"standby_power_w": 1.0},
                             "elevation": {"standby_power_w": 1.0}}}))]
    # standby: 2 × 0.25 W × 24 h = 12 Wh, then 2 × 1 W × 24 h = 48 Wh
    assert runs[0]["actuator_standby_energy_wh"] == pytest.approx(12.0)
    assert runs[1]["actuator_standby_energy_wh"] == pytest.approx(48.0)


@pytest.mark.parametrize(("tracker", "words"), [
    ({"drives": {"azimuth": {"gear_ratoi": 3.0}}},
     "tracker.drives.azimuth.gear_ratoi: unknown key"),
    ({"drives": {"roll": {}}}, "tracker.drives.roll: unknown key"),
    ({"inertia": {"m2_kg": "heavy"}}, "tracker.inertia.m2_kg: Input should be a valid number"),
    ({"azimuth_min_deg": 10.0, "azimuth_max_deg": 0.0}, "tracker: azimuth_min_deg"),
])
def test_bad_drives_name_the_field(tmp_path, tracker: dict, words: str) -> None:
    with pytest.raises(ValueError, match=words):
        _with_tracker(tmp_path, tracker)


# ------------------------------------------------ the documented format (issue 14, item 8)

SCHEMA = Path(__file__).resolve().parents[2] / "docs" / "site.schema.json"


def test_the_shipped_schema_is_the_model_s() -> None:
    from sim.site_config import site_json_schema

    assert json.loads(SCHEMA.read_text()) == site_json_schema(), (
        "docs/site.schema.json is stale: regenerate it with `heliotwin site schema > "
        "docs/site.schema.json`")


def _leaves(schema: dict, defs: dict, path: str = "") -> list[tuple[str, dict]]:
    """Every scalar field of the schema with its dotted path."""
    out = []
    for name, prop in schema.get("properties", {}).items():
        ref = prop.get("$ref") or (prop.get("additionalProperties") or {}).get("$ref")
        if ref:
            out += _leaves(defs[ref.split("/")[-1]], defs, f"{path}{name}.")
        else:
            out.append((f"{path}{name}", prop))
    return out


def test_every_field_of_the_schema_says_its_unit_and_default() -> None:
    schema = json.loads(SCHEMA.read_text())
    leaves = _leaves(schema, schema["$defs"])
    assert len(leaves) > 40  # site, tracker, two drives, inertia, array fields
    for path, prop in leaves:
        assert prop.get("description"), f"{path} has no description"
        if prop.get("type") in ("number", "integer"):
            assert prop["description"].startswith("["), f"{path}: no unit in {prop}"
        if "default" in prop and prop["default"] not in ("", None):
            assert "Default" in prop["description"], f"{path}: default not described"


def test_a_site_written_by_hand_from_the_schema_loads_and_simulates(tmp_path) -> None:
    """A second, independently written site (Greensboro NC, the pvlib TMY3 station):
    only the required keys and two arrays, everything else from the documented defaults."""
    import pandas as pd

    from sim.twin import simulate

    hand = {"$schema": "../docs/site.schema.json", "site_id": "my-roof", "latitude_deg": 36.1,
            "longitude_deg": -79.95, "timezone": "America/New_York",
            "arrays": {"tracker": {"mount": "tracker"},
                       "fixed": {"surface_tilt_deg": 36, "surface_azimuth_deg": 180}}}
    (tmp_path / "my-roof.json").write_text(json.dumps(hand))
    site = load_site("my-roof", tmp_path)
    assert site.name == "my-roof" and site.altitude == 0.0
    assert site.arrays["fixed"].surface_tilt == 36.0 and site.arrays["fixed"].mount == "fixed"
    summary = simulate(site, pd.Timestamp("2024-06-21", tz="America/New_York"),
                       pd.Timestamp("2024-06-22", tz="America/New_York"), step_s=600).summary()
    assert summary["tracker_energy_wh"] > summary["fixed_energy_wh"] > 0


@pytest.mark.parametrize(("change", "words"), [
    ({"latitude_deg": 91}, "latitude_deg: Input should be less than or equal to 90"),
    ({"timezone": "UTC+5"}, "timezone: 'UTC+5' is not an IANA time zone"),
    # the machine's own zone, a file beside the names: the days would move with the machine
    ({"timezone": "localtime"}, "timezone: 'localtime' is not an IANA time zone"),
    ({"site_id": "My Roof"}, "site_id: String should match pattern"),
    ({"arrays": {"fixed": {"surface_tilt_deg": "steep"}}}, "arrays.fixed.surface_tilt_deg"),
    ({"arrays": {"fixed": {"module": "Acme_9000"}}}, "arrays.fixed.module: module 'Acme_9000'"),
    ({"arrays": {"fixed": {"mount": "roof"}}}, "arrays.fixed.mount: Input should be 'tracker'"),
    ({"altitude": 10}, "altitude: unknown key"),
])
def test_a_malformed_site_names_the_field(change: dict, words: str) -> None:
    from sim.site_config import validate_site_config

    good = {"site_id": "ok", "latitude_deg": 10, "longitude_deg": 0, "timezone": "UTC"}
    validate_site_config(good)
    with pytest.raises(ValueError, match=re.escape(words)):
        validate_site_config({**good, **change}, where="ok.json")


def test_a_user_folder_adds_to_the_built_in_sites_and_wins_on_a_shared_id(tmp_path) -> None:
    d = load_site("tehuantepec").to_config()
    (tmp_path / "tehuantepec.json").write_text(json.dumps({**d, "altitude_m": 123.0}))
    (tmp_path / "extra.json").write_text(json.dumps({**d, "site_id": "extra"}))
    ids = [s.site_id for s in list_sites(tmp_path)]
    assert ids == ["extra", "guadalajara_fisheye", "tehuantepec"]
    assert load_site("tehuantepec", tmp_path).altitude == 123.0  # the user's file wins
    assert load_site("tehuantepec").altitude == 50.0
    assert load_site("guadalajara_fisheye", tmp_path).arrays == {}  # built-in still there
    assert site_path("tehuantepec", tmp_path) == tmp_path / "tehuantepec.json"


def test_to_config_round_trips() -> None:
    for site in list_sites():
        assert site_from_dict(json.loads(json.dumps(site.to_config()))) == site


@pytest.mark.parametrize("latitude", [16.29, -23.5, -45.0, 69.65, -69.0, 0.0, 52.0])
def test_a_relocated_tracker_follows_every_day_without_unwinding_in_daylight(
        latitude: float) -> None:
    """A tracker copied to a new place takes its azimuth range from the place
    (``sim.sites.tracker_azimuth_range_deg``): the twin's joint angles over a year
    (``sim.kinematics.inverse_kinematics`` with the twin's daily reference) then move with
    the sun's own azimuth, the short way, at every step while the sun is up. The sun is
    pvlib's SPA; the one exception is a midnight sun's daily unwind, at its lowest (below
    5°, the twin's pointing-error floor). Copied from Tehuantepec unchanged (range centred
    on south), a tracker at 45° S unwound 170° in the afternoon sun (a tester's finding)."""
    import numpy as np
    import pandas as pd
    from pvlib import solarposition

    from sim.control import noon_reference_azimuth
    from sim.kinematics import inverse_kinematics
    from sim.sites import relocated_config

    template = load_site("tehuantepec").to_config()
    config = relocated_config(template, {"site_id": "here", "latitude_deg": latitude,
                                         "longitude_deg": 10.0, "timezone": "UTC"})
    site = site_from_dict(config)
    lo, hi = site.tracker.azimuth_min_deg, site.tracker.azimuth_max_deg
    assert hi - lo == 540.0  # Tehuantepec's span: the machine's, kept
    assert (lo + hi) / 2 == (180.0 if latitude >= 0 else 0.0)  # centred on the equator side
    assert {"tracker.azimuth_min_deg", "tracker.azimuth_max_deg"} <= set(config["assumed"])
    times = pd.date_range("2023-01-01", "2024-01-01", freq="20min", tz="UTC", inclusive="left")
    sun = solarposition.get_solarposition(times, latitude, 10.0, method="nrel_numpy")
    az_sun = sun["azimuth"].to_numpy()
    elevation = sun["apparent_elevation"].to_numpy()
    joint, _ = inverse_kinematics(az_sun, elevation, site.tracker,
                                  reference_azimuth=noon_reference_azimuth(times, site))
    up = (elevation[1:] > 5.0) & (elevation[:-1] > 5.0)
    sun_step = (np.diff(az_sun) + 180.0) % 360.0 - 180.0  # the sun's move, the short way
    off = np.abs(np.diff(joint) - sun_step)[up]
    assert up.any() and off.max() < 1e-6, f"unwound {off.max():.0f}° with the sun up"


def test_a_note_may_span_lines_but_holds_no_nul() -> None:
    """Tabs and line ends are text; a NUL (PostgreSQL refuses it) or an escape is not."""
    from sim.site_config import validate_site_config
    from sim.sites import load_site

    config = load_site("tehuantepec").to_config()
    validate_site_config({**config, "notes": "line one\n\tline two\r\n"})
    for bad in ("a\x00b", "a\x1bb"):
        with pytest.raises(ValueError, match="notes: holds a control character"):
            validate_site_config({**config, "notes": bad})


def test_an_arrays_dc_loss_is_bounded_and_named() -> None:
    from sim.site_config import validate_site_config
    from sim.sites import load_site, site_from_dict

    config = load_site("tehuantepec").to_config()
    fixed = config["arrays"]["fixed"]
    lossy = {**config, "arrays": {**config["arrays"], "fixed": {**fixed, "dc_loss_pct": 16}}}
    site = site_from_dict(lossy)
    assert site.arrays["fixed"].dc_loss_pct == 16.0
    assert site_from_dict(site.to_config()) == site  # the config keeps it
    for bad in (-1, 51):
        with pytest.raises(ValueError, match="arrays.fixed.dc_loss_pct"):
            validate_site_config({**config, "arrays": {**config["arrays"],
                                                       "fixed": {**fixed, "dc_loss_pct": bad}}})
