"""Hand-typed figures in the docs agree with the code and with the tests that guard them.

A measured figure in ``docs/*.md`` either comes from a ``<!-- fig:NAME -->`` marker
filled by ``make bench`` (tests/test_docs_figures.py) or is checked here: the
number is read from the doc and compared with what the code computes now (to the
precision the doc prints), or with the constant or tolerance the guarding test
really uses (read from that test's source, so a tightened test and a stale doc
cannot disagree silently).
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
NUMBER = re.compile(r"[−-]?\d[\d,]*(?:\.\d+)?(?:e[−-]?\d+)?")


def doc(name: str) -> str:
    """The text of ``docs/<name>``."""
    return (ROOT / "docs" / name).read_text(encoding="utf-8")


def numbers(text: str) -> list[float]:
    """The numbers in ``text`` (typographic minus and thousands commas understood)."""
    return [float(n.replace("−", "-").replace(",", "")) for n in NUMBER.findall(text)]


def decimals(text: str) -> list[int]:
    """How many decimals each number in ``text`` is printed with."""
    return [len(n.split(".")[1]) if "." in n else 0 for n in NUMBER.findall(text)]


def table_row(text: str, *lead: str) -> list[str]:
    """The cells after ``lead`` of the first Markdown table row whose first cells are ``lead``."""
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and tuple(cells[: len(lead)]) == lead:
            return cells[len(lead):]
    raise AssertionError(f"no table row {lead!r}")


def sentence(text: str, pattern: str) -> re.Match[str]:
    """The one match of ``pattern`` in ``text`` (whitespace in the doc may wrap)."""
    found = list(re.finditer(pattern.replace(" ", r"\s+"), text))
    assert len(found) == 1, f"{pattern!r} found {len(found)} times"
    return found[0]


def _function(path: Path, name: str) -> ast.FunctionDef:
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.FunctionDef) and node.name == name:
            return node
    raise AssertionError(f"no function {name} in {path}")


def module_constant(path: str, name: str) -> Any:
    """The literal value a test module assigns to ``name`` at its top level."""
    for node in ast.parse((ROOT / path).read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == name for t in node.targets
        ):
            return ast.literal_eval(node.value)
    raise AssertionError(f"no constant {name} in {path}")


def approx_tolerances(path: str, function: str) -> list[tuple[str, float]]:
    """The ``rel=``/``abs=`` of every ``pytest.approx`` in a test function, in order."""
    out = []
    for node in ast.walk(_function(ROOT / path, function)):
        if isinstance(node, ast.Call) and ast.unparse(node.func) == "pytest.approx":
            out += [(k.arg or "", ast.literal_eval(k.value)) for k in node.keywords]
    return out


def parametrize_count(path: str, function: str) -> int:
    """How many cases the ``pytest.mark.parametrize`` of a test function gives it."""
    for deco in _function(ROOT / path, function).decorator_list:
        if isinstance(deco, ast.Call) and ast.unparse(deco.func).endswith("parametrize"):
            return len(ast.literal_eval(deco.args[1]))
    raise AssertionError(f"{function} is not parametrized")


def assert_printed(doc_values: list[float], places: list[int], computed: list[float]) -> None:
    """Each computed value, rounded as the doc prints it, is the doc's (to one unit in its
    last place: the doc and a recomputation may round a value on the edge differently)."""
    assert len(doc_values) == len(computed), (doc_values, computed)
    for shown, n, value in zip(doc_values, places, computed, strict=True):
        assert abs(round(value, n) - shown) <= 1.01 * 10.0**-n, (shown, value)


def test_helpers_read_what_they_should() -> None:
    assert numbers("−0.00058 %, 1,333 W and 2e-5") == [-0.00058, 1333.0, 2e-5]
    assert decimals("1.166° (20.4 mrad) 17") == [3, 1, 0]
    assert table_row("| a | b |\n| x | 1 | 2 |\n", "x") == ["1", "2"]
    with pytest.raises(AssertionError):
        assert_printed([13.5], [1], [13.3])


# --- docs/validation.md -------------------------------------------------------------


def test_validation_sun_tolerances_are_the_tests() -> None:
    m = sentence(
        doc("validation.md"), r"asserts max < ([\d.]+)° and a mean between ([\d.]+)° and ([\d.]+)°"
    )
    constants = "tests/sim/test_sun.py"
    assert float(m.group(1)) == module_constant(constants, "MAX_DB_SEP_DEG")
    assert (float(m.group(2)), float(m.group(3))) == module_constant(constants, "MEAN_DB_SEP_DEG")


def test_validation_modelchain_tolerances_are_the_tests() -> None:
    text = doc("validation.md")
    m = sentence(text, r"\((\w+) days across the seasons, energies within ([\de.-]+) relative, "
                       r"gain within ([\d.]+) points")
    days = {"two": 2, "three": 3, "four": 4, "five": 5}[m.group(1)]
    test = ("tests/sim/test_twin.py", "test_day_energy_agrees_with_pvlib_modelchain")
    assert parametrize_count(*test) == days
    tolerances = approx_tolerances(*test)
    assert tolerances[:3] == [("rel", float(m.group(2)))] * 2 + [("abs", float(m.group(3)))]
    m = sentence(text, r"matches ModelChain on that weather within ([\d.]+) %")
    tmy = approx_tolerances("tests/sim/test_twin.py", "test_twin_on_pvlib_tmy3_weather")
    assert tmy == [("rel", float(m.group(1)) / 100)] * 2


def test_validation_mpp_fixed_plane_bound_is_twice_the_figure() -> None:
    m = sentence(doc("validation.md"), r"10-min steps: ([−\d.]+) %, asserted within 2×")
    measured = numbers(m.group(1))[0] / 100
    src = _function(ROOT / "tests/sim/test_pv.py",
                    "test_mpp_table_close_to_full_single_diode_over_a_clear_year")
    bound = next(
        ast.literal_eval(n.left)
        for n in ast.walk(src)
        if isinstance(n, ast.Compare) and isinstance(n.left, ast.UnaryOp)
    )
    assert bound == pytest.approx(2 * measured, rel=0.05)


def test_validation_stc_table_is_the_cec_model() -> None:
    from sim.pv import KD205GX_LP_DATASHEET_STC as SHEET
    from sim.pv import module_mpp_exact

    twin = module_mpp_exact(np.array([1000.0]), np.array([25.0]))
    text = doc("validation.md")
    for label, sheet_key, twin_key in [
        ("P_mp", "pmax_w", "p_mp"),
        ("V_mp", "vmp_v", "v_mp"),
        ("I_mp", "imp_a", "i_mp"),
        ("V_oc", "voc_v", "v_oc"),
        ("I_sc", "isc_a", "i_sc"),
    ]:
        sheet_cell, twin_cell = table_row(text, label)
        assert numbers(sheet_cell) == [SHEET[sheet_key]]
        assert_printed(numbers(twin_cell), decimals(twin_cell), [float(twin[twin_key][0])])


def _separations(lat: float, lon: float, start: str, end: str) -> list[float]:
    """Duffie–Beckman vs SPA at 1 min with the sun up: (angle, |Δazimuth| below 80°
    elevation, |Δelevation|), each max then mean [°] — the method of validation.md §1."""
    from sim.sun import solar_position
    from vision.sphere import angular_separation_deg

    times = pd.date_range(start, end, freq="1min", inclusive="left", tz="UTC")
    db = solar_position(times, lat, lon, method="duffie-beckman")
    spa = solar_position(times, lat, lon)
    up = spa["elevation"] > 0
    sep = angular_separation_deg(db["azimuth"], 90 - db["zenith"], spa["azimuth"],
                                 90 - spa["zenith"])[up]
    d_az = np.abs((db["azimuth"] - spa["azimuth"] + 180) % 360 - 180)[up & (spa["elevation"] < 80)]
    d_el = np.abs(db["zenith"] - spa["zenith"])[up]
    return [float(f(x)) for x in (sep, d_az, d_el) for f in (np.max, np.mean)]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("row", "place"),
    [
        ("Tehuantepec, all of 2024", (16.28875, -95.240871, "2024-01-01", "2025-01-01")),
        (
            "Hermosillo (≈ 29.0 N, 111.1 W; the paper gives no coordinates), 26–27 Sep 2022, "
            "seed 001's test days",
            (29.0, -111.1, "2022-09-26 07:00", "2022-09-28 07:00"),
        ),
        ("Hermosillo, all of 2022", (29.0, -111.1, "2022-01-01", "2023-01-01")),
    ],
    ids=["tehuantepec-2024", "hermosillo-days", "hermosillo-2022"],
)
def test_validation_duffie_beckman_table(row: str, place: tuple) -> None:
    cells = table_row(doc("validation.md"), row)
    degrees = [c.split("/") for c in cells]  # "1.166° (20.4 mrad) / 0.413° (7.2 mrad)"
    shown = [numbers(part)[0] for pair in degrees for part in pair]
    places = [decimals(part)[0] for pair in degrees for part in pair]
    computed = _separations(*place)
    assert_printed(shown, places, computed)
    mrad = [numbers(part)[1] for pair in degrees for part in pair]
    assert_printed(mrad, [1] * len(mrad), [float(np.radians(d)) * 1000 for d in computed])


def _window_gain(series: pd.DataFrame, tz: str) -> float:
    """Tracker over fixed energy [%] counting only 09:30–16:30 local time (both ends in)."""
    hhmm = series.index.tz_convert(tz).strftime("%H:%M")
    inside = (hhmm >= "09:30") & (hhmm <= "16:30")
    return float(100 * (series.loc[inside, "tracker_power_w"].sum()
                        / series.loc[inside, "fixed_power_w"].sum() - 1))


@pytest.fixture(scope="module")
def tehuantepec():  # noqa: ANN201
    from sim.sites import load_site

    return load_site("tehuantepec")


@pytest.mark.parametrize("day", ["2024-03-15", "2024-04-25"])
def test_validation_gain_table_days(tehuantepec, day: str) -> None:
    from sim.twin import simulate

    start = pd.Timestamp(day, tz=tehuantepec.timezone)
    r = simulate(tehuantepec, start, start + pd.Timedelta(days=1))
    s = r.summary()
    tracker, fixed, gain, peaks, window = table_row(doc("validation.md"), day)
    assert_printed(numbers(tracker) + numbers(fixed), [2, 2],
                   [s["tracker_energy_wh"] / 1000, s["fixed_energy_wh"] / 1000])
    assert_printed(numbers(gain), [1], [s["gain_pct"]])
    peak_time = r.series["fixed_power_w"].idxmax().tz_convert(tehuantepec.timezone)
    assert_printed(numbers(peaks), [1, 1, 0, 0],
                   [s["tracker_peak_w"], s["fixed_peak_w"], peak_time.hour, peak_time.minute])
    assert_printed(numbers(window), [1], [_window_gain(r.series, tehuantepec.timezone)])


def test_validation_gain_table_alternative_dates(tehuantepec) -> None:
    from sim.twin import simulate

    cells = table_row(doc("validation.md"),
                      "2024-04-15 / 2024-03-25 (the paper's alternative dates)")
    gains, peaks, windows = [], [], []
    for day in ("2024-04-15", "2024-03-25"):
        start = pd.Timestamp(day, tz=tehuantepec.timezone)
        r = simulate(tehuantepec, start, start + pd.Timedelta(days=1))
        gains.append(r.summary()["gain_pct"])
        peaks.append(r.summary()["fixed_peak_w"])
        windows.append(_window_gain(r.series, tehuantepec.timezone))
    assert_printed(numbers(cells[2]), [1, 1], gains)
    assert_printed(numbers(cells[3]), [1, 1], peaks)
    assert_printed(numbers(cells[4]), [1, 1], windows)


@pytest.mark.slow
def test_validation_gain_table_year(tehuantepec) -> None:
    from sim.twin import simulate

    tz = tehuantepec.timezone
    r = simulate(tehuantepec, pd.Timestamp("2024-01-01", tz=tz), pd.Timestamp("2025-01-01", tz=tz))
    s = r.summary()
    month = r.series.index.tz_convert(tz).month
    by_month = r.series.groupby(month)[["tracker_power_w", "fixed_power_w"]].sum()
    monthly = 100 * (by_month["tracker_power_w"] / by_month["fixed_power_w"] - 1)
    tracker, fixed, gain, peaks, window = table_row(doc("validation.md"), "year 2024")
    assert_printed(numbers(tracker) + numbers(fixed), [0, 0],
                   [s["tracker_energy_wh"] / 1000, s["fixed_energy_wh"] / 1000])
    assert_printed(numbers(gain), [1, 1, 1], [s["gain_pct"], monthly.min(), monthly.max()])
    assert_printed(numbers(peaks), [1, 1], [s["tracker_peak_w"], s["fixed_peak_w"]])
    assert_printed(numbers(window), [1], [_window_gain(r.series, tz)])
    m = sentence(doc("validation.md"), r"\*\*([\d.]+) % over the year\*\*")
    assert float(m.group(1)) == numbers(window)[0]


@pytest.mark.slow
def test_validation_tmy3_year() -> None:
    import sys

    sys.path.insert(0, str(ROOT / "tests" / "sim"))
    from test_mpp_year import greensboro_tmy3

    from sim.sites import site_from_dict
    from sim.twin import simulate

    text = doc("validation.md")
    m = sentence(text, r"a fixed array at (\d+)° south: tracker ([\d.]+) kWh, fixed ([\d.]+) kWh, "
                       r"\*\*gain ([\d.]+) %\*\* \(clear-sky year at the same site: ([\d.]+) %\)")
    site, weather, start, end = greensboro_tmy3()
    tilted = site_from_dict({
        "site_id": "greensboro", "latitude_deg": site.latitude, "longitude_deg": site.longitude,
        "altitude_m": site.altitude, "timezone": "America/New_York",
        "arrays": {"tracker": {"mount": "tracker"},
                   "fixed": {"mount": "fixed", "surface_tilt_deg": float(m.group(1)),
                             "surface_azimuth_deg": 180}},
    })
    tmy = simulate(tilted, start, end, weather=weather).summary()
    clear = simulate(tilted, start, end).summary()
    shown = [float(g) for g in m.groups()[1:]]
    assert_printed(shown, [1, 1, 1, 1], [tmy["tracker_energy_wh"] / 1000,
                                         tmy["fixed_energy_wh"] / 1000,
                                         tmy["gain_pct"], clear["gain_pct"]])
    # section 4 quotes the same two gains
    m4 = sentence(text, r"the twin gives \*\*([\d.]+) %\*\*, against ([\d.]+) % for a clear-sky")
    assert [float(g) for g in m4.groups()] == shown[2:]


def test_validation_reading_of_the_duffie_beckman_table() -> None:
    text = doc("validation.md")
    mrad = [numbers(part)[1] for cell in table_row(
        text, "Hermosillo (≈ 29.0 N, 111.1 W; the paper gives no coordinates), 26–27 Sep 2022, "
              "seed 001's test days") for part in cell.split("/")]
    # columns: angle max/mean, azimuth max/mean, elevation max/mean
    m = sentence(text, r"Duffie–Beckman is about (\d+)–(\d+) mrad away from SPA in azimuth and "
                       r"(\d+)–(\d+) mrad in elevation")
    assert numbers(" ".join(m.groups())) == [round(mrad[3]), round(mrad[2]),
                                             round(mrad[5]), round(mrad[4])]
    m = sentence(text, r"in azimuth it accounts for at most ~(\d+) of")
    assert float(m.group(1)) == round(mrad[2])
    year = table_row(text, "Tehuantepec, all of 2024")[0]
    m = sentence(text, r"The year-round maximum \(≈ (\d+) mrad at Tehuantepec\)")
    assert float(m.group(1)) == round(numbers(year)[1])


def test_validation_cooper_declination_against_spa() -> None:
    from pvlib import solarposition, spa

    from sim.sun import _unix_seconds

    # local (standard) noon of every day of 2024 at Tehuantepec, UTC−6
    noon = pd.date_range("2024-01-01 18:00", "2025-01-01", freq="1D", inclusive="left", tz="UTC")
    delta = spa.solar_position_numpy(_unix_seconds(noon), 0.0, 0.0, 0.0, 1013.25, 12.0, 67.0,
                                     0.5667, 1, sst=True)[2]
    cooper = np.degrees(solarposition.declination_cooper69(noon.day_of_year.to_numpy()))
    diff = np.abs(cooper - np.asarray(delta))
    m = sentence(doc("validation.md"), r"off from SPA's declination at local noon by up to "
                                       r"([\d.]+)° \(mid-October; ([\d.]+)° on average over 2024\)")
    assert_printed(numbers(" ".join(m.groups())), [2, 2], [diff.max(), diff.mean()])
    assert noon[diff.argmax()].month == 10 and 10 <= noon[diff.argmax()].day <= 20


def test_validation_clear_sky_peaks_and_irradiation(tehuantepec) -> None:
    import dataclasses

    from sim.sky import clearsky_ineichen
    from sim.sun import solar_position
    from sim.twin import simulate

    def day_run(day: str, **site: float) -> Any:
        start = pd.Timestamp(day, tz=tehuantepec.timezone)
        return simulate(dataclasses.replace(tehuantepec, **site), start,
                        start + pd.Timedelta(days=1))

    text = doc("validation.md")
    days = ("2024-03-15", "2024-04-25")
    runs = {d: day_run(d) for d in days}
    peaks = [r.summary()["fixed_peak_w"] for r in runs.values()]
    cells = [r.series.loc[r.series["fixed_power_w"].idxmax(), "fixed_temp_cell"]
             for r in runs.values()]
    m = sentence(text, r"noon power is (\d+)–(\d+) W with cells at\s+(\d+)–(\d+) °C")
    assert_printed(numbers(" ".join(m.groups())), [0] * 4,
                   [min(peaks), max(peaks), min(cells), max(cells)])
    m = sentence(text, r"at (\d+) m/s wind the same sky gives (\d+) W \(15 March\) and (\d+) W "
                       r"\(25 April\); cooler air \((\d+) °C\) gives (\d+) W / (\d+) W")
    wind, w1, w2, air, a1, a2 = numbers(" ".join(m.groups()))
    assert_printed([w1, w2, a1, a2], [0] * 4,
                   [day_run(d, wind_speed=wind).summary()["fixed_peak_w"] for d in days]
                   + [day_run(d, temp_air=air).summary()["fixed_peak_w"] for d in days])
    # the seed's measured peaks (seed 000) against the twin's
    m = sentence(text, r"The measured ([\d.]+) W lies (\d+) % above the\s+twin's 15 March value; "
                       r"the measured ([\d.]+) W is (\d+)–(\d+) % above the twin's\s+April values "
                       r"\(([\d.]+) W on 15 April, ([\d.]+) W on 25 April\)")
    march, above, april, low, high, apr15, apr25 = numbers(" ".join(m.groups()))
    april_peaks = [day_run("2024-04-15").summary()["fixed_peak_w"], peaks[1]]
    assert_printed([apr15, apr25], [1, 1], april_peaks)
    assert_printed([above, low, high], [0, 0, 0],
                   [100 * (march / peaks[0] - 1), 100 * (april / april_peaks[0] - 1),
                    100 * (april / april_peaks[1] - 1)])
    m = sentence(text, r"vs the twin's (\d+):(\d+) \(solar noon")
    at = runs["2024-04-25"].series["fixed_power_w"].idxmax().tz_convert(tehuantepec.timezone)
    assert numbers(" ".join(m.groups())) == [at.hour, at.minute]
    m = sentence(text, r"the clear-sky model's ([\d.]+) kWh/m²\s+\(15 March\) and ([\d.]+) kWh/m² "
                       r"\(25 April\)")
    ghi = []
    for d in days:
        times = pd.date_range(d, periods=1440, freq="1min", tz=tehuantepec.timezone)
        sun = solar_position(times, tehuantepec.latitude, tehuantepec.longitude,
                             altitude=tehuantepec.altitude)
        with np.errstate(divide="ignore"):
            cs = clearsky_ineichen(times, sun["apparent_zenith"].to_numpy(), tehuantepec.latitude,
                                   tehuantepec.longitude, tehuantepec.altitude)
        ghi.append(float(np.sum(cs["ghi"])) / 60 / 1000)
    assert_printed(numbers(" ".join(m.groups())), [1, 1], ghi)


@pytest.mark.slow
def test_validation_forced_distant_station_run(tehuantepec) -> None:
    from backend.twin.scenario import Scenario, check_station, run_scenario
    from sim.sky import pvlib_tmy3_path, read_typical_year

    weather, meta = read_typical_year(pvlib_tmy3_path(), "tmy3")
    station = check_station(meta, tehuantepec, True)
    tz = tehuantepec.timezone
    start, end = pd.Timestamp("2024-01-01", tz=tz), pd.Timestamp("2025-01-01", tz=tz)
    series = run_scenario(tehuantepec, Scenario(tehuantepec.site_id, start, end, weather=weather,
                                                station=station)).series
    m = sentence(doc("validation.md"), r"The forced Greensboro year at Tehuantepec peaks at "
                                       r"([\d,]+) W at (\d+):(\d+)\s+\((\d+) January\), "
                                       r"against ([\d.]+) W on the clear-sky year")
    peak, hour, minute, day, clear = numbers(" ".join(m.groups()))
    at = series["tracker_power_w"].idxmax().tz_convert(tz)
    assert_printed([peak], [0], [series["tracker_power_w"].max()])
    assert (at.month, at.day, at.hour, at.minute) == (1, day, hour, minute)
    assert clear == round(numbers(table_row(doc("validation.md"), "year 2024")[3])[0])


# --- docs/dynamics.md ---------------------------------------------------------------


def test_dynamics_values_at_table_1() -> None:
    from sim.dynamics import TrackerInertia, gravity, mass_matrix

    p = TrackerInertia.seed002()
    m = sentence(doc("dynamics.md"), r"M22 = ([\d.]+) kg m², M11\(9.9°\) = ([\d.]+) kg m², "
                 r"M11 spans ([\d.]+) \(normal horizontal\) … ([\d.]+) kg m² \(normal vertical\), "
                 r"G2\(0°\) = ([−\d.]+) N m, G2\(9.9°\) = ([−\d.]+) N m")
    shown = numbers(" ".join(m.groups()))
    q = np.radians([9.9, 0.0, 90.0])
    computed = [mass_matrix(q[0], p)[1, 1], mass_matrix(q[0], p)[0, 0],
                mass_matrix(q[1], p)[0, 0], mass_matrix(q[2], p)[0, 0],
                gravity(q[1], p)[1], gravity(q[0], p)[1]]
    assert_printed(shown, [4] * 6, [float(v) for v in computed])


def test_dynamics_pd_sag_and_pid_bound() -> None:
    from sim.dynamics import TrackerInertia
    from sim.dynamics_check import KD_SEED002, KP_SEED002

    p = TrackerInertia.seed002()
    text = doc("dynamics.md")
    m = sentence(text, r"m2 g \|cg2\| / Kp = ([\d.]+) rad = ([\d.]+)°")
    sag = p.m2_kg * p.g_m_s2 * abs(p.cg2_m) / KP_SEED002
    assert_printed(numbers(" ".join(m.groups())), [3, 1], [sag, float(np.degrees(sag))])
    m = sentence(text, r"Ki < Kp Kd / M22 = ([\d.]+)")
    assert_printed(numbers(m.group(1)), [1], [KP_SEED002 * KD_SEED002 / p.m22_kg_m2])


@pytest.mark.slow
def test_dynamics_pymunk_check_table() -> None:
    from sim.dynamics_check import check

    result = check(1e-3)
    text = doc("dynamics.md")
    rows = {
        "seed002_azimuth_return": "seed 002 azimuth return −244° → −115.5° at 9.9°",
        "elevation_slew_0_60": "elevation slew 0° → 60°",
        "coupled_slew": "coupled slew: az 0° → 60°, el 10° → 40°",
    }
    for move in result["moves"]:
        duration, peak, torque, angle = table_row(text, rows[move["name"]])
        assert_printed(numbers(duration), [1], [move["duration_s"]])
        peaks = [move["peak_torque_elevation_nm"]]
        if "az" in peak:
            peaks.append(move["peak_torque_azimuth_nm"])
        assert_printed(numbers(peak), decimals(peak), peaks)
        assert_printed(numbers(torque) + numbers(angle), decimals(torque) + decimals(angle),
                       [move["torque_rms_diff_pct_of_peak"], move["angle_rms_diff_mrad"]])
    worst = table_row(text, "**worst**")
    assert_printed(numbers(" ".join(worst)), [4, 4],
                   [result["torque_rms_diff_pct_of_peak"], result["angle_rms_diff_mrad"]])
    m = sentence(text, r"at 5 ms and 10 ms the worst angle difference is ([\d.]+) and "
                       r"([\d.]+) mrad")
    assert_printed(numbers(" ".join(m.groups())), [3, 3],
                   [check(dt)["angle_rms_diff_mrad"] for dt in (5e-3, 1e-2)])


@pytest.mark.slow
def test_dynamics_gravity_hold_table() -> None:
    from sim.dynamics_check import gravity_hold_study

    study = gravity_hold_study()
    keys = ["pd_analytic", "pd_pymunk", "pd_equilibrium", "pd_gravity", "pid_30s", "pid_120s"]
    for row in ("9.9", "60.0"):
        cells = table_row(doc("dynamics.md"), f"{float(row):g}°")
        assert len(cells) == len(keys)
        for cell, key in zip(cells, keys, strict=True):
            value = study[row][key]
            if "e-" in cell:  # printed as an order of magnitude
                assert cell.rstrip("°") == f"{value:.0e}".replace("e-0", "e-"), (cell, value)
            else:
                assert_printed(numbers(cell), decimals(cell), [value])


def test_validation_station_distance_rule(tehuantepec) -> None:
    from backend.twin.scenario import MAX_STATION_DISTANCE_KM, station_distance_km
    from sim.sky import pvlib_tmy3_path, read_tmy3

    m = sentence(
        doc("validation.md"),
        r"A station more than (\d+) km \(great circle\) from the site is refused unless forced: "
        r"Greensboro's year at Tehuantepec is ([\d,]+) km away",
    )
    limit, shown = numbers(" ".join(m.groups()))
    assert limit == MAX_STATION_DISTANCE_KM
    _, meta = read_tmy3(pvlib_tmy3_path())
    assert_printed([shown], [0], [station_distance_km(meta, tehuantepec)])


def _tracking_day(day: str, step_min: int) -> tuple[np.ndarray, np.ndarray]:
    """dynamics.md's day of joint targets: the sun-up targets every ``step_min`` (with the
    daily-sweep reference) plus the evening return to the morning pose."""
    from sim.control import noon_reference_azimuth
    from sim.kinematics import tracking_angles
    from sim.sites import load_site
    from sim.sun import solar_position

    site = load_site("tehuantepec")
    times = pd.date_range(f"{day} 00:00", periods=1440 // step_min, freq=f"{step_min}min",
                          tz=site.timezone)
    sun = solar_position(times, site.latitude, site.longitude, altitude=site.altitude)
    up = sun["apparent_elevation"].to_numpy() > 0
    az, el = tracking_angles(
        sun["azimuth"].to_numpy()[up], sun["apparent_elevation"].to_numpy()[up], site.tracker,
        reference_azimuth=noon_reference_azimuth(times[up], site),
    )
    return np.append(az, az[0]), np.append(el, el[0])


def test_dynamics_day_of_motion_energy_table() -> None:
    import dataclasses

    from sim.dynamics import TrackerInertia
    from sim.motors import AxisDrive, tracking_motion_energy

    text = doc("dynamics.md")
    keys = ["moves", "azimuth_travel_deg", "elevation_travel_deg", "azimuth_motion_wh",
            "elevation_motion_wh", "motion_wh"]
    rows = {("21 Mar", "every 1 min"): ("2025-03-21", 1, 0.0),
            ("21 Mar", "1 min, 0.5° dead band"): ("2025-03-21", 1, 0.5),
            ("21 Jun", "every 1 min"): ("2025-06-21", 1, 0.0),
            ("21 Dec", "every 1 min"): ("2025-12-21", 1, 0.0)}
    out = {}
    for lead, (day, step, band) in rows.items():
        out[lead] = tracking_motion_energy(*_tracking_day(day, step), dead_band_deg=band)
        shown = " ".join(table_row(text, *lead))
        assert_printed(numbers(shown), decimals(shown), [out[lead][k] for k in keys])
    by_interval = [tracking_motion_energy(*_tracking_day("2025-03-21", m)) for m in (5, 30, 60)]
    cells = table_row(text, "21 Mar", "every 5 / 30 / 60 min")
    for cell, key in zip(cells, keys, strict=True):
        if cell:  # the per-axis energies are left blank
            assert_printed(numbers(cell), decimals(cell), [o[key] for o in by_interval])

    base, banded = out[("21 Mar", "every 1 min")], out[("21 Mar", "1 min, 0.5° dead band")]
    m = sentence(text, r"\(5 vs 60 min\) cost little extra energy \(([\d.]+) vs ([\d.]+) Wh\)")
    assert numbers(" ".join(m.groups())) == numbers(cells[-1])[::2]
    m = sentence(text, r"a 0.5° dead band cuts the moves by (\d+) % and the energy by (\d+) %")
    assert_printed(numbers(" ".join(m.groups())), [0, 0],
                   [100 * (1 - banded[k] / base[k]) for k in ("moves", "motion_wh")])
    m = sentence(text, r"0.5 W × 24 h = (\d+) Wh/day, some (\d+)× the motion")
    standby, ratio = numbers(" ".join(m.groups()))
    assert standby == base["standby_wh"]
    assert ratio == pytest.approx(base["standby_wh"] / base["motion_wh"], rel=0.05)  # "some"

    p = TrackerInertia.seed002()
    heavy = dataclasses.replace(p, m2_kg=5 * p.m2_kg, cg2_m=3 * p.cg2_m)
    drives = {f"{axis}_drive": dataclasses.replace(getattr(AxisDrive, f"{axis}_default")(),
                                                    no_load_current_a=1.5)
              for axis in ("azimuth", "elevation")}
    day = _tracking_day("2025-03-21", 1)
    m = sentence(text, r"5× the mass m2 with 3× the offset cg2 gives ([\d.]+) Wh/day\), or "
                       r"lossier drives \(no-load current 1.5 A: ([\d.]+) Wh/day\)")
    assert_printed(numbers(" ".join(m.groups())), [2, 2],
                   [tracking_motion_energy(*day, p=heavy)["motion_wh"],
                    tracking_motion_energy(*day, **drives)["motion_wh"]])


# --- docs/control.md ----------------------------------------------------------------

REFERENCE_COLUMNS = ["pointing_error_rms_mrad", "pointing_error_p95_mrad",
                     "pointing_error_max_mrad", "azimuth_error_rms_mrad",
                     "elevation_error_rms_mrad", "moves"]
RMS = ["pointing_error_rms_mrad", "azimuth_error_rms_mrad", "elevation_error_rms_mrad"]
YAW = (("pedestal_yaw_deg", 2.0),)
YAW_TILT_EAST = (*YAW, ("pedestal_tilt_deg", 0.5), ("pedestal_tilt_azimuth_deg", 90.0))


@cache
def reference_day(controller: str, disturbances: tuple = ()) -> dict[str, Any]:
    """The summary of control.md's reference day (2024-03-15 at Tehuantepec, 60 s steps)."""
    from sim.disturbances import Disturbances
    from sim.sites import load_site
    from sim.twin import simulate

    site = load_site("tehuantepec")
    day = pd.Timestamp("2024-03-15", tz=site.timezone)
    return simulate(site, day, day + pd.Timedelta(days=1), controller=controller,
                    disturbances=Disturbances(**dict(disturbances))).summary()


