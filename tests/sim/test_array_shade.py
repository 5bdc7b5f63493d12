"""The tracker's shade on the fixed array (sim/array_shade.py) and what the twin does with it.

The fraction is checked against a second method written here from scratch: rays from a
grid of points on the fixed array towards the sun, each tested against the tracker's
collector rectangle (built from the normal's azimuth/elevation, seed 002's d1 and a2,
not from sim.kinematics), and against a hand-computed case. The fixed array's shaded
power is checked against pvlib's functions with the beam cut by the shaded fraction.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pvlib
import pytest

from sim.array_shade import Placement, fixed_shade, layout_of, tracker_panel_frames
from sim.pv import ArrayConfig
from sim.sites import Site, load_site
from sim.twin import simulate

SITE = load_site("tehuantepec")
TZ = "America/Mexico_City"
W, H = 3.02, 2.00  # 2 x 2 landscape KD205GX-LP (1.50 m x 0.99 m, pvlib's CEC table), 0.02 m gaps


def _unit(az_deg: float | np.ndarray, el_deg: float | np.ndarray) -> np.ndarray:
    a, e = np.radians(az_deg), np.radians(el_deg)
    return np.stack([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), np.sin(e)], axis=-1)


def _site(tilt: float, azimuth: float, fixed_en: tuple[float, float], tracker_h: float = 1.3,
          fixed_h: float = 0.5) -> Site:
    return dataclasses.replace(
        SITE, arrays={**SITE.arrays, "fixed": ArrayConfig("fixed", surface_tilt=tilt,
                                                          surface_azimuth=azimuth)},
        placements={"tracker": Placement(2.0, -1.0, mount_height_m=tracker_h),
                    "fixed": Placement(2.0 + fixed_en[0], -1.0 + fixed_en[1],
                                       mount_height_m=fixed_h)})


def _rectangle(centre: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """In-plane axes of a rectangle with a horizontal width edge: u horizontal, v = n × u."""
    u = np.cross([0.0, 0.0, 1.0], normal)
    u = u / np.linalg.norm(u) if np.linalg.norm(u) > 1e-12 else np.array([1.0, 0.0, 0.0])
    return u, np.cross(normal, u)


def _ray_cast(site: Site, normal_az: float, normal_el: float, sun: np.ndarray,
              n: int = 300) -> float:
    """Share of an n x n grid of the fixed array's points whose ray towards the sun hits the
    tracker's collector."""
    fx, tr = site.arrays["fixed"], site.placements["tracker"]
    pf = site.placements["fixed"]
    t = np.radians(fx.surface_tilt)
    nf = _unit(fx.surface_azimuth, 90.0 - fx.surface_tilt)
    if sun[2] <= 0 or sun @ nf <= 0:
        return 0.0
    cf = np.array([pf.position_east_m - tr.position_east_m,
                   pf.position_north_m - tr.position_north_m,
                   pf.mount_height_m + H / 2 * np.sin(t)])
    uf, vf = _rectangle(cf, nf)
    g = (np.arange(n) + 0.5) / n - 0.5
    a, b = np.meshgrid(g * W, g * H)
    pts = cf + a.reshape(-1, 1) * uf + b.reshape(-1, 1) * vf
    nt = _unit(normal_az, normal_el)
    # seed 002: the panel centre is d1 above the base frame, a2 along the normal
    ct = np.array([0.0, 0.0, tr.mount_height_m + site.tracker.d1_m]) + site.tracker.a2_m * nt
    ut, vt = _rectangle(ct, nt)
    lam = ((ct - pts) @ nt) / (sun @ nt)
    hit = pts + lam[:, None] * sun - ct
    inside = (lam > 0) & (np.abs(hit @ ut) <= W / 2) & (np.abs(hit @ vt) <= H / 2)
    return float(inside.mean())


def _shade(site: Site, normal_az: float, normal_el: float, sun: np.ndarray):  # noqa: ANN202
    layout = layout_of(site)
    assert layout is not None
    frames = tracker_panel_frames(layout, site.tracker, [normal_az], [normal_el])
    return fixed_shade(layout, frames, sun[None])


