"""What a stored reading holds besides its time and array.

- The electrical quantities ``voltage_v``, ``current_a`` and ``power_w``. ``power_w``
  is always there (sent, or ``voltage_v·current_a``); voltage and current come
  together or not at all: a *power-only* logger (most inverter and meter
  loggers) sends ``power_w`` alone, and its energy then rests on that reported
  power, unchecked against V·I.
- Optional sensor fields (issue 13): what many loggers carry beside the arrays'
  output — a pyranometer or reference cell in the array's plane, a horizontal
  pyranometer, a module-temperature probe, an air-temperature probe, an anemometer
  (issue 27: the wind cools the cells), the tracker's encoder angles, and the sun's
  offset in the tracker's camera (issue 25, the pointing model's observations). Each
  is stored as sent (NULL when absent); the hourly rollups keep their sum and count,
  so bucket means are means of the readings that carried the field.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ELECTRICAL = ("voltage_v", "current_a", "power_w")


@dataclass(frozen=True)
class SensorField:
    """An optional per-reading sensor value: its name (with unit), plausible range, meaning."""

    name: str
    low: float
    high: float
    meaning: str


#: The optional sensor fields, in storage order. Ranges refuse only the impossible:
#: a pyranometer reads a little below zero at night (thermal offset), encoder
#: azimuths may come as −180…180 or past 360 on a cable wrap (stored in [0, 360),
#: clockwise from north).
SENSOR_FIELDS = (
    SensorField("poa_irradiance_w_m2", -50.0, 2000.0,
                "irradiance in this array's plane, from a pyranometer or reference cell on it "
                "[W/m²]"),
    SensorField("ghi_w_m2", -50.0, 1600.0, "global horizontal irradiance at the site [W/m²]"),
    SensorField("temp_module_c", -50.0, 120.0, "back-of-module temperature of this array [°C]"),
    SensorField("temp_air_c", -60.0, 70.0, "ambient air temperature at the site [°C]"),
    SensorField("azimuth_deg", -360.0, 720.0,
                "the tracker's measured azimuth joint angle (encoder), degrees clockwise from "
                "north; stored modulo 360 (a cable wrap's −90…450 as well as −180…180)"),
    SensorField("elevation_deg", -90.0, 90.0,
                "the tracker's measured elevation joint angle (encoder): elevation of the "
                "collector's normal above the horizon [°]"),
    # issue 25: the sun's offset in the tracker camera (docs/pointing-model.md). The limit is
    # the angle itself: 1000·atan2(·, s·n) of a sun in front of the camera (s·n > 0) is under
    # 90° = 1,570.8 mrad. Seed 000's camera's half fields (585 / 461 mrad at 67°) refused a
    # wider camera's sun at 600 mrad, found at confidence 1.0 (a tester's finding).
    SensorField("sun_offset_x_mrad", -1570.8, 1570.8,
                "the sun's offset in the tracker camera toward increasing azimuth, "
                "1000·atan2(s·h, s·n) [mrad]"),
    SensorField("sun_offset_y_mrad", -1570.8, 1570.8,
                "the sun's offset in the tracker camera toward increasing elevation, "
                "1000·atan2(s·u, s·n) [mrad]"),
    # issue 27: the wind speed cools the cells (SAPM cell temperature, King et al. 2004
    # eqs. 11–12). The upper bound is the highest surface wind ever measured, a 113.3 m/s
    # 3-second gust (Barrow Island, 10 Apr 1996; WMO's verified record, Courtney et al.
    # 2012, Aust. Met. Oceanogr. J. 62, 1–9): a mean above it is a faulty instrument. An
    # anemometer's zero offset reads a calm a little below 0 (NREL RMIS's, 2022: down to
    # −0.07 m/s), so the lower bound is −1 m/s; the diagnosis takes such a reading as calm.
    SensorField("wind_speed_m_s", -1.0, 113.3,
                "wind speed at the site, the anemometer's mean over the reading's interval "
                "[m/s]"),
)
SENSOR_NAMES = tuple(f.name for f in SENSOR_FIELDS)


def normalise_sensors(values: np.ndarray) -> np.ndarray:
    """Sensor columns ``(n, len(SENSOR_FIELDS))`` as stored: azimuths folded into [0, 360)."""
    out = np.array(values, np.float64, copy=True)
    k = SENSOR_NAMES.index("azimuth_deg")
    out[:, k] = np.mod(out[:, k], 360.0)  # NaN (absent) stays NaN
    return out
