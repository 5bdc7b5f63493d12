"""An inverter's limit (``inverter_limit_w``, sim.pv.array_mpp): a plant's DC/AC ratio of
1.1-1.4 clips a tracker on every clear day. Generated days (tests/sim/realistic_sky.py,
seed 31 held out) of Tehuantepec's arrays whose inverters deliver at most 600 W (820 W of
modules: DC/AC 1.37), diagnosed with and without the limit in the config."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from backend.diagnosis.faults import faults_over_days, features_by_day
from sim import pv, sky_sensor
from sim.sites import load_site
from tests.sim.realistic_sky import logger_days

SITE = load_site("tehuantepec")
FIRST = pd.Timestamp("2026-02-02", tz=SITE.timezone)
DAYS, SEED, LIMIT_W = 6, 31, 600.0


def _limited(site, limit_w: float | None):
    return replace(site, arrays={name: replace(a, inverter_limit_w=limit_w)
                                 for name, a in site.arrays.items()})


def test_the_limit_cuts_the_power_and_keeps_the_voltage() -> None:
    """array_mpp's power is the MPP's up to the limit and the limit above it, the current
    taking the cut at the MPP's voltage; without a limit, unchanged."""
    arr = SITE.arrays["tracker"]
    e = np.array([200.0, 600.0, 1000.0])
    t = np.full(3, 45.0)
    free = pv.array_mpp(e, t, arr)
    cut = pv.array_mpp(e, t, replace(arr, inverter_limit_w=500.0))
    np.testing.assert_allclose(cut["power_w"], np.minimum(free["power_w"], 500.0))
    np.testing.assert_allclose(cut["voltage_v"], free["voltage_v"])
    np.testing.assert_allclose(cut["current_a"] * cut["voltage_v"], cut["power_w"])
    assert free["power_w"][2] > 500.0 and cut["power_w"][0] == free["power_w"][0]
    with pytest.raises(ValueError, match="inverter_limit_w must be > 0 W"):
        replace(arr, inverter_limit_w=0.0)


def test_a_clipping_tracker_is_healthy_when_its_limit_is_known() -> None:
    """Both arrays clip at 600 W (hours a day: the loggers at 97 % of it or more). With the
    limit in the config a healthy tracker has no finding and its days read 0.999-1.011 of
    their expectation (the fixed array's clipped minutes read as at least the sky that
    gives the limit, sky_sensor.invert_poa); left out, five of six days read 0.927-0.946 and
    three are named an underperformance — a healthy plant accused on its sunniest days."""
    limited = _limited(SITE, LIMIT_W)
    d = logger_days(limited, FIRST, DAYS, SEED)
    assert d.tracker_power_w.max() < 1.04 * LIMIT_W  # the loggers' 1 % noise on the limit
    assert (d.tracker_power_w >= 0.97 * LIMIT_W).sum() > 600

    def diagnose(site):
        e = sky_sensor.weather_aware_twin(site, FIRST, FIRST + pd.Timedelta(days=DAYS),
                                          d.fixed_power_w)
        days = features_by_day(site, FIRST, e, d.tracker_power_w)
        ratios = [day["features"]["energy"]["measured_wh"] / day["features"]["energy"][
            "expected_wh"] for day in days]
        kinds = [f["kind"] for day in faults_over_days(days) for f in day]
        return np.array(ratios), kinds

    known, known_kinds = diagnose(limited)
    unknown, unknown_kinds = diagnose(SITE)
    # an inverter that reports its limit exactly (no noise: hours of one value, not a frozen
    # logger) reads the same
    exact = d.fixed_power_w.copy()
    d.fixed_power_w[:] = np.minimum(exact, LIMIT_W)
    assert (d.fixed_power_w == LIMIT_W).sum() > 300
    held, held_kinds = diagnose(limited)
    assert not held_kinds and np.all(np.abs(held - 1.0) < 0.015), held
    assert not known_kinds and np.all(np.abs(known - 1.0) < 0.015), known
    assert unknown_kinds.count("underperformance") == 3, unknown_kinds
    assert np.sum(unknown < 0.95) == 5 and unknown.min() > 0.92, unknown


def test_the_limit_is_a_site_files_key_and_round_trips() -> None:
    """``inverter_limit_w`` in a site file's array, back out of :meth:`to_config` and in
    the array's description; left out, neither says it."""
    from sim.pv import array_config_from_dict

    arr = array_config_from_dict("tracker", {"mount": "tracker", "inverter_limit_w": 600})
    assert arr.inverter_limit_w == 600.0
    assert arr.to_config()["inverter_limit_w"] == 600.0
    assert arr.to_dict()["inverter_limit_w"] == 600.0
    plain = array_config_from_dict("tracker", {"mount": "tracker", "inverter_limit_w": None})
    assert "inverter_limit_w" not in plain.to_config() and "inverter_limit_w" not in \
        plain.to_dict()
