"""The stuck-tracker diagnosis against an independent method: pvanalytics' NREL day-profile tests.

``pvanalytics.features.orientation.tracking_nrel`` / ``fixed_nrel`` (Perry et al.,
NREL's PVFleets QA) fit a quartic (tracking) or a quadratic (fixed) to each day's
power profile. They know nothing of our twin or sky, so on every day they can
classify, a day they call fixed-like and not tracking must carry our ``stuck`` fault
(confidence ≥ 0.5) and a day they call tracking must not. Days they cannot classify
(cloud) say nothing. Realistic days from tests/sim/realistic_sky.py, held-out seeds
31–33 (the diagnosis was tuned on seeds 1–4), the tracker frozen at azimuth 181°,
elevation 35° from day 3.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from backend.diagnosis.faults import faults_over_days, features_by_day
from sim import sky_sensor, sun
from sim.sites import load_site
from tests.sim.realistic_sky import logger_days

orientation = pytest.importorskip("pvanalytics.features.orientation")

SITE = load_site("tehuantepec")
FIRST = pd.Timestamp("2026-02-02", tz=SITE.timezone)
DAYS, FAULT_DAY = 6, 3


def _pvanalytics_days(power_w: np.ndarray, times: pd.DatetimeIndex) -> list[str | None]:
    """Each local day as pvanalytics sees its profile: "tracking", "fixed" or None."""
    power = pd.Series(np.nan_to_num(power_w), index=times.tz_convert(SITE.timezone))
    elevation = sun.solar_position(times, SITE.latitude, SITE.longitude,
                                   SITE.altitude)["apparent_elevation"].to_numpy()
    daytime = pd.Series(elevation > 0.0, index=power.index)
    tracking = orientation.tracking_nrel(power, daytime).resample("D").max()
    fixed = orientation.fixed_nrel(power, daytime).resample("D").max()
    return ["tracking" if t and not f else "fixed" if f and not t else None
            for t, f in zip(tracking.to_numpy(bool), fixed.to_numpy(bool), strict=True)]


def test_stuck_days_agree_with_pvanalytics() -> None:
    verdicts = []
    for seed in (31, 32, 33):
        d = logger_days(SITE, FIRST, DAYS, seed, fault="stuck", fault_day=FAULT_DAY)
        e = sky_sensor.weather_aware_twin(SITE, FIRST, FIRST + pd.Timedelta(days=DAYS),
                                          d.fixed_power_w)
        ours = faults_over_days(features_by_day(SITE, FIRST, e, d.tracker_power_w))
        for k, theirs in enumerate(_pvanalytics_days(d.tracker_power_w, d.times)):
            if theirs is not None:
                stuck = any(f["kind"] == "stuck" and f["confidence"] >= 0.5 for f in ours[k])
                verdicts.append((seed, k, d.kinds[k], theirs, stuck))
    # not vacuous: pvanalytics names healthy days tracking and stuck days fixed
    assert {(k >= FAULT_DAY, theirs) for _, k, _, theirs, _ in verdicts} == {
        (False, "tracking"), (True, "fixed")}, verdicts
    assert all(stuck == (theirs == "fixed") for *_, theirs, stuck in verdicts), verdicts
