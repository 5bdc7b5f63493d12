"""Sites: the built-in tehuantepec (seed 000), listing, errors."""

import json

import pytest

from sim.sites import UnknownSiteError, default_sites_dir, list_sites, load_site


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
    ({"drives": {"azimuth": {"gear_ratoi": 3.0}}}, "tracker.drives.azimuth: unknown keys"),
    ({"drives": {"roll": {}}}, "tracker.drives must be"),
    ({"inertia": {"m2_kg": "heavy"}}, "tracker.inertia"),
])
def test_bad_drives_name_the_field(tmp_path, tracker: dict, words: str) -> None:
    with pytest.raises(ValueError, match=words):
        _with_tracker(tmp_path, tracker)