def control_section(heading: str) -> str:
    """The text of one ``## heading…`` section of control.md."""
    return doc("control.md").split(f"## {heading}")[1].split("\n## ")[0]


@pytest.mark.parametrize(
    ("controller", "label"),
    [
        ("open_loop_spa", "`open_loop_spa`"),
        ("open_loop_duffie_beckman", "`open_loop_duffie_beckman`"),
        ("chronological", "`chronological` (30 min)"),
        ("hybrid", "`hybrid`"),
        # closed_loop_camera's row is filled by make bench (bench_control runs that day)
    ],
)
def test_control_reference_case_table(controller: str, label: str) -> None:
    s = reference_day(controller, YAW)
    shown = " ".join(table_row(control_section("The reference case"), label))
    computed = [float(s[k]) for k in REFERENCE_COLUMNS]
    computed += [1000 * s["spot_x_rms_m"], 1000 * s["spot_y_rms_m"]]
    assert_printed(numbers(shown), decimals(shown), computed)


def test_control_closed_loop_rows_come_from_the_bench() -> None:
    """The closed loop's reference day is bench_control's: its row and its reduction are
    fig markers of that bench, never hand-typed; the ideal row's bound is test_twin's."""
    text = control_section("The reference case")
    for lead in ("`closed_loop_camera`", "ours, `closed_loop_camera`, 2° yaw"):
        row = table_row(text, lead)
        assert all(re.fullmatch(r"(<!-- fig:control\.[\w.]+ -->[^<]*<!-- /fig -->[ /()→]*)+",
                                cell) for cell in row), row
    rms, _, peak = table_row(text, "`ideal`")[:3]
    assert rms == peak == "< 1e-6"
    test = ast.unparse(_function(ROOT / "tests/sim/test_twin.py",
                                 "test_ideal_summary_has_the_pointing_keys_and_zero_error"))
    assert "s['pointing_error_max_mrad'] < 1e-06" in test
    bench = (ROOT / "benchmarks" / "bench_control.py").read_text(encoding="utf-8")
    assert 'DAY = ("2024-03-15", "2024-03-16")' in bench and '"--pedestal-yaw-deg", "2"' in bench


