"""Benchmark of the twin: a full year at 1-minute steps for both arrays of ``tehuantepec``.

Baseline (measured in this run): what a pvlib user would write — pvlib's
``Location.get_clearsky`` and ``ModelChain`` with the CEC single-diode model,
computing the same two arrays (dual-axis tracker via a two-axis mount, fixed
16° south) for the same year at 1 min. Measured against it: the whole
``heliotwin simulate`` process (interpreter start and imports included), best
and median of five runs (the best is the figure: on a shared 2-core machine the
others carry other people's load), plus the energies of both so the speed is not bought
with accuracy. Also the two speed-ups inside: SPA with the geocentric part
interpolated (vs ``pvlib.solarposition.spa_python`` at every minute) and the
MPP table (vs ``pvlib.pvsystem.singlediode`` at every daytime minute).

Prints one Markdown section on stdout; progress on stderr.
"""

from __future__ import annotations

import json
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from _common import log  # noqa: E402  (bench scripts run from this folder)
from pvlib import solarposition

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "sim"))  # pvlib_reference: the independent baseline

LAT, LON, ALT, TEMP_AIR, WIND = 16.28875, -95.240871, 50.0, 27.0, 1.0
TZ = "America/Mexico_City"
YEAR = 2023  # 525,600 one-minute steps


def kwh(wh: float) -> str:
    return f"{wh / 1000:.2f}"


def baseline(times: pd.DatetimeIndex) -> tuple[float, float, dict[str, float]]:
    """pvlib ModelChain (CEC) for both arrays — the independent reference of
    tests/sim/pvlib_reference.py; returns (wall s, CPU s, energies [Wh])."""
    from pvlib_reference import modelchain_dc_power

    t0, c0 = time.perf_counter(), time.process_time()
    dc = modelchain_dc_power(
        times, LAT, LON, altitude=ALT, temp_air=TEMP_AIR, wind_speed=WIND
    )
    energies = {name: float(dc[name].sum() / 60.0) for name in ("tracker", "fixed")}
    return time.perf_counter() - t0, time.process_time() - c0, energies


def heliotwin_cmd() -> list[str]:
    exe = Path(sys.executable).parent / "heliotwin"
    if exe.exists():
        return [str(exe)]
    found = shutil.which("heliotwin")
    return [found] if found else [sys.executable, "-m", "backend"]


def twin_process(runs: int = 5) -> tuple[list[float], list[float], dict]:
    """Wall and CPU (user + system) times of whole ``heliotwin simulate`` processes."""
    cmd = heliotwin_cmd() + [
        "simulate",
        "--site",
        "tehuantepec",
        "--start",
        f"{YEAR}-01-01",
        "--end",
        f"{YEAR + 1}-01-01",
        "--json",
        "--no-progress",
    ]
    times, cpu, summary = [], [], {}
    for _ in range(runs):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, check=True)
        times.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append((r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime))
        summary = json.loads(proc.stdout)
    return times, cpu, summary


