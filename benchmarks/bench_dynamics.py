"""Dynamics benchmark: analytic RK4 plant vs pymunk on seed 002's azimuth return.

Prints one Markdown section to stdout (progress on stderr): steps per second of
``sim.dynamics.forward_dynamics`` (RK4, controller called every step) as a
ratio to the pymunk plant of ``sim.dynamics_check`` run on the same reference
with the same controller in the same process, both at 1 ms; plus the wall time
of the whole ``dynamics_check.check()`` and the cost of a day's actuator-energy
estimate (``sim.motors.tracking_motion_energy``, one target a minute).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from _common import log  # noqa: E402  (bench scripts run from this folder)

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sim.dynamics import TrackerInertia  # noqa: E402
from sim.dynamics_check import check, reference_moves, run_move  # noqa: E402
from sim.motors import tracking_motion_energy  # noqa: E402


def best_of(fn, repeat: int = 3) -> float:
    """Fastest wall time of ``repeat`` calls [s]."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> int:
    p = TrackerInertia.seed002()
    move = reference_moves(1e-3)[0]
    n = len(move["q_ref"]) - 1
    log(f"bench_dynamics: {n} steps per plant")
    t_rk4 = best_of(lambda: run_move(move["q_ref"], move["qd_ref"], 1e-3, p, "analytic"))
    t_pymunk = best_of(lambda: run_move(move["q_ref"], move["qd_ref"], 1e-3, p, "pymunk"))
    log("bench_dynamics: check()")
    t_check = best_of(lambda: check(1e-3), repeat=1)
    minutes = np.arange(0, 720)
    az = 90.0 + 0.25 * minutes  # a synthetic 12-hour sweep: 180° of azimuth
    el = 80.0 * np.sin(np.pi * minutes / 720.0)
    t_day = best_of(lambda: tracking_motion_energy(az, el))
    out = [
        "## dynamics — the analytic plant and pymunk",
        "",
        f"Seed 002's azimuth return at 1 ms ({n:,} steps, controller every step): analytic RK4 "
        f"plant **{n / t_rk4:,.0f} steps/s**, pymunk plant {n / t_pymunk:,.0f} steps/s "
        f"(RK4 is {t_pymunk / t_rk4:.1f}× faster; simulated time {n / 1000 / t_rk4:.0f}× real "
        f"time). Most of both is Python per step (the controller callback; pymunk's attribute "
        f"setters), not the physics.",
        f"`heliotwin dynamics check` work (3 moves, both plants, 1 ms): {t_check:.1f} s.",
        f"A day's actuator energy from 720 one-minute targets "
        f"(`tracking_motion_energy`): {1e3 * t_day:.0f} ms.",
    ]
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