def test_control_example_and_undisturbed_open_loops() -> None:
    m = sentence(doc("control.md"), r'r.summary\(\)\["pointing_error_rms_mrad"\] +# ([\d.]+)')
    assert_printed([float(m.group(1))], [1], [reference_day("hybrid", YAW)[RMS[0]]])
    m = sentence(control_section("The reference case"),
                 r"Without disturbances `open_loop_spa` is at ([\d.]+) mrad RMS [\s\S]*? "
                 r"`open_loop_duffie_beckman` at ([\d.]+) mrad")
    undisturbed = [reference_day(c)[RMS[0]] for c in ("open_loop_spa", "open_loop_duffie_beckman")]
    assert_printed(numbers(" ".join(m.groups())), [2, 2], undisturbed)


@pytest.mark.parametrize(
    ("label", "controller", "disturbances"),
    [
        ("ours, `hybrid`, 2° yaw", "hybrid", YAW),
        ("ours, `hybrid`, 2° yaw + 0.5° tilt towards east", "hybrid", YAW_TILT_EAST),
    ],
)
def test_control_reduction_table(label: str, controller: str, disturbances: tuple) -> None:
    ol, loop = reference_day("open_loop_spa", disturbances), reference_day(controller, disturbances)
    shown = " ".join(table_row(control_section("The reference case"), label))
    computed = [100 * (1 - loop[k] / ol[k]) for k in RMS] + [ol[RMS[2]], loop[RMS[2]]]
    assert_printed(numbers(shown), decimals(shown), computed)


