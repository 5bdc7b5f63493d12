"""A day too short of readings for the shape fits says so, over HTTP: a 30-minute logger at
Madrid (40.45° N) in December has about 17 readings under the sun, under the 20 a stuck or
clock-offset fit needs (faults.SHAPE_READINGS_PER_PARAMETER × SHAPE_PARAMETERS), and such a
day was never fitted without a word (a tester's finding). The loggers' power is pvlib's alone
(Ineichen clear sky, isotropic sky, SAPM cell temperature, the CEC single diode of the
KD205GX-LP, four in parallel): a healthy tracker and the fixed array at 33.8°."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pvlib
from live_service import InProcessServer, new_database

ROOT = Path(__file__).resolve().parents[2]
ADMIN = "admin-for-untested-tests"
SITE = "madrid_untested"
LAT, LON, ALT, TILT = 40.45, -3.7, 670.0, 33.8


def _config() -> dict:
    config = json.loads((ROOT / "sim" / "data" / "sites" / "tehuantepec.json").read_text())
    config.update(site_id=SITE, name="Madrid (untested-day test)", latitude_deg=LAT,
                  longitude_deg=LON, altitude_m=ALT, timezone="Europe/Madrid", temp_air_c=10.0)
    config["arrays"]["fixed"].update(surface_tilt_deg=TILT, surface_azimuth_deg=180.0)
    return config


def _readings(start: str, days: int, step_min: int) -> list[dict]:
    """Both arrays' power [W] every ``step_min`` minutes by pvlib alone, as instants."""
    from pvlib import irradiance, pvsystem, temperature

    loc = pvlib.location.Location(LAT, LON, altitude=ALT)
    t0 = pd.Timestamp(start, tz="Europe/Madrid")
    t = pd.date_range(t0, t0 + pd.Timedelta(days=days), freq=f"{step_min}min",
                      inclusive="left")
    sp, cs = loc.get_solarposition(t), loc.get_clearsky(t)
    mod = pvsystem.retrieve_sam("CECMod")["Kyocera_Solar_KD205GX_LP"]
    up = (sp["apparent_elevation"] > 0).to_numpy()

    def power(tilt: object, azimuth: object) -> np.ndarray:
        poa = irradiance.get_total_irradiance(tilt, azimuth, sp["apparent_zenith"],
                                              sp["azimuth"], cs["dni"], cs["ghi"], cs["dhi"],
                                              albedo=0.2)["poa_global"]
        cell = temperature.sapm_cell(poa, 10.0, 1.0, -3.56, -0.075, 3)
        params = pvsystem.calcparams_cec(poa, cell, mod["alpha_sc"], mod["a_ref"],
                                         mod["I_L_ref"], mod["I_o_ref"], mod["R_sh_ref"],
                                         mod["R_s"], mod["Adjust"])
        p_mp = pvsystem.max_power_point(*params, method="newton")["p_mp"]
        return np.clip(np.nan_to_num(4 * np.asarray(p_mp, float)), 0, None)

    tracker = power(np.where(up, sp["apparent_zenith"], 0.0), np.where(up, sp["azimuth"], 180))
    fixed = power(TILT, 180.0)
    return [{"ts": ts.tz_convert("UTC").isoformat(), "array": name, "power_w": round(float(p), 2)}
            for i, ts in enumerate(t) for name, p in (("tracker", tracker[i]), ("fixed", fixed[i]))]


def test_a_day_too_short_of_readings_for_the_shape_fits_says_so(tmp_path: Path) -> None:
    """30-minute readings, 1–3 December: each day says it was not tested, with its readings
    (measured 16.5–16.7; pvlib puts the sun over 5° at 17 of each day's stamps) of the 20
    needed; 15-minute readings, 5–6 December (33 under the sun), are tested: null."""
    db = new_database("sqlite", tmp_path)
    with InProcessServer(db.url, extra_env={"HELIOTWIN_SITES_DIR": str(tmp_path / "sites"),
                                            "HELIOTWIN_ADMIN_TOKEN": ADMIN,
                                            "HELIOTWIN_ENERGY_MAX_GAP_S": "3600"}) as server, \
            server.client(timeout_s=300) as client:
        r = client.put(f"/api/v1/sites/{SITE}", json=_config(),
                       headers={"Authorization": f"Bearer {ADMIN}"})
        assert r.status_code == 201, r.text
        token = {"Authorization": f"Bearer {server.token(SITE)}"}
        for start, days, step in (("2025-12-01", 3, 30), ("2025-12-05", 2, 15)):
            r = client.post(f"/api/v1/sites/{SITE}/measurements",
                            json={"readings": _readings(start, days, step)}, headers=token)
            assert r.status_code == 200, r.text
        slow = client.get(f"/api/v1/sites/{SITE}/diagnosis",
                          params={"start": "2025-12-01", "end": "2025-12-04"})
        fast = client.get(f"/api/v1/sites/{SITE}/diagnosis",
                          params={"start": "2025-12-05", "end": "2025-12-07"})
        assert slow.status_code == fast.status_code == 200, (slow.text, fast.text)
    db.drop()
    for day in slow.json()["days"]:
        untested = day["shape_untested"]
        assert untested is not None, day
        assert 16 <= untested["readings"] < 18 and untested["needed"] == 20, untested
        assert "about 17 tracker readings under the sun" in untested["detail"], untested
        assert "stuck tracker, a clock offset" in untested["detail"], untested
    for day in fast.json()["days"]:
        assert day["shape_untested"] is None, day