def inside_speedups(times: pd.DatetimeIndex) -> dict[str, float]:
    """SPA interpolation and the MPP table against pvlib's direct routes."""
    from pvlib import atmosphere

    from sim import pv
    from sim.sun import angular_separation, solar_position

    out: dict[str, float] = {}
    pressure = float(atmosphere.alt2pres(ALT))
    t0 = time.perf_counter()
    ref = solarposition.spa_python(times, LAT, LON, ALT, pressure, TEMP_AIR)
    out["spa_pvlib_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    ours = solar_position(times, LAT, LON, ALT, pressure, TEMP_AIR)
    out["spa_ours_s"] = time.perf_counter() - t0
    sep = angular_separation(ours["zenith"], ours["azimuth"], ref["zenith"], ref["azimuth"])
    out["spa_max_sep_deg"] = float(np.max(sep))
    out["spa_max_app_zen_deg"] = float(
        np.max(np.abs(ours["apparent_zenith"] - ref["apparent_zenith"]))
    )
    # MPP: realistic inputs, every daytime minute of the tracker (POA ~ DNI + diffuse)
    rng = np.random.default_rng(1)
    n = int((ref["apparent_elevation"] > 0).sum())
    e = rng.uniform(0.0, 1100.0, n)
    t = 27.0 + e * 0.03
    pv.mpp_table()  # build outside the timing (it is part of the process figure above)
    t0 = time.perf_counter()
    i_mp, v_mp = pv.mpp_table().lookup(e, t)
    out["mpp_table_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    exact = pv.module_mpp_exact(e, t)
    out["mpp_exact_s"] = time.perf_counter() - t0
    out["mpp_energy_rel"] = float((i_mp * v_mp).sum() / exact["p_mp"].sum() - 1)
    out["mpp_points"] = n
    return out


def main() -> int:
    times = pd.date_range(
        f"{YEAR}-01-01", f"{YEAR + 1}-01-01", freq="1min", inclusive="left", tz=TZ
    )
    log(f"baseline: pvlib ModelChain CEC, both arrays, {len(times)} steps ...")
    base_s, base_cpu, base_e = baseline(times)
    log(f"  {base_s:.2f} s")
    log("heliotwin simulate (5 whole processes) ...")
    runs, cpus, summary = twin_process()
    log(f"  {', '.join(f'{r:.2f}' for r in runs)} s")
    log("inside: SPA interpolation, MPP table ...")
    ins = inside_speedups(times)
    best, med = min(runs), statistics.median(runs)
    d_tr = 100 * (summary["tracker_energy_wh"] / base_e["tracker"] - 1)
    d_fx = 100 * (summary["fixed_energy_wh"] / base_e["fixed"] - 1)
    met = best <= 3 and base_s / best >= 5
    rows = [
        ("baseline: pvlib `ModelChain` (CEC), both arrays, in-process", f"{base_s:.2f} s"),
        (
            "`heliotwin simulate` whole process (imports included), best / median of 5",
            f"{best:.2f} s / {med:.2f} s",
        ),
        ("**speed-up vs baseline** (best process vs baseline)", f"**{base_s / best:.1f}×**"),
        ("speed-up, median process vs baseline", f"{base_s / med:.1f}×"),
        (
            "CPU time (user + system), baseline vs best process — less sensitive to other load",
            f"{base_cpu:.2f} s vs {min(cpus):.2f} s ({base_cpu / min(cpus):.1f}×)",
        ),
        ("target: ≤ 3 s and ≥ 5×", "met" if met else "NOT met"),
        (
            "tracker energy: twin vs baseline",
            f"{kwh(summary['tracker_energy_wh'])} vs {kwh(base_e['tracker'])} kWh ({d_tr:+.3f} %)",
        ),
        (
            "fixed energy: twin vs baseline",
            f"{kwh(summary['fixed_energy_wh'])} vs {kwh(base_e['fixed'])} kWh ({d_fx:+.3f} %)",
        ),
        ("clear-sky gain (twin)", f"{summary['gain_pct']:.1f} %"),
        (
            "sun, a year at 1 min: `pvlib.solarposition.spa_python` vs `sim.sun` "
            "(SPA, hourly geocentric grid)",
            f"{ins['spa_pvlib_s']:.2f} s vs {ins['spa_ours_s']:.2f} s "
            f"({ins['spa_pvlib_s'] / ins['spa_ours_s']:.0f}×); max separation "
            f"{ins['spa_max_sep_deg']:.1e}°, max apparent-zenith difference "
            f"{ins['spa_max_app_zen_deg']:.1e}°",
        ),
        (
            f"MPP, {ins['mpp_points']:,} points: `pvlib.pvsystem.singlediode` vs `MppTable`",
            f"{ins['mpp_exact_s']:.3f} s vs {ins['mpp_table_s']:.3f} s "
            f"({ins['mpp_exact_s'] / ins['mpp_table_s']:.0f}×); energy difference "
            f"{100 * ins['mpp_energy_rel']:+.5f} %",
        ),
    ]
    print("## sim — twin year run (tracker + fixed, 1-min steps)\n")
    print(
        f"Site `tehuantepec`, clear sky, {YEAR}-01-01 … {YEAR + 1}-01-01 "
        f"({len(times):,} steps per array).\n"
    )
    print("| figure | value |\n|---|---|")
    for name, value in rows:
        print(f"| {name} | {value} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
