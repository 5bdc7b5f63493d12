"""Sky: clear-sky irradiance, plane-of-array transposition, AOI, IAM, TMY weather (pvlib).

Every function is a thin, vectorised wrapper over pvlib that fixes the
model choices the twin uses and names units:

- clear sky: Ineichen & Perez (2002, doi:10.1016/S0038-092X(02)00045-2) with
  the Linke turbidity climatology shipped with pvlib (Remund et al. 2003),
  Kasten & Young (1989) relative air mass — as ``pvlib.location.Location.get_clearsky``;
- transposition: Hay & Davies (1980) by default, Perez (1990) on request,
  ``pvlib.irradiance.get_total_irradiance``;
- angle of incidence: ``pvlib.irradiance.aoi``;
- incidence-angle modifier: the physical (Fresnel + Beer) model of De Soto et
  al. (2006, doi:10.1016/j.solener.2005.06.010), the one the CEC model was
  fitted with, ``pvlib.iam.physical``;
- weather: TMY3 files through ``pvlib.iotools.read_tmy3``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

TRANSPOSITION_MODELS = ("haydavies", "perez", "isotropic")


def extra_radiation(times: pd.DatetimeIndex) -> np.ndarray:
    """Extraterrestrial normal irradiance [W m⁻²] (Spencer 1971).

    Via ``pvlib.irradiance.get_extra_radiation``.
    """
    from pvlib import irradiance

    return np.asarray(irradiance.get_extra_radiation(times), dtype=float)


def airmass(apparent_zenith: np.ndarray, altitude: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Relative (Kasten & Young 1989) and absolute air mass [-] via ``pvlib.atmosphere``.

    Parameters
    ----------
    apparent_zenith : array_like
        Refraction-corrected solar zenith [°].
    altitude : float
        Site elevation [m] (pressure from ``pvlib.atmosphere.alt2pres``).
    """
    from pvlib import atmosphere

    am_rel = np.asarray(atmosphere.get_relative_airmass(apparent_zenith, "kastenyoung1989"))
    am_abs = np.asarray(atmosphere.get_absolute_airmass(am_rel, atmosphere.alt2pres(altitude)))
    return am_rel.astype(float), am_abs.astype(float)


def clearsky_ineichen(
    times: pd.DatetimeIndex,
    apparent_zenith: np.ndarray,
    latitude: float,
    longitude: float,
    altitude: float = 0.0,
) -> dict[str, np.ndarray]:
    """Clear-sky GHI, DNI, DHI [W m⁻²] — Ineichen/Perez with pvlib's Linke turbidity table.

    Same recipe as ``pvlib.location.Location(...).get_clearsky(times)``:
    ``lookup_linke_turbidity`` (interpolated by day of year), Kasten–Young air
    mass, ``get_extra_radiation``, ``pvlib.clearsky.ineichen``.

    Parameters
    ----------
    times : pandas.DatetimeIndex
        Timezone-aware times.
    apparent_zenith : array_like
        Refraction-corrected solar zenith at ``times`` [°].
    latitude, longitude : float
        [°].
    altitude : float
        [m].

    Returns
    -------
    dict
        ``ghi``, ``dni``, ``dhi`` [W m⁻²]; also ``dni_extra`` [W m⁻²] and
        ``airmass_relative`` [-] for the transposition.
    """
    from pvlib import clearsky

    linke = np.asarray(clearsky.lookup_linke_turbidity(times, latitude, longitude), dtype=float)
    am_rel, am_abs = airmass(apparent_zenith, altitude)
    dni_extra = extra_radiation(times)
    cs = clearsky.ineichen(
        np.asarray(apparent_zenith, dtype=float),
        am_abs,
        linke,
        altitude=altitude,
        dni_extra=dni_extra,
    )
    out = {k: np.nan_to_num(np.asarray(cs[k], dtype=float)) for k in ("ghi", "dni", "dhi")}
    out["dni_extra"] = dni_extra
    out["airmass_relative"] = am_rel
    return out


def angle_of_incidence(
    surface_tilt: np.ndarray | float,
    surface_azimuth: np.ndarray | float,
    solar_zenith: np.ndarray,
    solar_azimuth: np.ndarray,
) -> np.ndarray:
    """Angle of incidence [°] between sun and surface normal via ``pvlib.irradiance.aoi``."""
    from pvlib import irradiance

    return np.asarray(
        irradiance.aoi(surface_tilt, surface_azimuth, solar_zenith, solar_azimuth), dtype=float
    )


