"""Real skies for the diagnosis (issue 27): NREL RMIS, Golden CO, 5-minute GHI/DNI/DHI, the
measured global *normal* irradiance (GNI: what a dual-axis tracker receives) and a fixed
south-facing plane's POA (tests/data/rmis/README.md: source, licence, caveats).

What a healthy tracker and fixed array would log there is made from the *measured*
irradiance with the project's PV model (:mod:`sim.pv`: CEC single-diode KD205GX-LP, SAPM
cell temperature; De Soto IAM on the fixed plane's beam, the measured DNI × cos AOI): the
tracker's plane irradiance is the measured GNI (AOI 0), so the truth is measured, not
modelled. The diagnosis' expectation is then computed from one instrument at a time —
(a) the fixed plane's POA (a reference cell, ``fixed_poa_w_m2``), (a′) the fixed array's
power (inverted), (b) GHI alone (a pyranometer), (c) nothing (the clear sky) — through
:func:`sim.sky_sensor.weather_from_fixed` and :func:`sim.twin.simulate`, the service's path.

Used by ``benchmarks/bench_diagnosis.py`` (the day-by-day table of docs/diagnosis.md) and
``tests/backend/test_diagnosis_real_sky.py`` (the 5-minute files posted to the service).
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from sim import pv, sky, sky_sensor, twin
from sim.energy import energy_wh, interval_middles, on_grid
from sim.sites import Site, site_from_dict

DATA = Path(__file__).resolve().parents[1] / "data" / "rmis"
MST = "Etc/GMT+7"  # the files' clock (UTC−07:00, no daylight saving)
STEP_S = 300
FILES = {
    "irradiance_RMIS_NREL.csv": {"irradiance_ghi__7981": "ghi", "irradiance_dni__7982": "dni",
                                 "irradiance_dhi__7983": "dhi", "irradiance_gni__7994": "gni",
                                 "irradiance_poa__7984": "poa"},
    "rmis_weather_data.csv": {"Global Horizontal": "ghi", "Direct Normal": "dni",
                              "Diffuse Horizontal": "dhi", "Global Normal": "gni",
                              "Plane of array": "poa", "Ambient Temperature": "temp_air",
                              "Wind Speed": "wind_speed"},
}
PATHS = ("poa_sensor", "fixed_array", "ghi_sensor", "clear_sky")


def station_site() -> Site:
    """The site at the station (tests/data/rmis/rmis_golden.json)."""
    return site_from_dict(json.loads((DATA / "rmis_golden.json").read_text()), "rmis_golden")


def load(mid_interval: bool = False) -> pd.DataFrame:
    """Both files, 5-minute, UTC index: ``ghi, dni, dhi, gni, poa`` [W m⁻²] (negative
    night offsets set to 0), ``temp_air`` [°C] and ``wind_speed`` [m s⁻¹] (NaN where the
    file has none); rows without irradiance dropped. The stamps are taken as they are: on
    the clear days the GHI-weighted mean time lies within 3 min of solar noon (12:14 MST in
    early February) after the 2.5 min of a 5-minute mean's end stamp. ``mid_interval``:
    each mean stamped at its middle instead (the end stamp − 2.5 min), so that the sun is
    taken where it was on average over the 5 minutes (a sensitivity check of the bench)."""
    frames = []
    for name, cols in FILES.items():
        df = pd.read_csv(DATA / name, index_col=0)
        df.index = pd.to_datetime(df.index, format="%m/%d/%Y %H:%M").tz_localize(MST)
        df = df[list(cols)].rename(columns=cols)
        df = df[df[["ghi", "dni", "dhi", "gni", "poa"]].notna().all(axis=1)]
        for k in ("ghi", "dni", "dhi", "gni", "poa"):
            df[k] = df[k].clip(lower=0.0)
        frames.append(df)
    out = pd.concat(frames).sort_index().tz_convert("UTC")
    if mid_interval:
        out.index = out.index - pd.Timedelta(seconds=STEP_S / 2)
    return out


def local_days(site: Site, df: pd.DataFrame) -> list[pd.Timestamp]:
    """The local days (site time zone midnights) with readings of at least 60 % of their
    5-minute steps (a day with gaps is compared on the minutes it covers)."""
    local = df.index.tz_convert(site.timezone)
    counts = pd.Series(1, index=local).groupby(local.normalize()).size()
    return [d for d, n in counts.items() if n >= 0.6 * 288]


def fit_fixed_plane(site: Site, df: pd.DataFrame) -> dict[str, float]:
    """Tilt and azimuth [°] of the station's POA sensor: least squares of the measured
    POA against the transposition of the measured GHI/DNI/DHI (pvlib
    ``get_total_irradiance``, Perez 1990 and Hay-Davies 1980, albedo 0.2), on the minutes
    with the beam on the plane (sun above 15°, DNI > 300 W m⁻²) of the days whose three
    components close (:func:`closes`: a fit needs the measured DNI and DHI); tilt 25–55° by 0.5°,
    azimuth 170–200° by 2°. Returns both models' best and the RMS [W m⁻²]."""
    from pvlib import irradiance, solarposition

    sp = solarposition.get_solarposition(df.index, site.latitude, site.longitude,
                                         site.altitude)
    use = (sp["apparent_elevation"] > 15) & (df["dni"] > 300)
    use &= closes(df, sp["apparent_zenith"])
    d, s = df[use], sp[use]
    dni_extra = irradiance.get_extra_radiation(d.index)
    out: dict[str, float] = {"minutes": float(use.sum())}
    for model in ("perez", "haydavies"):
        best = (np.inf, 0.0, 0.0)
        for az in np.arange(170.0, 200.5, 2.0):
            for tilt in np.arange(25.0, 55.5, 0.5):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    p = irradiance.get_total_irradiance(
                        tilt, az, s["apparent_zenith"], s["azimuth"], d["dni"], d["ghi"],
                        d["dhi"], dni_extra=dni_extra, albedo=0.2, model=model,
                        airmass=1.0 / np.cos(np.radians(s["apparent_zenith"])))["poa_global"]
                rms = float(np.sqrt(np.mean((p - d["poa"]) ** 2)))
                if rms < best[0]:
                    best = (rms, float(tilt), float(az))
        out.update({f"{model}_tilt_deg": best[1], f"{model}_azimuth_deg": best[2],
                    f"{model}_rms_w_m2": best[0]})
    return out


