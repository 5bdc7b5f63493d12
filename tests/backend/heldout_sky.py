"""Held-out real skies for the diagnosis (issue 27): measured 1-minute GHI, DNI and DHI at
stations the product was never tuned on — BSRN Payerne, SURFRAD Alamosa, NREL MIDC's UA
OASIS at Tucson (tests/data/heldout-sky/README.md: sources, licences, checks).

Unlike RMIS no tracker-plane irradiance is measured there, so the truth's planes are made
from the *measured* DNI, DHI and GHI by a transposition called in pvlib directly
(:func:`planes`: the sun-normal plane of a healthy dual-axis tracker, and the fixed plane),
with each of :data:`TRUTH_MODELS` — the checker's model is unknown. What the loggers log and
what the diagnosis expects are then made exactly as for RMIS (:mod:`rmis_sky`:
``logged_day``, ``expectation``: the service's sky path and twin). Nothing is tuned here.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd
import rmis_sky

from sim.sites import Site, site_from_dict

DATA = Path(__file__).resolve().parents[1] / "data" / "heldout-sky"
STEP_S = 60
TRUTH_MODELS = ("isotropic", "perez")
#: the issue's "16° fixed array" (tehuantepec's) beside the tilt `site create` gives the place
ISSUE_TILT_DEG = 16.0


@dataclass(frozen=True)
class Station:
    site_id: str
    csv: str
    days: tuple[str, ...]  # local days, chosen by the GHI clear-sky index before any run


STATIONS = (
    Station("heldout_payerne", "bsrn_payerne_2016-06.csv",
            ("2016-06-02", "2016-06-07", "2016-06-13", "2016-06-16", "2016-06-20",
             "2016-06-21", "2016-06-22", "2016-06-23", "2016-06-24", "2016-06-27")),
    Station("heldout_alamosa", "surfrad_alamosa_2016-01-01.csv", ("2016-01-01",)),
    Station("heldout_tucson", "midc_uat_2018-10-18.csv", ("2018-10-18",)),
)


def station_site(st: Station, tilt_deg: float | None = None) -> Site:
    """The site at the station (its JSON beside the data); ``tilt_deg``: the fixed array
    at that tilt instead, still facing the equator."""
    site = site_from_dict(json.loads((DATA / f"{st.site_id}.json").read_text()), st.site_id)
    if tilt_deg is None:
        return site
    return replace(site, arrays={**site.arrays, "fixed": replace(site.arrays["fixed"],
                                                                 surface_tilt=tilt_deg)})


def load(st: Station) -> pd.DataFrame:
    """The station's rows, UTC index: ``ghi, dni, dhi`` [W m⁻²] (negative night offsets
    set to 0), ``temp_air`` [°C], ``wind_speed`` [m s⁻¹] (NaN where the station has none);
    rows missing a component dropped (a gap, as a logger's)."""
    df = pd.read_csv(DATA / st.csv, index_col=0)
    df.index = pd.to_datetime(df.index, utc=True)
    if "wind_speed" not in df:
        df["wind_speed"] = np.nan
    df = df[df[["ghi", "dni", "dhi"]].notna().all(axis=1)].copy()
    for k in ("ghi", "dni", "dhi"):
        df[k] = df[k].clip(lower=0.0)
    return df


def planes(site: Site, df: pd.DataFrame, model: str) -> pd.DataFrame:
    """``df`` with ``gni`` (the sun-normal plane: a healthy dual-axis tracker) and ``poa``
    (the site's fixed plane) [W m⁻²] from the measured DNI, GHI and DHI by pvlib's
    ``get_total_irradiance`` (``model``; albedo the fixed array's; sun from pvlib's SPA)."""
    from pvlib import atmosphere, irradiance, solarposition

    sp = solarposition.get_solarposition(df.index, site.latitude, site.longitude,
                                         site.altitude)
    zen, az = sp["apparent_zenith"], sp["azimuth"]
    up = (sp["apparent_elevation"] > 0).to_numpy()
    fixed = site.arrays["fixed"]
    out = df.copy()
    for col, tilt, azimuth in (("gni", zen.clip(upper=90.0), az),
                               ("poa", fixed.surface_tilt, fixed.surface_azimuth)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            p = irradiance.get_total_irradiance(
                tilt, azimuth, zen, az, df["dni"], df["ghi"], df["dhi"],
                dni_extra=irradiance.get_extra_radiation(df.index), albedo=fixed.albedo,
                model=model, airmass=atmosphere.get_relative_airmass(zen))["poa_global"]
        out[col] = np.where(up, np.nan_to_num(p.to_numpy()), 0.0)
    return out


def logged_day(site: Site, df: pd.DataFrame, day: pd.Timestamp) -> rmis_sky.Logged:
    """What a healthy tracker and the fixed array log on ``day`` (:func:`rmis_sky.logged_day`
    on the planes of :func:`planes`), at the stations' 1-minute cadence."""
    return replace(rmis_sky.logged_day(site, df, day), step_s=STEP_S)


def clear_sky_index(site: Site, lg: rmis_sky.Logged) -> tuple[float, float]:
    """The day's GHI and DNI over pvlib's Ineichen clear sky's (Linke turbidity from pvlib's
    climatology), over the minutes with the sun above 5°: they sort the days, nothing else."""
    from pvlib.location import Location

    loc = Location(site.latitude, site.longitude, altitude=site.altitude)
    sp = loc.get_solarposition(lg.times)
    cs = loc.get_clearsky(lg.times, solar_position=sp)
    up = (sp["apparent_elevation"] > 5).to_numpy()
    return tuple(float(lg.data[k].to_numpy()[up].sum() / cs[k].to_numpy()[up].sum())
                 for k in ("ghi", "dni"))  # type: ignore[return-value]


def kind(kc: float, kb: float) -> str:
    """``clear`` (the GHI's and the DNI's clear-sky index both ≥ 0.9), ``overcast`` (GHI's
    < 0.5) or ``partly``; the targets: 3 % on clear days, 8 % on the others."""
    return "clear" if min(kc, kb) >= 0.9 else "overcast" if kc < 0.5 else "partly"


def closure_pct(site: Site, df: pd.DataFrame) -> float:
    """RMS of DNI·cos z + DHI − GHI over the steps with GHI > 50 W m⁻², in % of their mean GHI."""
    from pvlib import solarposition

    z = solarposition.get_solarposition(df.index, site.latitude, site.longitude,
                                        site.altitude)["apparent_zenith"].to_numpy()
    r = df["dni"] * np.maximum(np.cos(np.radians(z)), 0.0) + df["dhi"] - df["ghi"]
    sunny = (df["ghi"] > 50).to_numpy()
    return float(100 * np.sqrt(np.mean(r.to_numpy()[sunny] ** 2)) / df["ghi"][sunny].mean())


def noon_offset_min(site: Site, df: pd.DataFrame) -> float:
    """The GHI-weighted mean time of the day's stamps less solar noon (SPA transit) [min]:
    near 0 on a clear day whose stamps are right (a symmetric day)."""
    from pvlib import solarposition

    local = df.index.tz_convert(site.timezone)
    midnight = local[0].normalize()
    t = (local - midnight).total_seconds().to_numpy() / 60.0
    w = df["ghi"].to_numpy()
    transit = solarposition.sun_rise_set_transit_spa(
        pd.DatetimeIndex([midnight]), site.latitude, site.longitude)["transit"].iloc[0]
    return float((t * w).sum() / w.sum() - (transit - midnight).total_seconds() / 60.0)


def judged(site: Site, lg: rmis_sky.Logged, day: pd.Timestamp, path: str) -> dict[str, float]:
    """The diagnosis's expected tracker energy of ``day`` from one instrument (``path`` of
    :data:`rmis_sky.PATHS`) against the truth (the healthy tracker's logged energy), both by
    :mod:`sim.energy`'s rule over the minutes the readings cover, and its band
    (:func:`backend.diagnosis.faults.band_wh`): ``expected_wh``, ``truth_wh``, ``error_pct``,
    ``low_wh``, ``high_wh``, ``inside`` (1.0 or 0.0); ``blind_pct`` and ``seen_pct``: the
    error's parts [% of the truth] from the minutes the instrument's plane (the fixed plane;
    the horizontal for the GHI pyranometer) sees the sun behind or grazing it (cos AOI under
    :data:`sim.sky_sensor.BEAM_SEEN_COS`, where its beam can only be guessed) and from the
    rest."""
    from backend.diagnosis.faults import band_uncertainty, band_wh
    from sim.energy import energy_wh, on_grid

    e = rmis_sky.expectation(site, lg, day, path)
    grid = e["times"].as_unit("s").asi8
    ts = lg.times.as_unit("s").asi8
    gap = rmis_sky.bridged_gap_s(STEP_S)
    covered = np.isfinite(on_grid(ts, lg.tracker_power_w, grid, gap))

    def wh(p: np.ndarray) -> float:
        return energy_wh(grid, np.where(covered, p, np.nan), 60)

    truth_w = on_grid(ts, lg.tracker_power_w, grid, gap)
    truth = wh(truth_w)
    blind = behind_plane(site, e["times"], horizontal=path == "ghi_sensor")
    parts = {k: 100 * (wh(np.where(m, e["tracker_power_w"], 0.0))
                       - wh(np.where(m, truth_w, 0.0))) / truth
             for k, m in (("blind_pct", blind), ("seen_pct", ~blind))}
    a, b = wh(e["tracker_power_w"]), wh(e["tracker_power_alt_w"])
    low, high = band_wh(a, b, band_uncertainty(e["sky"]))
    return {"expected_wh": a, "truth_wh": truth, "error_pct": 100 * (a / truth - 1),
            "low_wh": low, "high_wh": high, "inside": float(low <= truth <= high), **parts}


def behind_plane(site: Site, times: pd.DatetimeIndex, horizontal: bool = False) -> np.ndarray:
    """Per minute: the sun is up but behind or grazing the fixed plane (the horizontal one:
    ``horizontal``), cos AOI < :data:`sim.sky_sensor.BEAM_SEEN_COS` (pvlib's geometry)."""
    from pvlib import irradiance, solarposition

    from sim.sky_sensor import BEAM_SEEN_COS

    sp = solarposition.get_solarposition(times, site.latitude, site.longitude, site.altitude)
    fixed = site.arrays["fixed"]
    tilt, az = (0.0, 180.0) if horizontal else (fixed.surface_tilt, fixed.surface_azimuth)
    cos_aoi = np.cos(np.radians(irradiance.aoi(tilt, az, sp["apparent_zenith"], sp["azimuth"])))
    return ((sp["apparent_elevation"] > 0) & (cos_aoi < BEAM_SEEN_COS)).to_numpy()