def test_control_pointing_error_minutes_is_a_duration() -> None:
    """``pointing_error_minutes`` is how long the samples cover, not how many there are (the
    doc said "how many there were"; a tester's finding): the same at 10 s and 60 s steps."""
    from sim.sites import load_site
    from sim.twin import simulate

    m = sentence(control_section("Pointing error and losses"),
                 r"the reference day's ([\d,]+) minutes at 10 s steps and at 60 s steps alike, "
                 r"([\d,]+) at 3600 s steps")
    site = load_site("tehuantepec")
    day = pd.Timestamp("2024-03-15", tz=site.timezone)
    computed = [simulate(site, day, day + pd.Timedelta(days=1), step_s=step,
                         controller="open_loop_spa").summary()["pointing_error_minutes"]
                for step in (10, 60, 3600)]
    assert computed[0] == computed[1] == reference_day("open_loop_spa")["pointing_error_minutes"]
    assert numbers(" ".join(m.groups())) == [computed[1], computed[2]]


def test_control_day_motion_and_standby_energy() -> None:
    s = reference_day("open_loop_spa")
    m = sentence(control_section("Motion and energy"),
                 r"A clear day at Tehuantepec costs ([\d.]+) Wh of motion \(≈ ([\d,]+) moves "
                 r"with the 0.1° dead band\) and (\d+) Wh of standby")
    motion, moves, standby = numbers(" ".join(m.groups()))
    assert_printed([motion, standby], [3, 0],
                   [s["actuator_move_energy_wh"], s["actuator_standby_energy_wh"]])
    assert moves == pytest.approx(s["moves"], rel=0.05)  # "≈"


def test_control_cloud_gate_bounds_are_the_tests() -> None:
    m = sentence(
        doc("control.md"),
        r"the closed loop stays within ([\d.]+) mrad, as on a clear sky; "
        r"with the gate off it wanders more than (\d+) times as far",
    )
    bound, factor = numbers(" ".join(m.groups()))
    test = ast.unparse(_function(ROOT / "tests/sim/test_control.py",
                                 "test_clouds_do_not_make_the_closed_loop_wander"))
    assert f"err.max() < {bound}" in test
    assert f"> {factor:g} * err.max()" in test
    assert "cover=0.5" in test and "< 0.5 * s['camera_frames']" in test


# --- docs/service.md ----------------------------------------------------------------


def test_service_memory_bound_is_the_tests() -> None:
    m = sentence(doc("service.md"), r"the peak summed PSS \(shared pages counted once\) "
                                    r"stays within (\d+) GB")
    assert float(m.group(1)) * 1e9 == module_constant("tests/backend/test_limits.py",
                                                      "BUDGET_BYTES")


# --- docs/dashboard.md, README.md ---------------------------------------------------


def _bundle_mb(path: Path) -> tuple[float, float]:
    """A JavaScript bundle's size and its gzip size (level 6, as the service serves it) [MB]."""
    import gzip

    raw = path.read_bytes()
    return len(raw) / 1e6, len(gzip.compress(raw, 6, mtime=0)) / 1e6


def test_plotly_bundle_sizes() -> None:
    partial = _bundle_mb(ROOT / "frontend" / "vendor" / "plotly" / "plotly.min.js")
    m = sentence(doc("dashboard.md"), r"The partial bundle is\s+([\d.]+) MB \(([\d.]+) MB gzip\)")
    assert_printed(numbers(" ".join(m.groups())), [2, 2], list(partial))
    m = sentence((ROOT / "README.md").read_text(encoding="utf-8"),
                 r"The partial bundle is a quarter of the full one "
                 r"\(([\d.]+) MB, ([\d.]+) MB\s+gzip")
    assert_printed(numbers(" ".join(m.groups())), [1, 1], list(partial))
    plotly = pytest.importorskip("plotly")
    full = _bundle_mb(Path(plotly.__file__).parent / "package_data" / "plotly.min.js")
    m = sentence(doc("dashboard.md"), r"the full bundle \(([\d.]+) MB, ([\d.]+) MB gzip")
    assert_printed(numbers(" ".join(m.groups())), [1, 2], list(full))
    assert round(full[0] / partial[0]) == 4  # "a quarter"


# --- docs/twin3d.md, docs/sites.md --------------------------------------------------