def _cases() -> list[tuple]:
    """Layouts and sun positions: half aimed (the fixed array facing roughly towards the
    tracker, the ray from it towards the sun passing near the tracker: shade likely), half
    anywhere; tracker normals on the sun or anywhere."""
    rng = np.random.default_rng(14)
    out = []
    for k in range(60):
        tilt, azimuth = rng.uniform(0, 90), rng.uniform(90, 270)
        east, north = rng.uniform(-7, 7, size=2)
        if np.hypot(east, north) < 3.0:
            east += 3.0 * np.sign(east or 1.0)
        th, fh = rng.uniform(1.0, 2.5), rng.uniform(0.2, 2.2)
        if k % 2 == 0:  # aim: the sun seen from the fixed array behind the tracker
            azimuth = (np.degrees(np.arctan2(-east, -north)) + rng.uniform(-60, 60)) % 360
            d = np.array([-east, -north, th + 0.4 - fh - 0.5]) + rng.normal(0, 0.8, 3)
            d[2] = max(d[2], 0.05 * np.hypot(d[0], d[1]))
            sun = d / np.linalg.norm(d)
        else:
            sun = _unit(rng.uniform(0, 360), rng.uniform(1, 70))
        if k % 3 == 0:
            n_az, n_el = rng.uniform(0, 360), rng.uniform(0, 90)
        else:
            n_az, n_el = np.degrees(np.arctan2(sun[0], sun[1])), np.degrees(np.arcsin(sun[2]))
        out.append((tilt, azimuth, (east, north), th, fh, n_az, n_el, sun))
    return out


def test_fraction_agrees_with_ray_casting_over_layouts_and_suns() -> None:
    errors, shaded = [], 0
    for tilt, azimuth, en, th, fh, n_az, n_el, sun in _cases():
        site = _site(tilt, azimuth, en, th, fh)
        got = float(_shade(site, n_az, n_el, sun).fraction[0])
        want = _ray_cast(site, n_az, n_el, sun)
        errors.append(abs(got - want))
        shaded += want > 0.02
    # measured: max 0.00015 on a 300 x 300 grid (its cells are 1/300 of each side); 29 of
    # the 60 cases shaded (over 2 %)
    assert max(errors) < 5e-4
    assert shaded >= 25


def test_only_the_part_of_the_collector_in_front_of_the_array_shades_it() -> None:
    # a flat fixed array 1.95 m up, beside the tracker: its plane cuts the tracker's
    # near-vertical collector (centre ~1.67 m up), whose lower part cannot shade it
    site = _site(0.0, 180.0, (-3.0, 0.0), tracker_h=1.3, fixed_h=1.95)
    sun = _unit(90.0, 12.0)  # east, low: the collector's shadow falls west
    got = float(_shade(site, 90.0, 12.0, sun).fraction[0])
    want = _ray_cast(site, 90.0, 12.0, sun)
    assert want > 0.1 and got == pytest.approx(want, abs=1e-3)  # measured 3e-4


@pytest.mark.parametrize(("elevation", "north"), [(10.0, 0.0), (10.0, 1.0), (25.0, -0.5)])
def test_hand_case_low_sun_due_west_on_a_vertical_array_east_of_the_tracker(
        elevation: float, north: float) -> None:
    """The fixed array stands vertical facing west, 4.5 m east; the sun due west at elevation
    e and the collector facing it. Cast along s onto the plane x = 4.5 the collector stays
    W wide and becomes H / cos e tall, centred at z_c − (4.5 − x_c) tan e."""
    site = _site(90.0, 270.0, (4.5, north), tracker_h=1.3, fixed_h=0.5)
    e = np.radians(elevation)
    sun = _unit(270.0, elevation)
    shade = _shade(site, 270.0, elevation, sun)
    x_c = -0.091 * np.cos(e)                   # the collector's centre: a2 along the normal
    z_c = 1.3 + 0.355 + 0.091 * np.sin(e)
    z_mid, z_half = z_c - (4.5 - x_c) * np.tan(e), H / 2 / np.cos(e)
    dz = max(0.0, min(z_mid + z_half, 0.5 + H) - max(z_mid - z_half, 0.5))
    dy = max(0.0, W - abs(north))
    assert shade.fraction[0] == pytest.approx(dz * dy / (W * H), abs=1e-9)
    poly = shade.polygon_enu[0, :shade.vertices[0]]
    np.testing.assert_allclose(poly[:, 0], 4.5, atol=1e-9)           # on the array's plane
    assert poly[:, 2].min() == pytest.approx(max(z_mid - z_half, 0.5), abs=1e-9)
    assert poly[:, 2].max() == pytest.approx(min(z_mid + z_half, 0.5 + H), abs=1e-9)