def at_plane(site: Site, df: pd.DataFrame, tilt_deg: float, model: str
             ) -> tuple[Site, pd.DataFrame]:
    """The site with its fixed array at ``tilt_deg`` facing south and the rows with that
    plane's ``poa`` made from the *measured* GHI/DNI/DHI by pvlib's transposition ``model``
    (albedo 0.2, 0 with the sun down): what a fixed array of another tilt would have seen
    there, for a checker that builds it so (issue 27: "a 16° fixed array"). Only the days
    whose components close (:func:`closes`) give it as the sky gave it."""
    from pvlib import atmosphere, irradiance, solarposition

    fixed = replace(site.arrays["fixed"], surface_tilt=tilt_deg, surface_azimuth=180.0)
    sp = solarposition.get_solarposition(df.index, site.latitude, site.longitude,
                                         site.altitude)
    zen = sp["apparent_zenith"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        poa = irradiance.get_total_irradiance(
            tilt_deg, 180.0, zen, sp["azimuth"], df["dni"], df["ghi"], df["dhi"],
            dni_extra=irradiance.get_extra_radiation(df.index), albedo=0.2, model=model,
            airmass=atmosphere.get_relative_airmass(zen))["poa_global"]
    out = df.copy()
    # a missing component leaves the plane's reading missing (NaN), never a dark 0
    out["poa"] = np.where(sp["apparent_elevation"] > 0, poa.to_numpy(), 0.0)
    return replace(site, arrays={**site.arrays, "fixed": fixed}), out


@dataclass
class Logged:
    """One local day as loggers would report it, and the truth."""

    date: str
    times: pd.DatetimeIndex  # the stamps (UTC) at the end of each mean
    tracker_power_w: np.ndarray  # a healthy tracker: the PV model at the measured GNI
    fixed_power_w: np.ndarray  # the fixed array: the PV model at the measured POA
    data: pd.DataFrame  # the measured rows (load())
    temp_air: np.ndarray  # [°C] measured where the file has it, else the site's default
    step_s: int = STEP_S  # the readings' cadence


def bridged_gap_s(step_s: int) -> int:
    """The longest gap between readings bridged for a logger of cadence ``step_s``: two
    steps, as far as the service can be set to bridge (``energy_max_gap_s`` ≤ 3600 s,
    backend/settings.py): an hourly logger bridges its own step and no missing hour."""
    from backend.settings import MAX_ENERGY_GAP_S

    return min(2 * step_s, MAX_ENERGY_GAP_S)


def coarser(lg: Logged, step_s: int) -> Logged:
    """The day as a logger of cadence ``step_s`` (a multiple of 5 minutes) would send it:
    the means of the 5-minute means (power, irradiance, temperature, wind) over each
    ``step_s``, stamped at its end as the files stamp theirs; a mean needs every one of its
    5-minute readings (a gap stays a gap). Energy is kept: the truth of the day is the
    same."""
    k = step_s // STEP_S
    frame = pd.concat([pd.DataFrame({"tracker": lg.tracker_power_w, "fixed": lg.fixed_power_w,
                                     "temp_air_logged": lg.temp_air}, index=lg.times),
                       lg.data], axis=1)
    bins = frame.resample(f"{step_s}s", label="right", closed="right")
    m = bins.mean()[bins["tracker"].count() == k]
    return Logged(lg.date, pd.DatetimeIndex(m.index), m["tracker"].to_numpy(),
                  m["fixed"].to_numpy(), m[list(lg.data.columns)],
                  m["temp_air_logged"].to_numpy(), step_s)


def logged_day(site: Site, df: pd.DataFrame, day: pd.Timestamp) -> Logged:
    """A healthy tracker's and the fixed array's logged power on ``day`` (module docstring).

    The fixed plane's beam: the measured DNI × cos AOI, at most the measured POA; its IAM
    (De Soto 2006, :func:`sim.sky.effective_irradiance`) on that part only."""
    d = df[(df.index >= day.tz_convert("UTC")) & (df.index < (day + pd.Timedelta(days=1))
                                                   .tz_convert("UTC"))]
    t_air = d["temp_air"].fillna(site.temp_air).to_numpy()
    wind = d["wind_speed"].fillna(site.wind_speed).to_numpy()
    clear = sky_sensor.fixed_clear_sky(site, d.index)
    aoi = clear["aoi"].to_numpy()
    up = clear["apparent_elevation"].to_numpy() > 0
    beam = np.where(up, np.minimum(d["dni"].to_numpy() * np.maximum(np.cos(np.radians(aoi)),
                                                                    0.0), d["poa"]), 0.0)
    e_fixed = sky.effective_irradiance(beam, d["poa"].to_numpy() - beam, np.minimum(aoi, 90.0))
    out = {}
    for name, g, e in (("tracker", d["gni"].to_numpy(), d["gni"].to_numpy()),
                       ("fixed", d["poa"].to_numpy(), e_fixed)):
        arr = site.arrays[name]
        t_cell = pv.cell_temperature(g, t_air, wind, arr.temperature_model)
        out[name] = np.where(g > 0, pv.array_mpp(np.asarray(e), t_cell, arr)["power_w"], 0.0)
    return Logged(day.date().isoformat(), d.index, out["tracker"], out["fixed"], d, t_air)


def minutes(day: pd.Timestamp) -> pd.DatetimeIndex:
    return pd.date_range(day.tz_convert("UTC"), (day + pd.Timedelta(days=1)).tz_convert("UTC"),
                         freq="60s", inclusive="left")


def expectation(site: Site, lg: Logged, day: pd.Timestamp, path: str,
                anemometer: bool = True, second_sky: bool = True
                ) -> dict[str, np.ndarray]:
    """The diagnosis' expectation of the day from one instrument (``path`` of :data:`PATHS`),
    on the minute grid: the 5-minute readings onto minutes by the energy rule's line
    (:func:`sim.energy.on_grid`, as the service's ``minute_grid``). Returns
    ``tracker_poa`` [W m⁻²] and ``tracker_power_w``/``tracker_power_alt_w`` [W] of the two
    decompositions, ``times``, and ``sky``: the sky's sensor frame (its ``sky_source`` per
    minute, :func:`sim.sky_sensor.weather_from_fixed`). The air temperature is posted, and
    the station's wind speed where the file has one (``wind_speed_m_s``, as a logger with
    an anemometer sends it); ``anemometer=False``: no wind posted, the expectation takes
    the site's default (a logger without one; the truth's cells keep the measured wind).
    ``second_sky=False``: the main decomposition only (no ``tracker_power_alt_w``)."""
    times = minutes(day)
    # each reading where the site's stamp convention puts it (sim.energy.interval_middles)
    ts = interval_middles(lg.times.as_unit("s").asi8, site.readings_stamped,
                          bridged_gap_s(lg.step_s))
    grid = times.as_unit("s").asi8

    def minute(v: np.ndarray) -> np.ndarray:
        return on_grid(ts, v, grid, bridged_gap_s(lg.step_s))

    n = len(times)
    fixed_w = minute(lg.fixed_power_w) if path == "fixed_array" else np.full(n, np.nan)
    sensors = pd.DataFrame({"temp_air_c": minute(lg.temp_air)}, index=times)
    if anemometer:
        sensors["wind_speed_m_s"] = minute(lg.data["wind_speed"].to_numpy())
    if path == "poa_sensor":
        sensors["fixed_poa_w_m2"] = minute(lg.data["poa"].to_numpy())
    if path == "ghi_sensor":
        sensors["ghi_w_m2"] = minute(lg.data["ghi"].to_numpy())
    models = ("gti_dirint", "clearsky_erbs") if second_sky else ("gti_dirint",)
    # where the readings can show a clear spell, per sky source (the service's sky_fine)
    fine = {key: sky_sensor.readings_fine(ts, lg.data[col].to_numpy(), grid)
            for key, col in (("fixed_poa_w_m2", "poa"), ("ghi_w_m2", "ghi"))}
    fine["fixed_power_w"] = sky_sensor.readings_fine(ts, lg.fixed_power_w, grid)
    weather, sky_frame = sky_sensor.weather_from_fixed(site, times, fixed_w, models=models,
                                                       sensors=sensors, fine=fine)
    end = day + pd.Timedelta(days=1)
    main = twin.simulate(site, day, end, weather=weather["gti_dirint"]).series
    # the sky frame with what the diagnosis's band reads (faults.band_uncertainty): the
    # main sky's expected power and its blind beam's spread (a reviewer's finding: without
    # them the bench's RMIS band left out the widening)
    sky_frame = sky_frame.assign(
        tracker_power_w=main["tracker_power_w"].to_numpy(),
        tracker_blind_sd_w=sky_sensor.tracker_blind_sd_w(main, weather["gti_dirint"]))
    out = {"times": times, "tracker_poa": np.nan_to_num(main["tracker_poa_global"].to_numpy()),
           "tracker_power_w": main["tracker_power_w"].to_numpy(), "sky": sky_frame}
    if second_sky:
        alt = twin.simulate(site, day, end, weather=weather["clearsky_erbs"]).series
        out["tracker_power_alt_w"] = alt["tracker_power_w"].to_numpy()
    return out


def day_energy_wh(times: pd.DatetimeIndex, power_w: np.ndarray, step_s: int) -> float:
    """:func:`sim.energy.energy_wh` of a series over its local day."""
    ts = times.as_unit("s").asi8
    return energy_wh(ts, power_w, 2 * step_s)


def sky_kind(site: Site, lg: Logged) -> tuple[str, float]:
    """``clear``/``partly``/``overcast`` and the day's clearness, the measured GNI over the
    clear-sky (Ineichen) DNI-plus-diffuse on the sun-normal plane, daylight-weighted;
    clear ≥ 0.8, overcast < 0.4 (the labels only sort the table; nothing is tuned on them)."""
    clear = sky_sensor.fixed_clear_sky(site, lg.times)
    normal = (clear["dni_clear"] + clear["dhi_clear"]).to_numpy()
    k = float(lg.data["gni"].sum() / max(normal.sum(), 1.0))
    return ("clear" if k >= 0.8 else "overcast" if k < 0.4 else "partly"), k


def closes(df: pd.DataFrame, zenith: pd.Series) -> pd.Series:
    """Per row: its local day's three horizontal components close — the RMS of
    DNI·cos z + DHI − GHI over the day's steps with GHI > 50 W m⁻² under 5 % of their mean
    GHI. False on every 2019 day (its DNI/DHI close best about 25 min from the GHI stamps,
    whose clear-day mean time sits at solar noon) and on the snow-covered 1 Jan 2022."""
    z = np.radians(zenith.to_numpy())
    r = (df["dni"] * np.maximum(np.cos(z), 0.0) + df["dhi"] - df["ghi"]).to_numpy()
    day = df.index.tz_convert(MST).normalize()
    sunny = (df["ghi"] > 50).to_numpy()
    frame = pd.DataFrame({"r2": np.where(sunny, r ** 2, np.nan),
                          "g": np.where(sunny, df["ghi"].to_numpy(), np.nan)}, index=df.index)
    per_day = frame.groupby(day).mean()
    ok = (np.sqrt(per_day["r2"]) < 0.05 * per_day["g"]).reindex(day).to_numpy()
    return pd.Series(ok, index=df.index)


def horizontal_ok(lg: Logged) -> bool:
    """The day's horizontal instruments close (:func:`closes`)."""
    from pvlib import solarposition

    z = solarposition.get_solarposition(lg.times, 39.742, -105.18, 1828)["apparent_zenith"]
    return bool(closes(lg.data, z).all())


#: pvlib's decompositions compared (issue 27 item 2): GHI → DNI, and GTI-DIRINT on the plane
DECOMPOSITIONS = ("dirint", "dirindex", "erbs", "erbs_driesse", "boland", "louche", "disc",
                  "gti_dirint")


def decomposition_normal_wh_m2(site: Site, lg: Logged) -> dict[str, float]:
    """The day's irradiation on the sun-normal plane [Wh m⁻²] (what the tracker receives)
    from each of pvlib's decompositions (:data:`DECOMPOSITIONS`, each as published, no
    constant refitted) of the measured GHI (GTI-DIRINT: of the fixed plane's POA), DHI =
    GHI − DNI·cos z, transposed by the site's model (Hay-Davies, :func:`sim.sky.poa_irradiance`);
    ``measured_components``: the measured DNI and DHI through the same transposition (the
    floor the transposition itself leaves); ``measured_gni``: the truth. On the 5-minute
    stamps (the sun at each stamp)."""
    out = {"measured_gni": day_energy_wh(lg.times, lg.data["gni"].to_numpy(), STEP_S)}
    out.update(normal_by_decomposition(site, lg.times, lg.data["ghi"].to_numpy(), STEP_S,
                                       lg.data["poa"].to_numpy(), lg.data["dni"].to_numpy()))
    return out


def normal_by_decomposition(site: Site, t: pd.DatetimeIndex, ghi: np.ndarray, step_s: int,
                            poa: np.ndarray | None = None, dni_measured: np.ndarray | None = None,
                            overcast_kc: float | None = None) -> dict[str, float]:
    """The sun-normal plane's irradiation [Wh m⁻²] over ``t`` from each of
    :data:`DECOMPOSITIONS` of ``ghi`` (GTI-DIRINT of the fixed plane's ``poa``, when given),
    and ``measured_components`` from ``dni_measured`` (when given). ``overcast_kc``: the beam
    set to 0 wherever the clear-sky index GHI/GHI_clear (Ineichen) is below it — the
    "beam → 0 when overcast" rule of issue 27 item 2, measured, not adopted."""
    from pvlib import atmosphere, irradiance

    clear = sky_sensor.fixed_clear_sky(site, t)
    zen = clear["apparent_zenith"].to_numpy()
    az = clear["azimuth"].to_numpy()
    up = zen < 90.0
    pressure = float(atmosphere.alt2pres(site.altitude))
    cos_z = np.maximum(np.cos(np.radians(zen)), 0.0)
    am = np.nan_to_num(np.asarray(atmosphere.get_relative_airmass(np.minimum(zen, 90.0)),
                                  dtype=float), nan=40.0)
    fixed = site.arrays["fixed"]
    ghi_clear = clear["ghi_clear"].to_numpy()
    overcast = np.zeros(len(t), dtype=bool) if overcast_kc is None else \
        ghi < overcast_kc * ghi_clear

    def normal(dni: np.ndarray, g: np.ndarray) -> float:
        # a model's undefined points (NaN, ±inf: DIRINDEX where the clear sky is 0) carry no beam
        dni = np.clip(np.nan_to_num(np.asarray(dni, dtype=float), posinf=0.0, neginf=0.0),
                      0.0, None)
        dni = np.where(overcast, 0.0, dni)
        dhi = np.maximum(g - dni * cos_z, 0.0)
        p = sky.poa_irradiance(np.minimum(zen, 90.0), az, zen, az, dni, g, dhi,
                               clear["dni_extra"].to_numpy(), am, albedo=fixed.albedo,
                               model=site.transposition_model)["poa_global"]
        return day_energy_wh(t, np.where(up, np.nan_to_num(p), 0.0), step_s)

    out: dict[str, float] = {}
    if dni_measured is not None:
        out["measured_components"] = normal(dni_measured, ghi)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s_ghi, s_zen = pd.Series(ghi, t), pd.Series(zen, t)
        dni = {
            "dirint": irradiance.dirint(s_ghi, s_zen, t, pressure),
            "dirindex": irradiance.dirindex(s_ghi, clear["ghi_clear"], clear["dni_clear"],
                                            s_zen, t, pressure),
            "erbs": irradiance.erbs(s_ghi, s_zen, t)["dni"],
            "erbs_driesse": irradiance.erbs_driesse(s_ghi, s_zen, t)["dni"],
            "boland": irradiance.boland(s_ghi, s_zen, t)["dni"],
            "louche": irradiance.louche(s_ghi, s_zen, t)["dni"],
            "disc": irradiance.disc(s_ghi, s_zen, t, pressure)["dni"],
        }
        for name, v in dni.items():
            out[name] = normal(np.asarray(v, dtype=float), ghi)
        if poa is not None:
            g = irradiance.gti_dirint(pd.Series(poa, t), pd.Series(clear["aoi"].to_numpy(), t),
                                      s_zen, pd.Series(az, t), t, fixed.surface_tilt,
                                      fixed.surface_azimuth, pressure, albedo=fixed.albedo)
            out["gti_dirint"] = normal(g["dni"].to_numpy(), np.nan_to_num(g["ghi"].to_numpy()))
    return out
