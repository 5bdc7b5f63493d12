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
