"""The MPP table's error over real years, through the twin's own pipeline.

:func:`mpp_table_year_error` runs :func:`sim.twin.simulate` and records the
effective irradiance and cell temperature the twin hands to
:func:`sim.pv.array_mpp` for each array, then solves pvlib's full single-diode
model (Lambert-W, :func:`sim.pv.module_mpp_exact`) on exactly those inputs. Two
years, both arrays:

- clear sky (Ineichen) at ``tehuantepec``, 2023;
- the TMY3 file pvlib ships (``pvlib/data/723170TYA.CSV``, Greensboro NC), a
  tracker and a fixed 16° south array as at ``tehuantepec``.

``benchmarks/bench_sim.py`` measures the figures at 1-min steps and writes
them to ``benchmarks/results.json`` (``sim.mpp_*``); the tests below run the same
function at 5-min steps (the error is a property of the (irradiance,
temperature) pairs, not of the step) and assert it within 2× of those figures.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Any

import numpy as np
import pandas as pd
import pytest

from sim import pv
from sim.sites import Site, load_site, site_from_dict
from sim.sky import pvlib_tmy3_path, read_tmy3
from sim.twin import simulate


@contextmanager
def _recording_mpp_inputs(seen: dict[str, list[tuple[np.ndarray, np.ndarray]]]) -> Any:
    """Wrap ``sim.pv.array_mpp`` (which the twin calls) to record its inputs per array."""
    original = pv.array_mpp

    def spy(e: Any, t: Any, array: pv.ArrayConfig, exact: bool = False) -> dict:
        seen.setdefault(array.name, []).append(
            (np.array(e, dtype=float), np.broadcast_to(np.asarray(t, dtype=float), np.shape(e)))
        )
        return original(e, t, array, exact)

    pv.array_mpp = spy  # type: ignore[assignment]
    try:
        yield
    finally:
        pv.array_mpp = original  # type: ignore[assignment]


def greensboro_tmy3() -> tuple[Site, pd.DataFrame, pd.Timestamp, pd.Timestamp]:
    """The TMY3 site (tracker + fixed 16° south), its weather and the run it covers."""
    weather, meta = read_tmy3(pvlib_tmy3_path(), coerce_year=1990)
    site = site_from_dict(
        {
            "site_id": "greensboro",
            "latitude_deg": meta["latitude"],
            "longitude_deg": meta["longitude"],
            "altitude_m": meta["altitude"],
            "timezone": "America/New_York",
            "arrays": {
                "tracker": {"mount": "tracker"},
                "fixed": {"mount": "fixed", "surface_tilt_deg": 16, "surface_azimuth_deg": 180},
            },
        }
    )
    # the weather's mid-hour samples span 8,759 h: the run covers them, end exclusive
    return site, weather, weather.index[0], weather.index[-1]


def mpp_table_year_error(
    site: Site,
    start: pd.Timestamp,
    end: pd.Timestamp,
    step_s: float = 60,
    weather: pd.DataFrame | None = None,
    inputs: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
) -> dict[str, dict[str, float]]:
    """Per array: the table's energy error against the full single-diode solution.

    ``inputs``, when given, receives per array the recorded (effective
    irradiance [W m⁻²], cell temperature [°C]) of the daytime steps.

    Returns ``{array: {"energy_rel", "max_abs_w", "points", "twin_energy_wh"}}``:
    relative energy difference (table / exact − 1, [-]), the largest
    difference of module power at any step [W], the number of daytime steps,
    and the twin's energy of that array [Wh].
    """
    seen: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    with _recording_mpp_inputs(seen):
        result = simulate(site, start, end, step_s=step_s, weather=weather)
    out: dict[str, dict[str, float]] = {}
    for name, parts in seen.items():
        e = np.concatenate([p[0] for p in parts])
        t = np.concatenate([p[1] for p in parts])
        if inputs is not None:
            inputs[name] = (e, t)
        i_mp, v_mp = pv.mpp_table(site.arrays[name].module).lookup(e, t)
        p_table = i_mp * v_mp
        p_exact = pv.module_mpp_exact(e, t, site.arrays[name].module)["p_mp"]
        twin_wh = result.energy_wh(name)
        # what was recorded is what the twin integrated (no other route to the power)
        recorded_wh = p_table.sum() * site.arrays[name].modules * step_s / 3600.0
        if not np.isclose(recorded_wh, twin_wh, rtol=1e-9, atol=1e-9):
            raise AssertionError(f"{name}: recorded {recorded_wh} Wh, twin {twin_wh} Wh")
        out[name] = {
            "energy_rel": float(p_table.sum() / p_exact.sum() - 1.0),
            "max_abs_w": float(np.max(np.abs(p_table - p_exact))),
            "points": float(np.count_nonzero(e > 0)),
            "twin_energy_wh": twin_wh,
        }
    return out


def clear_sky_year(step_s: float = 60, inputs: Any = None) -> dict[str, dict[str, float]]:
    """:func:`mpp_table_year_error` for a clear-sky 2023 at ``tehuantepec``."""
    site = load_site("tehuantepec")
    start = pd.Timestamp("2023-01-01", tz=site.timezone)
    return mpp_table_year_error(site, start, start + pd.DateOffset(years=1), step_s, inputs=inputs)


def tmy3_year(step_s: float = 60, inputs: Any = None) -> dict[str, dict[str, float]]:
    """:func:`mpp_table_year_error` for pvlib's TMY3 year (Greensboro NC)."""
    site, weather, start, end = greensboro_tmy3()
    return mpp_table_year_error(site, start, end, step_s, weather=weather, inputs=inputs)


# Measured by benchmarks/bench_sim.py at 1-min steps (benchmarks/results.json,
# sim.mpp_energy_error_*, in %; sim.mpp_max_abs_w, W per module); the bounds are 2× those.
MEASURED_ENERGY_PCT = {
    ("clear", "tracker"): -0.00036,
    ("clear", "fixed"): -0.00060,
    ("tmy3", "tracker"): -0.00023,
    ("tmy3", "fixed"): -0.00034,
}
MEASURED_MAX_ABS_W = 0.037


@pytest.mark.parametrize("sky", ["clear", "tmy3"])
def test_mpp_table_energy_error_over_a_real_year(sky: str) -> None:
    figures = clear_sky_year(300) if sky == "clear" else tmy3_year(300)
    assert set(figures) == {"tracker", "fixed"}
    for name, f in figures.items():
        measured = MEASURED_ENERGY_PCT[(sky, name)] / 100
        # same sign, within a factor of two of the 1-min figure
        assert measured / 2 >= f["energy_rel"] >= 2 * measured, (name, f)
        assert f["max_abs_w"] < 2 * MEASURED_MAX_ABS_W, (name, f)