def test_no_shade_with_the_sun_down_or_behind_the_array() -> None:
    site = _site(16.0, 180.0, (4.5, 0.0))
    for sun in (_unit(270.0, -2.0), _unit(0.0, 10.0)):  # below the horizon; north, behind
        assert _shade(site, 270.0, 10.0, sun).fraction[0] == 0.0


def test_without_positions_the_twin_is_unchanged_and_reports_no_shade() -> None:
    start = pd.Timestamp("2024-03-15", tz=TZ)
    r = simulate(SITE, start, start + pd.Timedelta(days=1), step_s=300)
    assert "fixed_shaded_fraction" not in r.series and "fixed_shade_loss_wh" not in r.summary()
    assert layout_of(SITE) is None


def _pvlib_fixed_power_w(times: pd.DatetimeIndex, shaded: np.ndarray) -> np.ndarray:
    """The fixed array (16° south, 4 KD205GX-LP in parallel) with pvlib's functions, its
    plane-of-array beam cut by the shaded fraction."""
    module = pvlib.pvsystem.retrieve_sam("CECMod")["Kyocera_Solar_KD205GX_LP"]
    tp = pvlib.temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"]["open_rack_glass_polymer"]
    sp = pvlib.solarposition.spa_python(times, SITE.latitude, SITE.longitude, SITE.altitude,
                                        pvlib.atmosphere.alt2pres(SITE.altitude), SITE.temp_air)
    loc = pvlib.location.Location(SITE.latitude, SITE.longitude, altitude=SITE.altitude)
    cs = loc.get_clearsky(times, model="ineichen", solar_position=sp)
    zen, azi = sp["apparent_zenith"], sp["azimuth"]
    poa = pvlib.irradiance.get_total_irradiance(
        16.0, 180.0, zen, azi, cs["dni"], cs["ghi"], cs["dhi"],
        dni_extra=pvlib.irradiance.get_extra_radiation(times), albedo=0.2, model="haydavies")
    beam = poa["poa_direct"].to_numpy() * (1.0 - shaded)
    aoi = pvlib.irradiance.aoi(16.0, 180.0, zen, azi).to_numpy()
    e_eff = beam * pvlib.iam.physical(aoi) + poa["poa_diffuse"].to_numpy()
    t_cell = pvlib.temperature.sapm_cell(beam + poa["poa_diffuse"].to_numpy(), SITE.temp_air,
                                         SITE.wind_speed, tp["a"], tp["b"], tp["deltaT"])
    params = pvlib.pvsystem.calcparams_cec(
        e_eff, t_cell, module["alpha_sc"], module["a_ref"], module["I_L_ref"],
        module["I_o_ref"], module["R_sh_ref"], module["R_s"], module["Adjust"])
    return 4.0 * np.asarray(pvlib.pvsystem.max_power_point(*params, method="newton")["p_mp"])


