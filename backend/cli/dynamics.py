"""``heliotwin dynamics``: the tracker's rigid-body dynamics (seed 002, eq. 24).

    heliotwin dynamics check --json
    heliotwin dynamics torque --elevation-deg 9.9 --azimuth-rate-rad-s 0.1 --json

``check`` runs the reference moves on the analytic plant and on pymunk and
prints how far apart they are (:func:`sim.dynamics_check.check`); ``torque``
prints the joint torques of the inverse dynamics for one state
(:func:`sim.dynamics.inverse_dynamics`, seed 002's Table 1). Heavy imports
happen inside the commands.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from backend.cli import fail

_RATE_FLAGS = (
    ("azimuth_rate_rad_s", "--azimuth-rate-rad-s", "azimuth joint rate [rad/s] (default 0)"),
    ("elevation_rate_rad_s", "--elevation-rate-rad-s", "elevation joint rate [rad/s] (default 0)"),
    (
        "azimuth_accel_rad_s2",
        "--azimuth-accel-rad-s2",
        "azimuth joint acceleration [rad/s^2] (default 0)",
    ),
    (
        "elevation_accel_rad_s2",
        "--elevation-accel-rad-s2",
        "elevation joint acceleration [rad/s^2] (default 0)",
    ),
)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``dynamics`` subcommand with ``check`` and ``torque``."""
    p = subparsers.add_parser(
        "dynamics",
        help="tracker dynamics: pymunk cross-check and inverse-dynamics torques",
        description="Seed 002's two-link tracker dynamics (eq. 24, Table 1).",
    )
    sub = p.add_subparsers(dest="dynamics_command", metavar="ACTION", required=True)

    c = sub.add_parser(
        "check",
        help="analytic plant vs pymunk on the reference moves",
        description="Run seed 002's azimuth return (-244 -> -115.5 deg at 9.9 deg), a "
        "0 -> 60 deg elevation slew and a coupled slew on the analytic plant and on pymunk "
        "under the same controller; print the torque and angle RMS differences.",
    )
    c.add_argument("--dt-s", type=float, default=1e-3, help="step of both plants [s] (1e-3)")
    c.add_argument("--json", action="store_true", help="print JSON (default: text)")
    c.set_defaults(func=run_check)

    t = sub.add_parser(
        "torque",
        help="joint torques for one state (inverse dynamics)",
        description="Joint torques tau = M(q) qdd + V(q, qd) + G(q) of seed 002's eq. 24 "
        "with Table 1. tau_elevation > 0 raises the panel normal.",
    )
    t.add_argument(
        "--elevation-deg", type=float, required=True,
        help="elevation joint angle [deg], within the joint's range 0..90"
    )
    for dest, flag, text in _RATE_FLAGS:
        t.add_argument(flag, dest=dest, type=float, default=0.0, help=text)
    t.add_argument("--json", action="store_true", help="print JSON (default: text)")
    t.set_defaults(func=run_torque)


def compute_torque(args: argparse.Namespace) -> dict[str, float]:
    """``{"tau_azimuth_nm", "tau_elevation_nm"}`` for the state in ``args``."""
    import numpy as np

    from sim.dynamics import TrackerInertia, inverse_dynamics

    with np.errstate(over="ignore", invalid="ignore"):  # a finite check follows
        tau1, tau2 = inverse_dynamics(
            math.radians(args.elevation_deg),
            args.azimuth_rate_rad_s,
            args.elevation_rate_rad_s,
            args.azimuth_accel_rad_s2,
            args.elevation_accel_rad_s2,
            TrackerInertia.seed002(),
        )
    return {"tau_azimuth_nm": float(tau1), "tau_elevation_nm": float(tau2)}


def _torque_problem(args: argparse.Namespace) -> str | None:
    """An error message for bad input, else None."""
    values = [("--elevation-deg", args.elevation_deg)] + [
        (flag, getattr(args, dest)) for dest, flag, _ in _RATE_FLAGS
    ]
    for flag, value in values:
        if not math.isfinite(value):
            return f"{flag} {value}: must be a finite number"
    from sim.kinematics import TrackerGeometry

    joint = TrackerGeometry()  # the elevation joint's range (sim/kinematics.py)
    lo, hi = joint.elevation_min_deg, joint.elevation_max_deg
    if not lo <= args.elevation_deg <= hi:
        return (f"--elevation-deg {args.elevation_deg:g}: outside the elevation joint's range "
                f"[{lo:g}, {hi:g}] deg (the panel normal from horizontal to the zenith)")
    return None


def run_torque(args: argparse.Namespace) -> int:
    """Print the inverse-dynamics torques; exit 2 on bad input."""
    problem = _torque_problem(args)
    if problem:
        fail(problem)
    out = compute_torque(args)
    if not all(math.isfinite(v) for v in out.values()):
        fail("the torques overflow a float for these rates and accelerations "
             f"({', '.join(flag for _, flag, _ in _RATE_FLAGS)}): give physical ones "
             "(a tracker's drives reach hundredths of a rad/s)")
    if args.json:
        print(json.dumps(out))
    else:
        print(
            f"elevation {args.elevation_deg:g} deg: tau_azimuth {out['tau_azimuth_nm']:.6f} N m, "
            f"tau_elevation {out['tau_elevation_nm']:.6f} N m"
        )
    return 0


def run_check(args: argparse.Namespace) -> int:
    """Print the analytic-vs-pymunk comparison; exit 2 on a bad step."""
    if not (math.isfinite(args.dt_s) and 0 < args.dt_s <= 0.05):
        fail(f"--dt-s {args.dt_s}: must be in (0, 0.05] s")
    from sim.dynamics_check import check

    out: dict[str, Any] = check(dt_s=args.dt_s)
    if args.json:
        print(json.dumps(out))
        return 0
    print(
        f"analytic vs pymunk at dt {out['dt_s']:g} s: torque RMS difference "
        f"{out['torque_rms_diff_pct_of_peak']:.4f} % of peak, angle RMS difference "
        f"{out['angle_rms_diff_mrad']:.4f} mrad (worst move)"
    )
    for move in out["moves"]:
        print(
            f"  {move['name']:<24} {move['duration_s']:6.2f} s  peak {move['peak_torque_nm']:7.3f} "
            f"N m  torque {move['torque_rms_diff_pct_of_peak']:.4f} %  "
            f"angle {move['angle_rms_diff_mrad']:.4f} mrad"
        )
    return 0