def _placed(site: Any, fixed_east_m: float, drawn: bool = False) -> Any:
    """``site`` with the tracker at the origin and the fixed array ``fixed_east_m`` east;
    ``drawn``: with the 3D scene's 2 × 2 outlines, as the scene assumes them."""
    import dataclasses

    from backend.twin.scene_build import ARRAY_HEIGHT_M, ARRAY_WIDTH_M
    from sim.array_shade import Placement

    size = {"width_m": ARRAY_WIDTH_M, "height_m": ARRAY_HEIGHT_M} if drawn else {}
    return dataclasses.replace(site, placements={"tracker": Placement(0.0, 0.0, **size),
                                                 "fixed": Placement(fixed_east_m, 0.0, **size)})


def test_twin3d_shadow_on_the_fixed_array(tehuantepec) -> None:
    from backend.twin.scene_build import FIXED_ARRAY_ORIGIN_M
    from sim.twin import simulate

    assert FIXED_ARRAY_ORIGIN_M[1:] == (0.0, 0.0)
    tz = tehuantepec.timezone
    start = pd.Timestamp("2024-03-15 12:00", tz=tz)
    shade = simulate(_placed(tehuantepec, FIXED_ARRAY_ORIGIN_M[0], drawn=True), start,
                     start + pd.Timedelta(hours=7)).series["fixed_shaded_fraction"]
    shade.index = shade.index.tz_convert(tz)
    text = doc("twin3d.md")
    m = sentence(text, r"the shade starts at (\d+):(\d+) local time on 15 March and covers the "
                       r"whole array from about (\d+):(\d+) \((\d+) % at 16:00, (\d+) % at "
                       r"16:45, (\d+) % at 17:15")
    h0, m0, h1, m1, *pct = numbers(" ".join(m.groups()))
    first, full = shade[shade > 0].index[0], shade[shade > 0.999].index[0]
    assert (first.hour, first.minute) == (h0, m0)
    assert abs((full.hour * 60 + full.minute) - (h1 * 60 + m1)) <= 5  # "about"
    at = [shade[pd.Timestamp(f"2024-03-15 {t}", tz=tz)] for t in ("16:00", "16:45", "17:15")]
    assert_printed(pct, [0, 0, 0], [100 * f for f in at])
    # the screenshot's caption, in this doc and the README
    for caption in (text, (ROOT / "README.md").read_text(encoding="utf-8")):
        m = sentence(caption, r"!\[The [^\]]*?(\d+) % of the fixed array")
        assert_printed(numbers(m.group(1)), [0], [100 * at[1]])


@pytest.mark.slow
def test_sites_shade_loss_of_a_year(tehuantepec) -> None:
    from sim.twin import simulate

    tz = tehuantepec.timezone
    m = sentence(doc("sites.md"), r"a clear-sky 2023\s+at 1 min loses ([\d.]+) kWh of the fixed "
                 r"array's ([\d,]+) kWh \(([\d.]+) %\) with the array\s+([\d.]+) m east, "
                 r"(\d+) kWh \(([\d.]+) %\) at ([\d.]+) m east")
    loss1, total, pct1, east1, loss2, pct2, east2 = numbers(" ".join(m.groups()))
    computed = []
    for east in (east1, east2):
        s = simulate(_placed(tehuantepec, east), pd.Timestamp("2023-01-01", tz=tz),
                     pd.Timestamp("2024-01-01", tz=tz)).summary()
        unshaded = s["fixed_energy_wh"] + s["fixed_shade_loss_wh"]
        computed.append((s["fixed_shade_loss_wh"] / 1000, unshaded / 1000,
                         100 * s["fixed_shade_loss_wh"] / unshaded))
    assert_printed([loss1, total, pct1, loss2, pct2], [1, 0, 1, 0, 1],
                   [*computed[0], computed[1][0], computed[1][2]])


# --- docs/plants.md -----------------------------------------------------------------


@pytest.mark.parametrize(("label", "day", "tst_h"), [
    ("21 Dec 08:24", "2021-12-21", 8.4), ("21 Dec 15:24", "2021-12-21", 15.4),
    ("21 Jun 07:30", "2021-06-21", 7.5), ("21 Jun 15:48", "2021-06-21", 15.8),
])
def test_plants_seed_004_instants_table(label: str, day: str, tst_h: float) -> None:
    import sys

    sys.path.insert(0, str(ROOT / "tests" / "sim" / "plant"))
    from plant_reference import utc_from_true_solar_time

    from sim.plant.layout import load_plant
    from sim.plant.shading import plant_shade
    from sim.sun import solar_position

    plant = load_plant("penarroya")
    t = utc_from_true_solar_time(day, tst_h, plant.longitude)
    sun = solar_position(t, plant.latitude, plant.longitude, plant.altitude)
    az, el = float(sun["azimuth"].iloc[0]), float(sun["apparent_elevation"].iloc[0])
    shade = plant_shade(plant.positions, [az], [el], [az], [el], plant.collector.width,
                        plant.collector.height)
    sky, count, mean = table_row(doc("plants.md"), label)
    assert_printed(numbers(sky), [1, 1], [az, el])
    shaded = shade.shaded[0]
    assert numbers(count)[0] == int(shaded.sum())
    if "all but" in count:  # "23 (all but 1–6)": the unshaded trackers, runs written a–b
        spans = [numbers(s) for s in count.split("all but")[1].rstrip(")").split(",")]
        unshaded = {i for s in spans for i in range(int(s[0]), int(abs(s[-1])) + 1)}
        ids = plant.tracker_ids
        assert unshaded == {ids[k] for k in np.flatnonzero(~shaded)}
    assert_printed(numbers(mean), decimals(mean), [float(shade.fraction[0].mean())])


def test_plants_backtracking_winner_at_dec_21_15_24() -> None:
    import sys

    from pvlib.irradiance import get_total_irradiance

    sys.path.insert(0, str(ROOT / "tests" / "sim" / "plant"))
    from plant_reference import utc_from_true_solar_time

    from sim.plant.layout import load_plant
    from sim.plant.simulate import sky_conditions
    from sim.plant.strategies import lowest_free_elevation, orientations

    plant = load_plant("penarroya")
    sky = sky_conditions(plant, pd.DatetimeIndex(
        [utc_from_true_solar_time("2021-12-21", 15.4, plant.longitude)]))

    def poa(az: float, el: float) -> float:
        return float(get_total_irradiance(
            90 - el, az % 360, sky["apparent_zenith"][0], sky["solar_azimuth"][0],
            sky["dni"][0], sky["ghi"][0], sky["dhi"][0], dni_extra=sky["dni_extra"][0],
            airmass=sky["airmass_relative"][0], albedo=plant.albedo, model="perez",
        )["poa_global"])

    az_sun, el_sun = float(sky["solar_azimuth"][0]), float(sky["apparent_elevation"][0])
    az, el = (float(v[0]) for v in orientations("backtrack", plant, sky))
    raised = float(lowest_free_elevation(plant, [az_sun], [el_sun], np.array([[az_sun]]),
                                         [el_sun])[0][0])
    m = sentence(doc("plants.md"), r"On 21 Dec at 15:24 the winner turns the collectors ([\d.]+)° "
                 r"off the sun's azimuth \(shadows fall between neighbours\) at ([\d.]+)° "
                 r"elevation — (\d+) % more POA than raising the collectors at the sun's azimuth "
                 r"until the shade clears \((\d+) W m⁻²\)")
    assert_printed(numbers(" ".join(m.groups())), [1, 1, 0, 0],
                   [abs((az - az_sun + 180) % 360 - 180), el,
                    100 * (poa(az, el) / poa(az_sun, raised) - 1), poa(az_sun, raised)])


def test_control_move_costing_step() -> None:
    from sim.tracking import DriveLimits, Move, move_energies_wh

    text = control_section("Motion and energy")
    m = sentence(text, r"at (\d+) ms samples of the moving time only \(within\s+([\d.]+) % of "
                       r"(\d+) ms samples; equal to `motors.tracking_motion_energy` to ([\de.-]+) "
                       r"in the tests\)")
    coarse_ms, within_pct, fine_ms, equal = numbers(" ".join(m.groups()))
    rng = np.random.default_rng(0)
    # the dead band's moves: 0.1°–1° on either axis, either way
    moves = [Move(k % 2, float(k), float(rng.uniform(0.1, 1.0) * rng.choice([-1, 1])),
                  40.0 if k % 2 else 120.0, 40.0, 0.0) for k in range(40)]
    coarse = move_energies_wh(moves, DriveLimits(), dt_s=coarse_ms / 1000)[1]
    fine = move_energies_wh(moves, DriveLimits(), dt_s=fine_ms / 1000)[1]
    assert abs(coarse / fine - 1) < within_pct / 100
    assert ("rel", equal) in approx_tolerances(
        "tests/sim/test_control.py", "test_move_energies_match_motors_tracking_motion_energy")
    m = sentence(text, r"reports ≈ ([\d.]+) Wh/day for a small\s+tracker's motion: our motion "
                       r"energy is ~(\d+)× lower")
    reference, lower = numbers(" ".join(m.groups()))
    assert lower == pytest.approx(reference / reference_day("open_loop_spa")[
        "actuator_move_energy_wh"], rel=0.1)  # "~"


def test_control_why_ours_differ() -> None:
    text = control_section("The reference case")
    ol, hybrid = reference_day("open_loop_spa", YAW), reference_day("hybrid", YAW)
    tilted = [reference_day(c, YAW_TILT_EAST) for c in ("open_loop_spa", "hybrid")]
    m = sentence(text, r"our open loop's elevation error is just its update lag "
                       r"\(([\d.]+) mrad RMS\)")
    assert_printed(numbers(m.group(1)), [2], [ol[RMS[2]]])
    m = sentence(text, r"the elevation error appears and is removed \((\d+) %, beside")
    assert_printed(numbers(m.group(1)), [0], [100 * (1 - tilted[1][RMS[2]] / tilted[0][RMS[2]])])
    m = sentence(text, r"= (\d+) mrad RMS,\s+not 87–100 mrad: with a similar residual floor the "
                       r"percentage is lower \((\d+) % vs 96 %\)")
    assert_printed(numbers(" ".join(m.groups())), [0, 0],
                   [ol[RMS[1]], 100 * (1 - hybrid[RMS[1]] / ol[RMS[1]])])
    m = sentence(text, r"\(the hybrid's max over the day: ([\d.]+) mrad\)")
    assert_printed(numbers(m.group(1)), [1], [hybrid["pointing_error_max_mrad"]])
    from sim.control import ControlSettings

    m = sentence(text, r"Ours is the ([\d.]+)° \(([\d.]+) mrad\) dead band")
    band, band_mrad = numbers(" ".join(m.groups()))
    assert band == ControlSettings().dead_band_deg
    assert_printed([band_mrad], [2], [float(np.radians(band)) * 1000])


