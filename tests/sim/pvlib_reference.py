"""Independent computations of the tehuantepec twin's physics with pvlib alone.

Two baselines, sharing none of sim/'s code, both for the twin's two arrays (a
dual-axis tracker and a fixed 16° south array of 1 × 4 Kyocera KD205GX-LP,
CEC single-diode, physical IAM, SAPM cell temperature, Hay–Davies, albedo 0.2):

- :func:`modelchain_dc_power` — what a pvlib user writes: ``Location``,
  ``PVSystem`` with two ``Array`` s, ``ModelChain`` with the CEC model. The
  reference the twin is checked against in tests/sim/test_twin.py. The clear sky
  is computed from a solar position at the weather's air temperature (the one
  ``ModelChain`` uses), passed to ``get_clearsky``; ``ModelChain.run_model``
  then computes SPA once more, as it has no way to take a precomputed solar
  position. No AC model is run (the twin has none; a no-op ``ac_model``).
- :func:`expert_dc_power` — what an expert writes with pvlib's functions: SPA
  once for both arrays, night steps skipped, ``pvlib.pvsystem.max_power_point``
  (the maximum power point without the rest of the I–V curve).

Run as a script it computes a year at 1-min steps and prints the energies as
JSON (``benchmarks/bench_sim.py`` times it as a whole process)::

    python tests/sim/pvlib_reference.py modelchain|expert [--year 2023]
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass

import numpy as np
import pandas as pd
from pvlib import (
    atmosphere,
    iam,
    irradiance,
    location,
    modelchain,
    pvsystem,
    solarposition,
    temperature,
)

LATITUDE, LONGITUDE, ALTITUDE = 16.28875, -95.240871, 50.0
"""The tehuantepec site (sim/data/sites/tehuantepec.json)."""
MODULE = "Kyocera_Solar_KD205GX_LP"
FIXED_TILT, FIXED_AZIMUTH = 16.0, 180.0
ALBEDO = 0.2


@dataclass
class DualAxisMount(pvsystem.AbstractMount):
    """Ideal two-axis tracking: the panel normal on the apparent sun."""

    def get_orientation(self, solar_zenith, solar_azimuth):  # noqa: ANN001, ANN201
        return {"surface_tilt": np.clip(solar_zenith, 0, 90), "surface_azimuth": solar_azimuth}


def _no_ac_model(mc: modelchain.ModelChain) -> modelchain.ModelChain:
    """ModelChain needs an AC model; the twin runs none, so neither does the baseline."""
    return mc


def _clear_sky_weather(
    loc: location.Location, times: pd.DatetimeIndex, temp_air: float, wind_speed: float
) -> pd.DataFrame:
    solpos = loc.get_solarposition(times, temperature=temp_air)
    weather = loc.get_clearsky(times, model="ineichen", solar_position=solpos)
    weather["temp_air"] = temp_air
    weather["wind_speed"] = wind_speed
    return weather


def modelchain_dc_power(
    times: pd.DatetimeIndex,
    latitude: float = LATITUDE,
    longitude: float = LONGITUDE,
    altitude: float = ALTITUDE,
    temp_air: float = 27.0,
    wind_speed: float = 1.0,
    strings: int = 4,
    modules_per_string: int = 1,
    weather: pd.DataFrame | None = None,
    fixed_tilt: float = FIXED_TILT,
) -> pd.DataFrame:
    """DC power [W] of the tracker and the fixed (16°, south; ``fixed_tilt`` [°]) array by
    ``ModelChain``.

    Clear sky (Ineichen) with ``temp_air`` [°C] and ``wind_speed`` [m s⁻¹] by
    default, else ``weather`` (``ghi``, ``dni``, ``dhi``, ``temp_air``,
    ``wind_speed``) on ``times``. Returns columns ``tracker``, ``fixed``; zero at night.
    """
    module = pvsystem.retrieve_sam("CECMod")[MODULE]
    temp_params = temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"]["open_rack_glass_polymer"]
    arrays = [
        pvsystem.Array(
            mount,
            albedo=ALBEDO,
            module_parameters=module,
            temperature_model_parameters=temp_params,
            modules_per_string=modules_per_string,
            strings=strings,
            name=name,
        )
        for name, mount in (
            ("tracker", DualAxisMount()),
            ("fixed", pvsystem.FixedMount(fixed_tilt, FIXED_AZIMUTH)),
        )
    ]
    system = pvsystem.PVSystem(arrays=arrays)
    loc = location.Location(latitude, longitude, altitude=altitude)
    mc = modelchain.ModelChain(
        system,
        loc,
        aoi_model="physical",
        spectral_model="no_loss",
        temperature_model="sapm",
        dc_model="cec",
        ac_model=_no_ac_model,
        transposition_model="haydavies",
    )
    if weather is None:
        weather = _clear_sky_weather(loc, times, temp_air, wind_speed)
    mc.run_model(weather)
    return pd.DataFrame(
        {
            name: dc["p_mp"].fillna(0.0).clip(lower=0.0)
            for name, dc in zip(("tracker", "fixed"), mc.results.dc, strict=True)
        }
    )


def expert_dc_power(
    times: pd.DatetimeIndex,
    latitude: float = LATITUDE,
    longitude: float = LONGITUDE,
    altitude: float = ALTITUDE,
    temp_air: float = 27.0,
    wind_speed: float = 1.0,
    strings: int = 4,
    modules_per_string: int = 1,
    method: str = "newton",
) -> pd.DataFrame:
    """The same as :func:`modelchain_dc_power` (clear sky), written with pvlib's functions.

    SPA once for both arrays (``pvlib.solarposition.spa_python``), only the
    steps with the sun above the horizon, then per array Hay–Davies
    (``pvlib.irradiance.get_total_irradiance``), physical IAM, SAPM cell
    temperature, ``calcparams_cec`` and ``pvlib.pvsystem.max_power_point``
    (``method``: ``"newton"``, pvlib's fastest; ``"brentq"`` its default).
    """
    module = pvsystem.retrieve_sam("CECMod")[MODULE]
    tp = temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"]["open_rack_glass_polymer"]
    pressure = atmosphere.alt2pres(altitude)
    sp = solarposition.spa_python(times, latitude, longitude, altitude, pressure, temp_air)
    day = (sp["apparent_elevation"] > 0).to_numpy()
    sp = sp[day]
    loc = location.Location(latitude, longitude, altitude=altitude)
    cs = loc.get_clearsky(sp.index, model="ineichen", solar_position=sp)
    dni_extra = irradiance.get_extra_radiation(sp.index)
    zen, azi = sp["apparent_zenith"].to_numpy(), sp["azimuth"].to_numpy()
    out = pd.DataFrame(0.0, index=times, columns=["tracker", "fixed"])
    for name, (tilt, surf_az) in (
        ("tracker", (np.clip(zen, 0, 90), azi)),
        ("fixed", (FIXED_TILT, FIXED_AZIMUTH)),
    ):
        poa = irradiance.get_total_irradiance(
            tilt,
            surf_az,
            zen,
            azi,
            cs["dni"].to_numpy(),
            cs["ghi"].to_numpy(),
            cs["dhi"].to_numpy(),
            dni_extra=dni_extra.to_numpy(),
            albedo=ALBEDO,
            model="haydavies",
        )
        aoi = irradiance.aoi(tilt, surf_az, zen, azi)
        e_eff = poa["poa_direct"] * iam.physical(aoi) + poa["poa_diffuse"]
        t_cell = temperature.sapm_cell(
            poa["poa_global"], temp_air, wind_speed, tp["a"], tp["b"], tp["deltaT"]
        )
        params = pvsystem.calcparams_cec(
            e_eff,
            t_cell,
            module["alpha_sc"],
            module["a_ref"],
            module["I_L_ref"],
            module["I_o_ref"],
            module["R_sh_ref"],
            module["R_s"],
            module["Adjust"],
        )
        mpp = pvsystem.max_power_point(*params, method=method)
        p = np.nan_to_num(np.asarray(mpp["p_mp"], dtype=float)).clip(min=0.0)
        out.loc[out.index[day], name] = p * strings * modules_per_string
    return out


def main(argv: list[str] | None = None) -> int:
    """A clear-sky year at 1 min for both arrays; prints ``{"tracker_energy_wh", …}``."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("baseline", choices=("modelchain", "expert"))
    ap.add_argument("--year", type=int, default=2023)
    ap.add_argument("--temp-air", type=float, default=27.0)
    ap.add_argument("--wind-speed", type=float, default=1.0)
    args = ap.parse_args(argv)
    times = pd.date_range(
        f"{args.year}-01-01",
        f"{args.year + 1}-01-01",
        freq="1min",
        inclusive="left",
        tz="America/Mexico_City",
    )
    run = modelchain_dc_power if args.baseline == "modelchain" else expert_dc_power
    dc = run(times, temp_air=args.temp_air, wind_speed=args.wind_speed)
    print(
        json.dumps(
            {
                "baseline": args.baseline,
                "steps": len(times),
                "tracker_energy_wh": float(dc["tracker"].sum() / 60.0),
                "fixed_energy_wh": float(dc["fixed"].sum() / 60.0),
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