def iam_physical(aoi: np.ndarray) -> np.ndarray:
    """Incidence-angle modifier [-] of De Soto et al. (2006).

    Via ``pvlib.iam.physical`` (glass n = 1.526, K = 4 m⁻¹, L = 2 mm).
    """
    from pvlib import iam

    return np.asarray(iam.physical(np.asarray(aoi, dtype=float)), dtype=float)


def poa_irradiance(
    surface_tilt: np.ndarray | float,
    surface_azimuth: np.ndarray | float,
    solar_zenith: np.ndarray,
    solar_azimuth: np.ndarray,
    dni: np.ndarray,
    ghi: np.ndarray,
    dhi: np.ndarray,
    dni_extra: np.ndarray,
    airmass_relative: np.ndarray | None = None,
    albedo: float = 0.2,
    model: str = "haydavies",
) -> dict[str, np.ndarray]:
    """Plane-of-array irradiance [W m⁻²] via ``pvlib.irradiance.get_total_irradiance``.

    Parameters
    ----------
    surface_tilt, surface_azimuth : array_like
        Surface orientation [°] (pvlib convention).
    solar_zenith, solar_azimuth : array_like
        Sun position [°] (pass the apparent zenith, as pvlib's ModelChain does).
    dni, ghi, dhi, dni_extra : array_like
        [W m⁻²].
    airmass_relative : array_like, optional
        Needed by ``"perez"`` [-].
    albedo : float
        Ground reflectance [-].
    model : {"haydavies", "perez", "isotropic"}

    Returns
    -------
    dict
        ``poa_global``, ``poa_direct``, ``poa_diffuse`` [W m⁻²] (NaN → 0).
    """
    from pvlib import irradiance

    if model not in TRANSPOSITION_MODELS:
        raise ValueError(f"model must be one of {', '.join(TRANSPOSITION_MODELS)}; got {model!r}")
    tot = irradiance.get_total_irradiance(
        surface_tilt,
        surface_azimuth,
        solar_zenith,
        solar_azimuth,
        dni,
        ghi,
        dhi,
        dni_extra=dni_extra,
        airmass=airmass_relative,
        albedo=albedo,
        model=model,
    )
    return {
        k: np.nan_to_num(np.asarray(tot[k], dtype=float))
        for k in ("poa_global", "poa_direct", "poa_diffuse")
    }


def effective_irradiance(
    poa_direct: np.ndarray, poa_diffuse: np.ndarray, aoi: np.ndarray
) -> np.ndarray:
    """Irradiance reaching the cells [W m⁻²]: IAM on the beam, diffuse as is, no spectral loss.

    The same combination as ``pvlib.modelchain.ModelChain`` with
    ``aoi_model="physical"`` and ``spectral_model="no_loss"``.
    """
    return np.asarray(poa_direct) * iam_physical(aoi) + np.asarray(poa_diffuse)


def pvlib_tmy3_path() -> Path:
    """Path of the real TMY3 file that ships with pvlib (723170TYA, Greensboro NC)."""
    import pvlib

    return Path(pvlib.__file__).parent / "data" / "723170TYA.CSV"


def read_tmy3(path: str | Path, coerce_year: int | None = None) -> tuple[pd.DataFrame, dict]:
    """Read a TMY3 file with ``pvlib.iotools.read_tmy3`` for the twin.

    TMY3 values are hour-ending averages; the index is moved back 30 min to the
    middle of each hour so that interpolation onto finer steps is centred.

    Returns
    -------
    weather : pandas.DataFrame
        UTC index; ``ghi``, ``dni``, ``dhi`` [W m⁻²], ``temp_air`` [°C],
        ``wind_speed`` [m s⁻¹].
    metadata : dict
        ``latitude``, ``longitude`` [°], ``altitude`` [m], ``TZ`` [h], ``Name``…
    """
    from pvlib import iotools

    data, meta = iotools.read_tmy3(str(path), coerce_year=coerce_year, map_variables=True)
    weather = data[["ghi", "dni", "dhi", "temp_air", "wind_speed"]].astype(float)
    weather.index = (data.index - pd.Timedelta(minutes=30)).tz_convert("UTC")
    return weather, dict(meta)
