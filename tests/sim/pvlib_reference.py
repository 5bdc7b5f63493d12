"""An independent computation of the tehuantepec twin's physics with pvlib's ModelChain.

Written the way a pvlib user would (Location, PVSystem with two Arrays, ModelChain
with the CEC model), sharing none of sim/'s code: the reference the twin is
checked against in tests/sim/test_twin.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from pvlib import location, modelchain, pvsystem, temperature


@dataclass
class DualAxisMount(pvsystem.AbstractMount):
    """Ideal two-axis tracking: the panel normal on the apparent sun."""

    def get_orientation(self, solar_zenith, solar_azimuth):  # noqa: ANN001, ANN201
        return {"surface_tilt": np.clip(solar_zenith, 0, 90), "surface_azimuth": solar_azimuth}


def modelchain_dc_power(
    times: pd.DatetimeIndex,
    latitude: float = 16.28875,
    longitude: float = -95.240871,
    altitude: float = 50.0,
    temp_air: float = 27.0,
    wind_speed: float = 1.0,
    strings: int = 4,
    modules_per_string: int = 1,
    weather: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """DC power [W] of the tracker and the fixed (16°, south) array; clear sky by default."""
    module = pvsystem.retrieve_sam("CECMod")["Kyocera_Solar_KD205GX_LP"]
    temp_params = temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"]["open_rack_glass_polymer"]
    arrays = [
        pvsystem.Array(
            mount,
            albedo=0.2,
            module_parameters=module,
            temperature_model_parameters=temp_params,
            modules_per_string=modules_per_string,
            strings=strings,
            name=name,
        )
        for name, mount in (("tracker", DualAxisMount()), ("fixed", pvsystem.FixedMount(16, 180)))
    ]
    system = pvsystem.PVSystem(arrays=arrays, inverter_parameters={"pdc0": 2000.0})
    loc = location.Location(latitude, longitude, altitude=altitude)
    mc = modelchain.ModelChain(
        system,
        loc,
        aoi_model="physical",
        spectral_model="no_loss",
        temperature_model="sapm",
        dc_model="cec",
        ac_model="pvwatts",
        transposition_model="haydavies",
    )
    if weather is None:
        weather = loc.get_clearsky(times, model="ineichen")
        weather["temp_air"] = temp_air
        weather["wind_speed"] = wind_speed
    mc.run_model(weather)
    return pd.DataFrame(
        {
            name: dc["p_mp"].fillna(0.0).clip(lower=0.0)
            for name, dc in zip(("tracker", "fixed"), mc.results.dc, strict=True)
        }
    )