def test_dynamics_table_1_readings() -> None:
    from sim.dynamics import TrackerInertia

    p = TrackerInertia.seed002()
    text = doc("dynamics.md")
    m = sentence(text, r"I21 ≈ I22 \+ I23 \(([\d.]+) vs ([\d.]+) kg m²\)")
    assert_printed(numbers(" ".join(m.groups())), [2, 2],
                   [p.i21_kg_m2, p.i22_kg_m2 + p.i23_kg_m2])
    m = sentence(text, r"balanced to (\d+) mm \(G2 ≤ ([\d.]+) N m\)")
    assert_printed(numbers(" ".join(m.groups())), [0, 1],
                   [1000 * abs(p.cg2_m), p.m2_kg * p.g_m_s2 * abs(p.cg2_m)])
    m = sentence(text, r"make the engines differ by > (\d+) mrad in ([\d.]+) s \(tested")
    mrad, seconds = numbers(" ".join(m.groups()))
    test = (ROOT / "tests" / "sim" / "test_dynamics_check.py").read_text(encoding="utf-8")
    assert f"> {mrad:g}e-3" in test and f"for {seconds:g} s" in test


# --- docs/diagnosis.md --------------------------------------------------------------


def test_diagnosis_held_out_bounds_are_the_tests() -> None:
    text = doc("diagnosis.md")
    m = sentence(text, r"the fixed array's own twin under its reconstructed sky\s+within (\d+) % "
                       r"of its readings on every day \(checked by `tests/sim/test_sky_sensor.py"
                       r"::test_inversion_reproduces_the_fixed_array_it_came_from`, seeds "
                       r"(\d+)–(\d+);")
    pct, first, last = numbers(" ".join(m.groups()))
    sky = (ROOT / "tests" / "sim" / "test_sky_sensor.py").read_text(encoding="utf-8")
    assert f"abs(ratio - 1) < {pct / 100:g}" in sky
    assert f"params={list(range(int(first), int(last) + 1))}" in sky
    m = sentence(text, r"soiling of ([\d.]+) %/day found within ±([\d.]+) %/day of\s+output and "
                       r"its start within ±(\d+) days \(checked by `tests/backend/"
                       r"test_diagnosis_faults.py::test_soiling_found_as_a_slow_decline`, "
                       r"seed (\d+)\)")
    rate, tol, days, seed = numbers(" ".join(m.groups()))
    faults = ast.unparse(_function(ROOT / "tests/backend/test_diagnosis_faults.py",
                                   "test_soiling_found_as_a_slow_decline"))
    assert f"abs(soil[0]['magnitude'] - {rate:g}) <= {tol:g}" in faults
    assert f"abs(since - start) <= {days:g}" in faults and f", {seed:g}, " in faults
    m = sentence(text, r"A day without readings after a measured one agrees\s+with `/energy` to "
                       r"([\d.]+) % in energy and ([\d.]+) point in gain")
    energy_pct, gain_points = numbers(" ".join(m.groups()))
    tolerances = approx_tolerances("tests/backend/test_diagnosis_api.py",
                                   "test_a_day_without_readings_expects_the_clear_sky_twin")
    assert sorted(tolerances) == [("abs", gain_points), ("rel", energy_pct / 100)]


# --- settings and constants the docs quote --------------------------------------------


def _control(name: str) -> Any:
    from sim.control import ControlSettings, make_controller
    from sim.sites import load_site

    return make_controller(name, load_site("tehuantepec"), ControlSettings(), 0.0)


def _tracker_camera() -> list[float]:
    from sim.tracking import CameraSetup

    c = CameraSetup().camera
    return [c.width_px, c.height_px, c.fov_deg]


def _default(function: Any, name: str) -> Any:
    import inspect

    return inspect.signature(function).parameters[name].default


def _settings() -> Any:
    from sim.control import ControlSettings

    return ControlSettings()


def _drives() -> tuple[Any, Any]:
    from sim.motors import AxisDrive

    return AxisDrive.azimuth_default(), AxisDrive.elevation_default()


def _both_drives(field: str) -> list[float]:
    """A drive setting the doc gives once for both axes (asserted equal on both)."""
    az, el = (getattr(d, field) for d in _drives())
    assert az == el, field
    return [az]


def _limits_rad() -> list[float]:
    from sim.tracking import DriveLimits

    d = DriveLimits()
    rates = [d.azimuth_rate_deg_s, d.elevation_rate_deg_s]
    accels = [d.azimuth_accel_deg_s2, d.elevation_accel_deg_s2]
    assert rates[0] == rates[1] and accels[0] == accels[1]  # "on both axes"
    return [float(np.radians(rates[0])), float(np.radians(accels[0]))]


def _code(module: str, name: str) -> Any:
    """``module.name`` of our packages."""
    import importlib

    return getattr(importlib.import_module(module), name)


def _site() -> Any:
    from sim.sites import load_site

    return load_site("tehuantepec")


def _module_size_m() -> list[float]:
    from sim.pv import cec_module_parameters

    cec = cec_module_parameters(_site().arrays["fixed"].module)
    return [round(float(cec["Length"]), 2), round(float(cec["Width"]), 2)]


def _cec_share_without_size() -> float:
    """The share of pvlib's CEC modules without a Length or a Width."""
    import pvlib

    from sim.pv import CEC_TABLE_FILE

    # the file retrieve_sam("CECMod") reads; its rows 2 and 3 are units and SAM names
    table = Path(pvlib.__file__).parent / "data" / CEC_TABLE_FILE
    size = pd.read_csv(table, usecols=["Length", "Width"], skiprows=[1, 2])
    return float(size.isna().any(axis=1).mean())


def _default_field(name: str) -> Any:
    from sim.site_config import SiteConfig

    return SiteConfig.model_fields[name].default


def _source_numbers(path: str, pattern: str) -> list[float]:
    """The numbers of ``pattern``'s groups, found once in a repository file (JS, CSS, JSON)."""
    found = list(re.finditer(pattern, (ROOT / path).read_text(encoding="utf-8")))
    assert len(found) == 1, (path, pattern, len(found))
    return [float(g) for g in found[0].groups()]


def _source_number(path: str, pattern: str) -> float:
    return _source_numbers(path, pattern)[0]


def _installed_version(distribution: str) -> list[float]:
    """The installed version of a distribution, as numbers."""
    from importlib.metadata import version

    return [float(v) for v in version(distribution).split(".") if v.isdigit()]


def _twin_default(name: str) -> Any:
    return _default(_code("sim.twin", "simulate"), name)