def test_the_twin_loses_the_shaded_share_of_the_fixed_array_s_beam() -> None:
    site = _site(16.0, 180.0, (4.5, 0.0))
    start = pd.Timestamp("2024-03-15 15:00", tz=TZ)
    r = simulate(site, start, start + pd.Timedelta(hours=3), step_s=300)
    unplaced = simulate(SITE, start, start + pd.Timedelta(hours=3), step_s=300)
    s, f = r.series, r.series["fixed_shaded_fraction"].to_numpy()
    shaded = (f > 0) & (s["apparent_elevation"].to_numpy() > 0)
    assert shaded.sum() >= 10 and f.max() > 0.9
    # the fraction: the twin's sun and ideal pose, ray-cast
    sp = pvlib.solarposition.spa_python(s.index, SITE.latitude, SITE.longitude, SITE.altitude,
                                        pvlib.atmosphere.alt2pres(SITE.altitude), SITE.temp_air)
    for k in np.nonzero(shaded)[0]:
        az, el = float(sp["azimuth"].iloc[k]), float(sp["apparent_elevation"].iloc[k])
        # measured: within 1e-4 of the 200 x 200 grid
        assert f[k] == pytest.approx(_ray_cast(site, az, el, _unit(az, el), n=200), abs=1e-3)
    # the power: pvlib with the beam cut by that fraction (measured within 0.0032 W)
    ref = _pvlib_fixed_power_w(s.index[shaded], f[shaded])
    np.testing.assert_allclose(s["fixed_power_w"].to_numpy()[shaded], ref, rtol=0, atol=0.02)
    # the loss is what the unshaded twin makes more; the tracker is untouched
    loss = unplaced.energy_wh("fixed") - r.energy_wh("fixed")
    assert r.summary()["fixed_shade_loss_wh"] == pytest.approx(loss, rel=1e-9)
    assert loss > 0 and r.energy_wh("tracker") == unplaced.energy_wh("tracker")


# ------------------------------------------------------------ the site config's fields

_GOOD = {"site_id": "ok", "latitude_deg": 10, "longitude_deg": 0, "timezone": "UTC",
         "arrays": {"tracker": {"mount": "tracker", "position_east_m": 0,
                                "position_north_m": 0},
                    "fixed": {"surface_tilt_deg": 16, "position_east_m": 4.5,
                              "position_north_m": 0}}}


@pytest.mark.parametrize(("fixed", "words"), [
    ({"position_east_m": 4.5},
     "arrays.fixed.position_north_m: give position_east_m and position_north_m together"),
    ({"position_north_m": 0.0},
     "arrays.fixed.position_north_m: give position_east_m and position_north_m together"),
    ({"width_m": 3.0}, "arrays.fixed.width_m: only used with position_east_m and"),
    ({"position_east_m": 4.5, "position_north_m": 0, "width_m": 3.0},
     "arrays.fixed.height_m: give width_m and height_m together"),
    ({"position_east_m": 4.5, "position_north_m": 0, "module": "Advance_Power_API_P320"},
     "arrays.fixed.width_m: module 'Advance_Power_API_P320' has no size in pvlib's CEC"),
    ({"position_east_m": 4.5, "position_north_m": 0, "mount_height_m": -1},
     "arrays.fixed.mount_height_m: Input should be greater than or equal to 0"),
    ({}, "arrays: arrays.fixed.position_east_m/position_north_m: needed as arrays.tracker"),
])
def test_a_bad_placement_names_the_field(fixed: dict, words: str) -> None:
    import re

    from sim.site_config import validate_site_config

    validate_site_config(_GOOD)
    bad = {**_GOOD, "arrays": {**_GOOD["arrays"], "fixed": {"surface_tilt_deg": 16, **fixed}}}
    with pytest.raises(ValueError, match=re.escape(words)):
        validate_site_config(bad, where="ok.json")


def test_placements_load_round_trip_and_size_from_the_modules() -> None:
    import json

    from sim.sites import site_from_dict

    cfg = json.loads(json.dumps(_GOOD))
    cfg["arrays"]["tracker"]["mount_height_m"] = 1.8
    cfg["arrays"]["fixed"].update(width_m=6.0, height_m=1.0)
    site = site_from_dict(cfg)
    assert site.placements["fixed"] == Placement(4.5, 0.0, None, 6.0, 1.0)
    assert site_from_dict(json.loads(json.dumps(site.to_config()))) == site
    assert site.to_dict()["arrays"]["tracker"]["mount_height_m"] == 1.8
    layout = layout_of(site)
    assert layout is not None and not layout.assumed
    assert layout.fixed_size_m == (6.0, 1.0) and layout.tracker_mount_height_m == 1.8
    assert layout.tracker_size_m == pytest.approx((W, H))  # 4 modules: 2 x 2 landscape
    # 6 modules: 3 across, 2 rows; 1 module: itself
    six = dataclasses.replace(site, arrays={**site.arrays, "tracker": ArrayConfig(
        "tracker", mount="tracker", strings_in_parallel=6)})
    assert layout_of(six).tracker_size_m == pytest.approx((3 * 1.5 + 0.04, 2 * 0.99 + 0.02))
