"""PV electrics: KD205GX-LP datasheet at STC, wiring, MPP table vs pvlib's full solution."""

import numpy as np
import pandas as pd
import pytest
from pvlib import iam, irradiance, location, pvsystem, temperature

from sim.pv import (
    KD205GX_LP,
    ArrayConfig,
    array_config_from_dict,
    array_mpp,
    cec_module_parameters,
    cell_temperature,
    iv_curve,
    module_mpp_exact,
    mpp_table,
)

# Kyocera KD205GX-LP datasheet, STC (seed 000; ../shared/reference/sites.json)
DATASHEET = {"p_mp": 205.0, "v_mp": 26.6, "i_mp": 7.71, "v_oc": 33.2, "i_sc": 8.36}


def test_module_comes_from_pvlib_cec_table() -> None:
    row = pvsystem.retrieve_sam("CECMod")[KD205GX_LP]
    params = cec_module_parameters()
    for key in ("I_L_ref", "I_o_ref", "R_s", "R_sh_ref", "a_ref", "Adjust", "alpha_sc"):
        assert params[key] == row[key]
    assert params["N_s"] == 54


def test_stc_matches_datasheet_within_1pct() -> None:
    sol = module_mpp_exact(np.array([1000.0]), np.array([25.0]))
    for key, expected in DATASHEET.items():
        assert sol[key][0] == pytest.approx(expected, rel=0.01), key


def test_array_wiring_scales_current_or_voltage() -> None:
    e, t = np.array([1000.0]), np.array([25.0])
    parallel = array_mpp(e, t, ArrayConfig("p", strings_in_parallel=4, modules_in_series=1))
    series = array_mpp(e, t, ArrayConfig("s", strings_in_parallel=1, modules_in_series=4))
    assert parallel["current_a"][0] == pytest.approx(4 * DATASHEET["i_mp"], rel=0.01)
    assert parallel["voltage_v"][0] == pytest.approx(DATASHEET["v_mp"], rel=0.01)
    assert series["voltage_v"][0] == pytest.approx(4 * DATASHEET["v_mp"], rel=0.01)
    assert series["power_w"][0] == pytest.approx(parallel["power_w"][0], rel=1e-9)
    # the default (seed 000 hint: ACS712-30A) is four modules in parallel, ~31 A at MPP
    assert ArrayConfig("default").wiring == "parallel"
    assert 30 < array_mpp(e, t, ArrayConfig("d"))["current_a"][0] < 32


def test_cell_temperature_is_sapm() -> None:
    # King et al. (2004), open rack glass/polymer: a=-3.56, b=-0.075, dT=3 C
    t_module = 25 + 1000 * np.exp(-3.56 - 0.075 * 1.0)
    assert cell_temperature(np.array([1000.0]), 25.0, 1.0)[0] == pytest.approx(
        t_module + 3, abs=1e-6
    )


def test_mpp_table_close_to_full_single_diode_over_a_clear_year() -> None:
    # Realistic (irradiance, temperature) pairs from an independent pvlib chain:
    # a clear-sky year at Tehuantepec on the fixed 16 deg south plane, 10-min steps.
    loc = location.Location(16.28875, -95.240871, altitude=50)
    times = pd.date_range("2024-01-01", "2025-01-01", freq="10min", inclusive="left", tz="UTC")
    sp = loc.get_solarposition(times)
    cs = loc.get_clearsky(times, solar_position=sp)
    poa = irradiance.get_total_irradiance(
        16,
        180,
        sp["apparent_zenith"],
        sp["azimuth"],
        cs["dni"],
        cs["ghi"],
        cs["dhi"],
        dni_extra=irradiance.get_extra_radiation(times),
        model="haydavies",
    )
    aoi = irradiance.aoi(16, 180, sp["apparent_zenith"], sp["azimuth"])
    e = (poa["poa_direct"] * iam.physical(aoi) + poa["poa_diffuse"]).fillna(0).to_numpy()
    p = temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"]["open_rack_glass_polymer"]
    t = temperature.sapm_cell(poa["poa_global"].fillna(0), 27.0, 1.0, **p).to_numpy()
    lit = e > 0
    module = pvsystem.retrieve_sam("CECMod")[KD205GX_LP]
    sd = pvsystem.singlediode(
        *pvsystem.calcparams_cec(
            e[lit],
            t[lit],
            module["alpha_sc"],
            module["a_ref"],
            module["I_L_ref"],
            module["I_o_ref"],
            module["R_sh_ref"],
            module["R_s"],
            module["Adjust"],
        )
    )
    i_mp, v_mp = mpp_table().lookup(e[lit], t[lit])
    energy_full, energy_table = sd["p_mp"].sum(), (i_mp * v_mp).sum()
    # measured: -0.00058 % in energy, 0.035 W per module at worst; bounds 2x those
    # (the twin's own years, both arrays, clear sky and TMY3: tests/sim/test_mpp_year.py)
    assert -1.2e-5 < energy_table / energy_full - 1 < 0
    assert np.max(np.abs(i_mp * v_mp - sd["p_mp"])) < 0.07  # W per module, at every step