# (doc, the sentence with the quoted values as groups, what the code has)
QUOTED_CONSTANTS = [
    ("control.md", r"\*\*dead band\*\* `dead_band_deg` = ([\d.]+)°",
     lambda: [_settings().dead_band_deg]),
    ("control.md", r"a PID \(kp ([\d.]+), ki ([\d.]+) s⁻¹\)",
     lambda: [_settings().kp, _settings().ki_per_s]),
    ("control.md", r"narrow camera \((\d+)×(\d+), (\d+)°\) at (\d+) frame/s",
     lambda: [*_tracker_camera(), 1 / _control("closed_loop_camera").camera_interval_s]),
    ("control.md", r"a frame every (\d+) s \(`camera_interval_s`\), low-pass `hybrid_gain` "
                   r"([\d.]+)", lambda: [_control("hybrid").camera_interval_s,
                                         _settings().hybrid_gain]),
    ("control.md", r"`stow_elevation_deg` \(([\d.]+)°\) now and `wake_lead_s` \((\d+) s\)",
     lambda: [_settings().stow_elevation_deg, _settings().wake_lead_s]),
    ("control.md", r"\(`min_peak_dn` (\d+) —", lambda: [_settings().min_peak_dn]),
    ("control.md", r"within `area_tolerance` \(([\d.]+)×\)", lambda: [_settings().area_tolerance]),
    ("control.md", r"`max_jump_deg` \((\d+)°\) from .* `reacquire_frames` \((\d+)\) frames",
     lambda: [_settings().max_jump_deg, _settings().reacquire_frames]),
    ("control.md", r"`DriveLimits`: ([\d.]+) rad s⁻¹, ([\d.]+) rad s⁻² on both axes",
     _limits_rad),
    ("control.md", r"`AxisDrive.standby_power_w`, ([\d.]+) W per drive",
     lambda: _both_drives("standby_power_w")),
    ("control.md", r"within `acceptance_angle_deg` of its axis \(default ([\d.]+)°\)",
     lambda: [_twin_default("acceptance_angle_deg")]),
    ("control.md", r"`spot_distance_m · tan θ` \(default ([\d.]+) m",
     lambda: [_twin_default("spot_distance_m")]),
    ("control.md", r"above `POINTING_MIN_ELEVATION_DEG` \((\d+)°:",
     lambda: [_code("sim.twin", "POINTING_MIN_ELEVATION_DEG")]),
    ("control.md", r"\| `chronological` \((\d+) min\) \|",
     lambda: [_settings().chronological_interval_min]),
    ("dynamics.md", r"k_t = ([\d.]+) N m/A, R = ([\d.]+) Ω, i₀ = ([\d.]+) A,\s+worm 1:([\d,]+) "
                    r"\(elevation\) / 1:([\d,]+) \(azimuth\) at η = ([\d.]+) [\s\S]*? "
                    r"([\d.]+) N m and ([\d.]+) rad/s output limits, driver η = ([\d.]+),\s+"
                    r"standby ([\d.]+) W",
     lambda: [*_both_drives("torque_constant_nm_a"), *_both_drives("winding_resistance_ohm"),
              *_both_drives("no_load_current_a"), _drives()[1].gear_ratio,
              _drives()[0].gear_ratio, *_both_drives("gear_efficiency"),
              *_both_drives("max_output_torque_nm"), *_both_drives("max_output_speed_rad_s"),
              *_both_drives("driver_efficiency"), *_both_drives("standby_power_w")]),
    ("dynamics.md", r"seed 000's\s+(\d+) V bus", lambda: _both_drives("supply_voltage_v")),
    ("dynamics.md", r"seed 002's Kp = (\d+),\s+Kd = (\d+)",
     lambda: [_code("sim.dynamics_check", "KP_SEED002"),
              _code("sim.dynamics_check", "KD_SEED002")]),
    ("validation-vision.md", r"looks within (\d+)° of\s+the prediction",
     lambda: [_code("vision.detect", "_SEARCH_DEG")]),
    ("validation-vision.md", r"grows the window × ([\d.]+) while",
     lambda: [_code("vision.detect", "_SEARCH_GROW")]),
    ("validation-vision.md", r"within ([\d.]+) px of the image\s+circle's edge are never limb; "
                             r"a core with ≥ (\d+) % of its outline",
     lambda: [_code("vision.detect", "_FOV_EDGE_PX"), 100 * _code("vision.detect", "_CUT_SHARE")]),
    ("validation-vision.md", r"refitted with (\d+) triples",
     lambda: [_code("vision.detect", "_CUT_TRIALS")]),
    ("validation-vision.md", r"≥ (\d+) % of it\s+lies on the contained circle",
     lambda: [100 * _code("vision.detect", "_CONTAINED_MIN_INLIERS")]),
    ("validation-vision.md", r"tolerance max\(([\d.]+) px, (\d+) % of the radius\)",
     lambda: [_default(_code("vision.limb", "contained_limb_centre"), "tol_px"),
              100 * _code("vision.limb", "_CONTAINED_REL_TOL")]),
    ("validation-vision.md", r"\(zenith angle off by more\s+than (\d+)°",
     lambda: [_code("backend.vision.checks", "ZENITH_ANGLE_LIMIT_DEG")]),
    ("validation-vision.md", r"random camera: (\d+)–(\d+) px, (\d+)–(\d+) px/°",
     lambda: [*(lambda sizes: (min(sizes), max(sizes)))(_source_numbers(
         "vision/skyrender.py", r"short = int\(rng.choice\(\[(\d+), (\d+), (\d+), (\d+), "
                                r"(\d+), (\d+), (\d+), (\d+)\]\)\)")),
              *_source_numbers("vision/skyrender.py",
                               r"px_per_deg = float\(np.clip\(.*, ([\d.]+), ([\d.]+)\)\)")]),
    ("validation-vision.md", r"\| synthetic fisheye (\d+)×(\d+), ([\d.]+) px/°, trees",
     lambda: (lambda cx, cy, scale: [2 * cx + 1, 2 * cy + 1, scale])(*_source_numbers(
         "vision/evalset.py", r"cam = FisheyeCamera\(([\d.]+), ([\d.]+), ([\d.]+)\)"))),
    ("validation-vision.md", r"\| first renderer, (\d+) % thin cloud \|",
     lambda: [100 * _source_number("vision/evalset.py", r"cloud_cover=([\d.]+), cloud_optical_"
                                                         r"depth=[\d.]+\)\n +src = \"synth/thin")]),
    ("validation-vision.md", r"when less than\s+(\d+) % of its limb fits one circle",
     lambda: [100 * _source_number("vision/detect.py",
                                   r"fallback is not None and inliers < ([\d.]+)")]),
    ("validation-vision.md", r"decode excluded, best of (\d+) passes",
     lambda: [_source_number("benchmarks/bench_vision.py", r"passes: int = (\d+),")]),
    ("twin3d.md", r"viser (\d+)\.(\d+) has no public accessor",
     lambda: _installed_version("viser")[:2]),
    ("validation-vision.md", r"`ephemeris_far_unclear` = min\(distance, (\d+)°\)/(\d+)° ×",
     lambda: _source_numbers("vision/confidence.py",
                             r"min\(float\(ephemeris_deg\), ([\d.]+)\) / ([\d.]+) \*")),
    ("validation-vision.md", r"scenes, the prediction (\d+)–(\d+)° off\)",
     lambda: [_default(_code("vision.evalset", "far_direction"), k) for k in ("lo_deg", "hi_deg")]),
    ("validation-vision.md", r"frames with the clock (\d+) h off",
     lambda: [_source_number("benchmarks/bench_vision.py", r"\nWRONG_CLOCK_H = ([\d.]+)\n")]),
    ("validation-vision.md", r"suns under cloud passing ≤ (\d+) % of their light",
     lambda: [100 * v for v in {float(x) for x in re.findall(
         r'truth\["transmittance"\] > ([\d.]+)', (ROOT / "vision/evalset.py").read_text())}]),
    ("twin3d.md", r"a point ([\d.]+) m east of\s+the tracker \(`FIXED_ARRAY_ORIGIN_M`",
     lambda: [_code("backend.twin.scene_build", "FIXED_ARRAY_ORIGIN_M")[0]]),
    ("twin3d.md", r"a disc ([\d.]+) m from the elevation axis",
     lambda: [_code("backend.twin.scene_build", "SUN_DISTANCE_M")]),
    ("twin3d.md", r"lifts them all by (\d+) m \(`PIVOT_HEIGHT_M`",
     lambda: [_code("backend.twin.scene_plant", "PIVOT_HEIGHT_M")]),
    ("twin3d.md", r"`GHOST_THRESHOLD_MRAD` \((\d+) mrad, ([\d.]+)°\)",
     lambda: [_code("backend.twin.scene_pose", "GHOST_THRESHOLD_MRAD"),
              round(float(np.degrees(_code("backend.twin.scene_pose",
                                             "GHOST_THRESHOLD_MRAD") / 1000)), 1)]),
    ("twin3d.md", r"d1 = (\d+) mm, a2 = (\d+) mm",
     lambda: [1000 * _code("sim.kinematics", "TrackerGeometry")().d1_m,
              1000 * _code("sim.kinematics", "TrackerGeometry")().a2_m]),
    ("architecture.md", r"`d1_m=([\d.]+)`, `a2_m=([\d.]+)`",
     lambda: [_code("sim.kinematics", "TrackerGeometry")().d1_m,
              _code("sim.kinematics", "TrackerGeometry")().a2_m]),
    ("dynamics.md", r"frame \{2\}'s origin, (\d+) mm further out",
     lambda: [1000 * _code("sim.kinematics", "TrackerGeometry")().a2_m]),
    ("dynamics.md", r"A day of 2025 at Tehuantepec \(([\d.]+)° N",
     lambda: [round(_site().latitude, 2)]),
    ("twin3d.md", r"the compass letters on the\s+ground mark N/E/S/W at (\d+) m",
     lambda: [_source_number("backend/twin/scene_build.py", r'"N": \(0\.0, ([\d.]+)\)')]),
    ("twin3d.md", r"a pedestal \(([\d.]+) m, assumed",
     lambda: [_code("sim.site_config", "TRACKER_MOUNT_HEIGHT_M")]),
    ("twin3d.md", r"lower edge ([\d.]+) m\s+up, a ([\d.]+) m pedestal",
     lambda: [_code("sim.site_config", "FIXED_MOUNT_HEIGHT_M"),
              _code("sim.site_config", "TRACKER_MOUNT_HEIGHT_M")]),
    ("twin3d.md", r"modules,\s+([\d.]+) m × ([\d.]+) m each \(pvlib CEC table\)",
     lambda: _module_size_m()),
    ("twin3d.md", r"\(Tehuantepec: (\d+)° facing south",
     lambda: [_site().arrays["fixed"].surface_tilt]),
    ("twin3d.md", r"\(`/sun_path`,\s+(\d+)-minute steps", lambda: [_code("backend.twin.scene_build",
                                                                         "SUN_PATH_STEP_MIN")]),
    ("twin3d.md", r"none below ([\d.]+)° of sun elevation",
     lambda: [float(np.degrees(np.arcsin(_code("backend.twin.scene_shadow", "MIN_SUN_Z"))))]),
    ("twin3d.md", r"Peñarroya I's (\d+) collectors of (\d+) m × (\d+) m",
     lambda: (lambda p: [p.n_trackers, p.collector.width, p.collector.height])(
         _code("sim.plant.layout", "load_plant")("penarroya"))),
    ("twin3d.md", r"seed 000's camera \((\d+) × (\d+) px, (\d+)° taken as the horizontal",
     lambda: [_code("backend.twin.scene_build", k)
              for k in ("CAMERA_WIDTH_PX", "CAMERA_HEIGHT_PX", "CAMERA_FOV_DEG")]),
    ("dashboard.md", r"refreshed every (\d+) s while the overview",
     lambda: [_source_number("frontend/js/alerts.js", r"const POLL_MS = (\d+);") / 1000]),
    ("dashboard.md", r"the gaps \(> (\d+) min\) in the day",
     lambda: [_source_number("frontend/js/overview.js",
                             r"const gapMs = Math.max\(3 \* step, (\d+) \* 60000\);")]),
    ("dashboard.md", r"calibrate a fisheye \(≤ (\d+) px RMS\)",
     lambda: [_source_number("tests/e2e/test_dashboard.py", r"assert float\(rms\) < ([\d.]+),")]),
    ("dashboard.md", r"alerts evaluated every ([\d.]+) s",
     lambda: [_source_number("tests/e2e/test_alerts_page.py",
                             r'"HELIOTWIN_ALERT_INTERVAL_S": "([\d.]+)"')]),
    ("architecture.md", r"a body over (\d+) kB on",
     lambda: [_code("backend.measurements.ingest", "THREAD_FROM_BYTES") / 1024]),
    ("sites.md", r"in parallel per array, (\d+) °C and (\d+) m s⁻¹ for\s+clear-sky runs",
     lambda: [_default_field("temp_air_c"), _default_field("wind_speed_m_s")]),
    ("dashboard.md", r"refreshes itself every (\d+) s while it is open",
     lambda: [_source_number("frontend/js/overview.js", r"const LIVE_MS = (\d+);") / 1000]),
    ("dashboard.md", r"responsive below (\d+) px",
     lambda: [max(float(w) for w in re.findall(  # the widest breakpoint: the layout's
         r"@media \(max-width: (\d+)px\)", (ROOT / "frontend/css/app.css").read_text()))]),
    ("dashboard.md", r"\*\*Plotly.js\*\* (\d+)\.(\d+)\.(\d+) \(npm",
     lambda: _source_numbers("frontend/vendor/plotly/package.json",
                             r'"plotly.js": "(\d+)\.(\d+)\.(\d+)"')),
    ("sites.md", r"\(KD205GX-LP ([\d.]+) m × ([\d.]+) m\), ([\d.]+) m gaps — (\d+) modules make "
                 r"([\d.]+) m × ([\d.]+) m\. About (\d+) % of the table's modules have no size",
     lambda: [*_module_size_m(), _code("sim.array_shade", "MODULE_GAP_M"),
              _site().arrays["fixed"].strings_in_parallel,
              *[round(v, 2) for v in _code("sim.array_shade", "collector_size_m")(
                  _site().arrays["fixed"])], round(100 * _cec_share_without_size())]),
    ("sites.md", r"default ([\d.]+) m; a fixed array: its lower edge above the ground, default "
                 r"([\d.]+) m", lambda: [_code("sim.site_config", "TRACKER_MOUNT_HEIGHT_M"),
                                         _code("sim.site_config", "FIXED_MOUNT_HEIGHT_M")]),
]


