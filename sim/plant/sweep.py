"""One case of a plant-design sweep: a layout at a GCR under a strategy, over a time range.

A sweep asks which layout and which spacing (Cumpston & Pye 2014,
doi:10.1016/j.solener.2014.06.012): how much beam each collector loses to its
neighbours against how much land it needs. A case builds the field
(:mod:`sim.plant.fields`: a regular field of ``rows × columns`` collectors around the
interior one, or an existing plant scaled to the GCR) and runs
:func:`sim.plant.simulate.simulate_plant` on a sky computed once for the whole range
(:func:`case_sky`, shared by every case at the same place and range). The row:

- ``interior_beam_shaded_pct``: the interior collector's Σ F · DNI / Σ DNI over daylight
  steps [%] (twoaxistracking's interior collector when every collector faces the sun);
- ``field_beam_shaded_pct``: the same averaged over the finite field's collectors;
- ``energy_kwh_per_collector``: the finite field's DC energy per collector, bypass-diode
  model (Martinez-Moreno 2010 via :mod:`sim.plant.electrical`) — the field's average, 16 of
  whose 25 collectors in 5 × 5 stand on its edge with fewer shading neighbours;
  ``interior_energy_kwh`` the interior collector's own: what a large plant's collectors get
  (the dashboard's figure; the two can rank strategies differently);
- ``land_m2_per_collector``: A / GCR; ``energy_mwh_per_ha``: the field average's energy per
  collector over that land, ``interior_energy_mwh_per_ha`` the interior collector's.

No scheduling here: the backend runs cases as Dask tasks (``backend.plants.sweep``).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from sim.energy import simulation_times
from sim.plant.fields import (
    FieldLayout,
    interior_tracker,
    lattice_positions,
    plant_land_m2,
    regular_field,
    scaled_plant,
)
from sim.plant.layout import Collector, Plant
from sim.plant.simulate import local_day, simulate_plant, sky_conditions
from sim.plant.strategies import STRATEGIES

FloatArray = NDArray[np.float64]

#: Layout name of the cases of an existing plant scaled in spacing.
PLANT_LAYOUT = "plant"


@dataclass(frozen=True)
class SweepCase:
    """One task of a sweep: a layout name (or :data:`PLANT_LAYOUT`), a GCR, a strategy."""

    layout: str
    gcr: float
    strategy: str


@dataclass(frozen=True)
class SweepSpec:
    """What every case of a sweep shares: place, range, collector and field.

    Parameters
    ----------
    latitude, longitude, altitude : float
        [°], [°], [m].
    start, end : pandas.Timestamp
        Tz-aware; end exclusive.
    step_s : float
        [s].
    collector : Collector
    rows, columns : int
        Size of a regular field (5 × 5 holds twoaxistracking's ``neighbor_order=2``).
    slope_azimuth_deg, slope_tilt_deg : float
        Ground plane of the regular fields [°].
    custom : tuple of float, optional
        (aspect ratio, offset, rotation [°]) of the layout named ``custom``.
    plant : Plant, optional
        An existing plant: its cases (layout :data:`PLANT_LAYOUT`) scale its spacing.
    timezone : str
        Zone of the local days (the plant's, or UTC for a place given by coordinates).
    albedo, temp_air, wind_speed : float
        Ground reflectance [-], clear-sky air temperature [°C] and wind [m s⁻¹].
    weather_token : str
        Names the weather the sky comes from ("" for clear sky): part of :meth:`sky_key`.
    """

    latitude: float
    longitude: float
    start: pd.Timestamp
    end: pd.Timestamp
    step_s: float
    collector: Collector
    altitude: float = 0.0
    rows: int = 5
    columns: int = 5
    slope_azimuth_deg: float = 0.0
    slope_tilt_deg: float = 0.0
    custom: tuple[float, float, float] | None = None
    plant: Plant | None = field(default=None, compare=False)
    timezone: str = "UTC"
    albedo: float = 0.2
    temp_air: float = 20.0
    wind_speed: float = 1.0
    weather_token: str = ""

    def sky_key(self) -> tuple[Any, ...]:
        """What the sky of the range depends on (equal keys: the same sky)."""
        return (self.latitude, self.longitude, self.altitude, self.start.value, self.end.value,
                self.step_s, self.temp_air, self.wind_speed, self.weather_token)

    def times(self) -> pd.DatetimeIndex:
        """The instants the range is simulated at (UTC): its steps and the instant closing
        the last (:func:`sim.energy.simulation_times`)."""
        return simulation_times(self.start, self.end, self.step_s)


def case_layout(spec: SweepSpec, case: SweepCase) -> FieldLayout:
    """The regular layout of a case (named, or ``custom`` from ``spec.custom``)."""
    if case.layout == "custom":
        if spec.custom is None:
            raise ValueError("layout 'custom' needs aspect_ratio, offset and rotation_deg")
        ar, off, rot = spec.custom
        return FieldLayout("custom", case.gcr, ar, off, rot, spec.slope_azimuth_deg,
                           spec.slope_tilt_deg)
    return FieldLayout.named(case.layout, case.gcr, spec.slope_azimuth_deg, spec.slope_tilt_deg)


def case_plant(spec: SweepSpec, case: SweepCase) -> tuple[Plant, int, float]:
    """The field of a case, the index of its interior collector and its land per collector
    [m²]. ``ValueError`` (naming the parameter) for an infeasible layout or GCR."""
    if case.layout == PLANT_LAYOUT:
        if spec.plant is None:
            raise ValueError(f"layout {PLANT_LAYOUT!r} needs a plant")
        plant = scaled_plant(spec.plant, case.gcr)
        return plant, interior_tracker(plant), plant_land_m2(plant) / plant.n_trackers
    layout = case_layout(spec, case)
    plant, interior = regular_field(layout, spec.collector, spec.latitude, spec.longitude,
                                    spec.altitude, spec.rows, spec.columns, spec.timezone,
                                    spec.albedo)
    return plant, interior, layout.land_m2_per_collector(spec.collector.area)


def site_plant(spec: SweepSpec) -> Plant:
    """A one-collector plant at the sweep's place: what :func:`sky_conditions` reads."""
    return Plant(plant_id="site", name="site", latitude=spec.latitude, longitude=spec.longitude,
                 altitude=spec.altitude, timezone=spec.timezone, tracker_ids=(1,),
                 positions=np.zeros((1, 3)), collector=spec.collector, albedo=spec.albedo,
                 temp_air=spec.temp_air, wind_speed=spec.wind_speed)


def case_sky(spec: SweepSpec, weather: pd.DataFrame | None = None) -> dict[str, FloatArray]:
    """Sun (SPA) and irradiance of the range, shared by every case of the sweep
    (:func:`sim.plant.simulate.sky_conditions`; clear sky unless ``weather``)."""
    return sky_conditions(site_plant(spec), spec.times(), weather, closing=True)


def run_case(spec: SweepSpec, case: SweepCase, sky: dict[str, FloatArray],
             weather: pd.DataFrame | None = None) -> dict[str, Any]:
    """The sweep row of one case (module docstring), on the range's ``sky``."""
    if case.strategy not in STRATEGIES:
        raise ValueError(f"strategy {case.strategy!r} is not one of {', '.join(STRATEGIES)}")
    plant, interior, land_m2 = case_plant(spec, case)
    r = simulate_plant(plant, spec.start, spec.end, spec.step_s, case.strategy, weather,
                       sky=sky, with_fixed=False, tracker=interior)
    s = r.summary()
    n = plant.n_trackers
    per_tracker = r.tracker_dni_weighted_shaded_fraction
    e_kwh = s["plant_energy_wh"] / n / 1000.0
    interior_kwh = r.energy_wh("tracker_power_w") / 1000

    def pct(x: float | None) -> float | None:
        return None if x is None or not np.isfinite(x) else round(100.0 * x, 6)

    return {
        "layout": case.layout if case.layout != PLANT_LAYOUT else plant.plant_id.rsplit("-gcr")[0],
        "gcr": case.gcr,
        "strategy": case.strategy,
        "interior_beam_shaded_pct": pct(None if per_tracker is None else
                                        float(per_tracker[interior])),
        "field_beam_shaded_pct": pct(r.dni_weighted_shaded_fraction),
        "energy_kwh_per_collector": round(e_kwh, 4),
        "interior_energy_kwh": round(interior_kwh, 4),
        "energy_mwh_per_ha": round(e_kwh / land_m2 * 10.0, 4),   # kWh/m² · 10⁴ m²/ha / 10³
        "interior_energy_mwh_per_ha": round(interior_kwh / land_m2 * 10.0, 4),
        "land_m2_per_collector": round(land_m2, 4),
        "collectors": n,
        "shading_loss_electrical_pct": s["shading_loss_electrical_pct"],
    }


def _day_times(date: dt.date, timezone: str, step_s: float) -> pd.DatetimeIndex:
    """The steps of a local day (UTC), from its midnight to the next (23 or 25 h at DST)."""
    day0, day1 = local_day(date, timezone)
    return pd.date_range(day0.tz_convert("UTC"), day1.tz_convert("UTC"),
                         freq=pd.Timedelta(seconds=step_s), inclusive="left")


def shade_day(spec: SweepSpec, step_s: float = 900.0) -> str:
    """The default day of a case's shade (:func:`case_day_shade`): the winter solstice of the
    place's hemisphere (21 December north, 21 June south: the longest shadows) in the local
    year the sweep starts, or, where that day has no daylight step (a polar night: 69.65° N
    on 21 December), the day nearest to it that has one. ISO date."""
    year = spec.start.tz_convert(spec.timezone).year
    solstice = dt.date(year, 6 if spec.latitude < 0 else 12, 21)
    days = sorted((solstice + dt.timedelta(days=k) for k in range(-183, 184)),
                  key=lambda d: abs((d - solstice).days))
    for n in (1, 31, len(days)):  # the solstice alone first, then widening windows
        each = [_day_times(d, spec.timezone, step_s) for d in days[:n]]
        up = sky_conditions(site_plant(spec), each[0].append(each[1:]))["apparent_elevation"] > 0
        ends = np.cumsum([len(t) for t in each])
        lit = np.add.reduceat(up, ends - [len(t) for t in each]) > 0
        if lit.any():
            return days[int(np.argmax(lit))].isoformat()
    return solstice.isoformat()  # no daylight within half a year of it: none anywhere


def case_day_shade(spec: SweepSpec, case: SweepCase, date: str, step_s: float = 900.0
                   ) -> dict[str, Any]:
    """A case's field through one clear-sky day (local date in ``spec.timezone``): every
    collector's shaded fraction at each daylight step under the case's strategy, the
    interior collector's, and the pivots (east, north) [m] to draw it."""
    from sim.plant.simulate import field_shade
    from sim.plant.strategies import orientations

    plant, interior, _ = case_plant(spec, case)
    times = _day_times(dt.date.fromisoformat(date), spec.timezone, step_s)
    sky = sky_conditions(plant, times)
    up = np.nonzero(sky["apparent_elevation"] > 0)[0]
    dsky = {k: v[up] for k, v in sky.items()}
    saz, sel = orientations(case.strategy, plant, dsky)
    shade, _ = field_shade(plant, dsky, saz, sel)
    frac = shade.fraction
    return {"layout": case.layout, "gcr": case.gcr, "strategy": case.strategy, "date": date,
            "step_s": step_s, "interior_index": interior,
            "positions_m": [[round(float(x), 3), round(float(y), 3)]
                            for x, y in plant.positions[:, :2]],
            "times": [ts.isoformat() for ts in times[up]],
            "sun_azimuth_deg": [float(a) for a in dsky["solar_azimuth"]],
            "sun_elevation_deg": [float(e) for e in dsky["apparent_elevation"]],
            "interior_shaded_fraction": [round(float(f), 5) for f in frac[:, interior]],
            "field_mean_shaded_fraction": [round(float(f), 5) for f in frac.mean(axis=1)],
            "shaded_fraction": [[round(float(f), 4) for f in row] for row in frac]}


def interior_beam_shaded_pct(layout: FieldLayout, collector: Collector,
                             sky: dict[str, FloatArray]) -> float:
    """The interior collector's Σ F · DNI / Σ DNI [%] over the daylight steps of ``sky``,
    every collector facing the sun (twoaxistracking's figure; a sweep case's
    ``interior_beam_shaded_pct`` under ``sun`` without the electrical model): what a layout
    search evaluates per candidate. ``sky`` as :func:`case_sky` returns it: the range's
    steps and the instant closing the last, which is left out (as the sweep's cases do)."""
    from sim.plant.shading import plant_shade

    sky = {k: v[:-1] for k, v in sky.items()}
    up = sky["apparent_elevation"] > 0
    az, el, dni = sky["solar_azimuth"][up], sky["apparent_elevation"][up], sky["dni"][up]
    positions, interior = lattice_positions(layout, collector.area, 5, 5)
    shade = plant_shade(positions, az, el, az, el, collector.width, collector.height,
                        outline=None if collector.is_rectangle else collector.outline_m())
    return float(100.0 * np.sum(shade.fraction[:, interior] * dni) / np.sum(dni))


def least_shaded_layout(collector: Collector, sky: dict[str, FloatArray], gcr: float,
                        offset: float, aspect_ratios: FloatArray, rotations_deg: FloatArray
                        ) -> tuple[FieldLayout, float]:
    """The layout of one family (a row ``offset``: 0 rectangular, −0.5 diamond) at ``gcr``
    whose interior collector loses the least beam to shade, by a grid search over aspect
    ratio and rotation (Cumpston & Pye 2014 §3 optimise the same parameters at each GCR);
    candidates outside the limits of :meth:`FieldLayout.check` are skipped. Returns the
    layout and its :func:`interior_beam_shaded_pct`; ``ValueError`` when no candidate is
    feasible."""
    best: tuple[FieldLayout, float] | None = None
    for ar in np.asarray(aspect_ratios, dtype=float):
        for rot in np.asarray(rotations_deg, dtype=float):
            layout = FieldLayout("custom", gcr, float(ar), offset, float(rot))
            try:
                layout.check(collector)
            except ValueError:
                continue
            pct = interior_beam_shaded_pct(layout, collector, sky)
            if best is None or pct < best[1]:
                best = (layout, pct)
    if best is None:
        raise ValueError(f"no feasible layout with offset {offset} at gcr {gcr}")
    return best


__all__ = ["PLANT_LAYOUT", "SweepCase", "SweepSpec", "case_layout", "case_plant", "case_sky",
           "case_day_shade", "interior_beam_shaded_pct", "least_shaded_layout", "run_case",
           "shade_day", "site_plant"]