def test_mpp_table_falls_back_to_exact_outside_grid() -> None:
    e, t = np.array([1600.0, 0.0, -5.0]), np.array([110.0, 25.0, 25.0])
    i_mp, v_mp = mpp_table().lookup(e, t)
    exact = module_mpp_exact(e[:1], t[:1])
    assert i_mp[0] * v_mp[0] == pytest.approx(exact["p_mp"][0], rel=1e-9)
    assert i_mp[1:] == pytest.approx([0, 0]) and v_mp[1:] == pytest.approx([0, 0])


def test_iv_curve_ends_at_isc_and_voc_and_peaks_at_mpp() -> None:
    arr = ArrayConfig("t", strings_in_parallel=4)
    curve = iv_curve(800.0, 45.0, arr, points=400)
    exact = module_mpp_exact(np.array([800.0]), np.array([45.0]))
    assert curve["current_a"].iloc[0] == pytest.approx(4 * exact["i_sc"][0], rel=1e-6)
    assert curve["voltage_v"].iloc[-1] == pytest.approx(exact["v_oc"][0], rel=1e-6)
    assert curve["current_a"].iloc[-1] == pytest.approx(0.0, abs=1e-6)
    assert curve["power_w"].max() == pytest.approx(4 * exact["p_mp"][0], rel=1e-3)
    with pytest.raises(ValueError, match="effective_irradiance"):
        iv_curve(0.0, 25.0, arr)


def test_array_config_from_dict_rejects_unknown_keys() -> None:
    arr = array_config_from_dict("fixed", {"mount": "fixed", "surface_tilt_deg": 16})
    assert arr.surface_tilt == 16 and arr.modules == 4
    with pytest.raises(ValueError, match="tilt_degrees"):
        array_config_from_dict("fixed", {"tilt_degrees": 16})
    with pytest.raises(ValueError, match="mount"):
        ArrayConfig("x", mount="roof")


def test_an_arrays_dc_loss_takes_its_share_of_the_current_alone() -> None:
    """``dc_loss_pct`` (PVWatts' system losses, docs/sites.md) scales the current at the
    maximum power point, so the power by the same share; the voltage is the model's."""
    import dataclasses

    e, t = np.array([150.0, 600.0, 1000.0]), np.array([5.0, 30.0, 55.0])
    ideal = ArrayConfig("a", modules_in_series=3, strings_in_parallel=2)
    lossy = dataclasses.replace(ideal, dc_loss_pct=14.0)
    a, b = array_mpp(e, t, ideal), array_mpp(e, t, lossy)
    np.testing.assert_array_equal(b["voltage_v"], a["voltage_v"])
    np.testing.assert_allclose(b["current_a"], 0.86 * a["current_a"], rtol=1e-12)
    np.testing.assert_allclose(b["power_w"], 0.86 * a["power_w"], rtol=1e-12)
    assert lossy.stc_power_w == ideal.stc_power_w  # the rating is the nameplate's
    assert array_config_from_dict("f", {"dc_loss_pct": 14}).to_dict()["dc_loss_pct"] == 14.0
    assert "dc_loss_pct" not in ideal.to_dict()  # a stored config without it is unchanged
    with pytest.raises(ValueError, match="dc_loss_pct"):
        ArrayConfig("x", dc_loss_pct=100.0)