@pytest.mark.parametrize(("name", "pattern", "code"), QUOTED_CONSTANTS,
                         ids=[f"{d}-{k}" for k, (d, _, _) in enumerate(QUOTED_CONSTANTS)])
def test_quoted_settings_are_the_code(name: str, pattern: str, code: Any) -> None:
    m = sentence(doc(name), pattern)
    assert numbers(" ".join(m.groups())) == pytest.approx([float(v) for v in code()])


def test_vision_confidence_paragraph_is_the_fitted_model() -> None:
    import json

    model = json.loads((ROOT / "vision" / "confidence.json").read_text(encoding="utf-8"))
    losses = {float(k): v for k, v in model["cv_log_loss"].items()}
    assert model["l2"] == min(losses, key=losses.get)  # the penalty chosen by the CV
    for said in ("development split only", "5-fold", "cross-validation grouped by frame"):
        assert said in model["fitted_by"]
    said = "fitted with `bench_vision.py --fit-confidence` on the **development** split"
    assert said in " ".join(doc("validation-vision.md").split())


def test_control_inertia_torque_of_a_move() -> None:
    from sim.dynamics import TrackerInertia, mass_matrix

    m = sentence(control_section("Motion and energy"),
                 r"the inertia torque M11 q̈ is\s+([\d.]+)–([\d.]+) N m at `DriveLimits`' "
                 r"acceleration")
    m11 = [float(mass_matrix(np.radians(e), TrackerInertia.seed002())[0, 0])
           for e in np.linspace(0.0, 90.0, 91)]
    accel = _limits_rad()[1]
    assert_printed(numbers(" ".join(m.groups())), [1, 1], [min(m11) * accel, max(m11) * accel])


def test_dynamics_centrifugal_lift_of_the_seed_move() -> None:
    from sim.dynamics import TrackerInertia, coriolis_centrifugal
    from sim.dynamics_check import KP_SEED002, REFERENCE_RATE_RAD_S

    m = sentence(doc("dynamics.md"), r"V2 at ([\d.]+) rad/s,\s+held against Kp, moves the panel "
                                     r"by ([\d.]+) mrad at ([\d.]+)°")
    rate, lift, el = numbers(" ".join(m.groups()))
    assert rate == REFERENCE_RATE_RAD_S
    v2 = coriolis_centrifugal(np.radians(el), rate, 0.0, TrackerInertia.seed002())[1]
    assert_printed([lift], [2], [1000 * abs(float(v2)) / KP_SEED002])


def test_dynamics_day_against_reference_34() -> None:
    """The reading of the day table against seed 000's [34]: the range of the motion Wh of
    the 1-min days and how many times less than [34]'s 1.5 Wh that is."""
    text = doc("dynamics.md")
    days = [numbers(table_row(text, d, "every 1 min")[-1])[0]
            for d in ("21 Mar", "21 Jun", "21 Dec")]
    m = sentence(text, r"\(≈ ([\d.]+) Wh/day for a small tracker's\s+motion, [\d.]+ % of its "
                       r"gain\):\*\* our motion energy is ≈ ([\d.]+)–([\d.]+) Wh/day, (\d+)–(\d+)×")
    ref, low, high, less_low, less_high = numbers(" ".join(m.groups()))
    assert (low, high) == (round(min(days), 2), round(max(days), 2))
    assert less_low <= ref / max(days) and ref / min(days) <= less_high
    m = sentence(text, r"\(≈ (\d+)–(\d+)° of azimuth, (\d+)–(\d+)° of\s+elevation\)")
    az = [numbers(table_row(text, d, "every 1 min")[1])[0] for d in ("21 Mar", "21 Jun", "21 Dec")]
    el = [numbers(table_row(text, d, "every 1 min")[2])[0] for d in ("21 Mar", "21 Jun", "21 Dec")]
    lo_az, hi_az, lo_el, hi_el = numbers(" ".join(m.groups()))
    assert lo_az <= min(az) and max(az) <= hi_az + 5 and lo_el <= min(el) and max(el) <= hi_el


def test_validation_spa_reference_case_and_site_file() -> None:
    import sys

    sys.path.insert(0, str(ROOT / "tests" / "sim"))
    from test_sun import SPA_CASE, SPA_TIME

    from sim.sun import solar_position

    text = doc("validation.md")
    m = sentence(text, r"topocentric zenith ([\d.]+)°, azimuth ([\d.]+)° \| ([\d.]+)°, ([\d.]+)° "
                       r"\(`heliotwin sun")
    published_zenith, published_azimuth, zenith, azimuth = numbers(" ".join(m.groups()))
    pos = solar_position(SPA_TIME, **SPA_CASE).iloc[0]
    assert_printed([zenith, azimuth], [6, 6], [pos["apparent_zenith"], pos["azimuth"]])
    src = (ROOT / "tests" / "sim" / "test_sun.py").read_text(encoding="utf-8")
    assert f"- {published_zenith}) <= 1e-4" in src and f"- {published_azimuth}) <= 1e-4" in src
    site = _site()
    m = sentence(text, r"\(air (\d+) °C — the middle of seed 000's (\d+)–(\d+) °C —,\s+wind (\d+) "
                       r"m/s, altitude (\d+) m, albedo ([\d.]+)\)")
    air, low, high, wind, altitude, albedo = numbers(" ".join(m.groups()))
    assert [air, wind, altitude] == [site.temp_air, site.wind_speed, site.altitude]
    assert abs(air - (low + high) / 2) <= 0.5  # the middle, to a whole degree
    assert {a.albedo for a in site.arrays.values()} == {albedo}
    m = sentence(text, r"Wiring: (\d+) series × (\d+) parallel by default")
    wiring = {(a.modules_in_series, a.strings_in_parallel) for a in site.arrays.values()}
    assert wiring == {tuple(numbers(" ".join(m.groups())))}


def test_validation_reading_of_the_gain_table() -> None:
    """The prose of section 4 against its own table (which tests above recompute)."""
    text = doc("validation.md")
    days = [table_row(text, d) for d in ("2024-03-15", "2024-04-25")]
    gains = [numbers(row[2])[0] for row in days]
    windows = [numbers(row[4])[0] for row in days]
    m = sentence(text, r"the twin's clear-sky gain \((\d+)–(\d+) %\) is about twice")
    assert numbers(" ".join(m.groups())) == [round(min(gains)), round(max(gains))]
    m = sentence(text, r"the\s+twin's gain falls to (\d+)–(\d+) % on the two days")
    assert numbers(" ".join(m.groups())) == [int(min(windows)), int(max(windows))]
    # "The 12:04 peak of "15 March" is 26 min before solar noon (12:30)": the table's time
    m = sentence(text, r"12:04 peak of \"15 March\" is (\d+) min before solar noon \((\d+):(\d+)\)")
    before, hour, minute = numbers(" ".join(m.groups()))
    assert numbers(days[0][3])[2:] == [hour, minute]
    assert before == 60 * (hour - 12) + minute - 4
    m = sentence(text, r"against (\d+) W on the clear-sky year")
    assert float(m.group(1)) == round(numbers(table_row(text, "year 2024")[3])[0])


def test_validation_wiring_station_and_steps() -> None:
    from sim.pv import KD205GX_LP_DATASHEET_STC as SHEET
    from sim.sky import pvlib_tmy3_path, read_tmy3

    text = doc("validation.md")
    m = sentence(text, r"ACS712-30A fits (\d+) × ([\d.]+) A ≈ (\d+) A")
    n, imp, total = numbers(" ".join(m.groups()))
    assert n == _site().arrays["tracker"].strings_in_parallel and imp == SHEET["imp_a"]
    assert total == round(n * imp)
    m = sentence(text, r"\(Greensboro Piedmont Triad Intl., NC, ([\d.]+) N\)")
    assert_printed(numbers(m.group(1)), [1], [read_tmy3(pvlib_tmy3_path())[1]["latitude"]])
    m = sentence(text, r"over 2023 \(([\d,]+) steps\)")
    steps = pd.date_range("2023-01-01", "2024-01-01", freq="1min", inclusive="left")
    assert numbers(m.group(1)) == [len(steps)]
