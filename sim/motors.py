"""DC motor + gearbox per axis: the electrical cost of a tracker's moves.

A permanent-magnet brushed DC motor behind a PWM H-bridge on a 24 V bus
(seed 000, Acosta-Banda et al. 2025, section 2.4: two MD03 drivers, 24 V from an
FSP300-60ATV supply, PWM at 7.8 kHz, duty ↔ speed linear, Fig. 17), driving
the joint through a worm gearbox. Steady-state motor equations (the electrical
time constant, ~1 ms, is far below a move's duration):

* motor speed ω_m = N ω_out, back-EMF e = k_e ω_m with k_e = k_t (SI units);
* motor torque from the output torque through the gear:
  τ_m = τ_out / (N η) when the motor drives the load (τ_out ω_out ≥ 0), and
  τ_m = τ_out η_r / N when the load overhauls (τ_out ω_out < 0) or is held
  (ω_out = 0), with the reverse efficiency of a worm η_r = 2 − 1/η. For
  η < ½ (a self-locking worm) η_r < 0: the motor must still push to lower a
  load, and holding costs nothing — the worm holds it.
* armature current i = τ_m / k_t + i_0 sign(ω_m) (i_0: no-load current,
  the motor's own friction), armature voltage V = R i + k_e ω_m, PWM duty
  d = V / V_bus.
* power from the bus P = max(V i, 0) / η_driver: an H-bridge on a PSU does
  not recover regenerated energy (it is dumped or goes to the bus capacitors),
  so negative power counts as zero.

Standby (driver logic, the controller) is a separate line item,
``standby_power_w``; it is not part of :func:`electrical_power_w`.

The default parameters are assumptions for a small worm-geared tracker drive
of seed 000's size (seed 000 names the drivers and the bus voltage, not the
motors): each is stated with its field below.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.dynamics import TrackerInertia, inverse_dynamics, move_profile

__all__ = [
    "AxisDrive",
    "DutyCommand",
    "motor_torque_nm",
    "motor_current_a",
    "armature_voltage_v",
    "electrical_power_w",
    "duty_for",
    "move_energy_wh",
    "tracking_motion_energy",
]


@dataclass(frozen=True)
class AxisDrive:
    """One axis drive: PWM H-bridge, brushed DC motor, worm gearbox.

    Parameters
    ----------
    supply_voltage_v : float
        Motor bus [V]. Source: seed 000, section 2.4 (MD03 drivers at 24 V).
    torque_constant_nm_a : float
        Motor torque constant k_t = back-EMF constant k_e [N m A⁻¹] = [V s rad⁻¹].
        Assumption: 0.045, a ~40 W 24 V brushed motor (no-load ≈ 5,000 rpm).
    winding_resistance_ohm : float
        Armature resistance [Ω]. Assumption: 1.5 (stall current 16 A, inside
        the MD03's 20 A rating).
    no_load_current_a : float
        Current the motor draws spinning unloaded (its own friction) [A].
        Assumption: 0.15.
    gear_ratio : float
        Motor turns per output turn [-]. Assumption: 1,500 (worm 1:60 ×
        planetary 1:25), giving ≈ 0.35 rad s⁻¹ (20 ° s⁻¹) at no load.
    gear_efficiency : float
        Forward efficiency of the gearbox [-], in (0, 1]. Assumption: 0.40, a
        single-start worm (self-locking below 0.5).
    max_output_torque_nm : float
        Gearbox output rating [N m]. Assumption: 60.
    max_output_speed_rad_s : float
        Output speed limit [rad s⁻¹]. Assumption: 0.2 (≈ 11 ° s⁻¹).
    driver_efficiency : float
        H-bridge efficiency [-]. Assumption: 0.95 (MOSFET bridge at 7.8 kHz).
    standby_power_w : float
        Driver logic and share of the controller, drawn all day [W]. Assumption:
        0.25 (MD03 5 V logic, ≈ 50 mA).
    """

    supply_voltage_v: float = 24.0
    torque_constant_nm_a: float = 0.045
    winding_resistance_ohm: float = 1.5
    no_load_current_a: float = 0.15
    gear_ratio: float = 1500.0
    gear_efficiency: float = 0.40
    max_output_torque_nm: float = 60.0
    max_output_speed_rad_s: float = 0.2
    driver_efficiency: float = 0.95
    standby_power_w: float = 0.25

    def __post_init__(self) -> None:
        positive = (
            "supply_voltage_v",
            "torque_constant_nm_a",
            "winding_resistance_ohm",
            "gear_ratio",
            "max_output_torque_nm",
            "max_output_speed_rad_s",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"AxisDrive.{name} must be > 0, got {value}")
        for name in ("gear_efficiency", "driver_efficiency"):
            value = getattr(self, name)
            if not (0 < value <= 1):
                raise ValueError(f"AxisDrive.{name} must be in (0, 1], got {value}")
        for name in ("no_load_current_a", "standby_power_w"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"AxisDrive.{name} must be >= 0, got {value}")

    @classmethod
    def azimuth_default(cls) -> AxisDrive:
        """Azimuth drive: the default motor behind a 1:1,000 worm train (assumption:
        no gravity load, so a faster ratio for the ≈ 250° daily sweep and the
        evening return; no-load output ≈ 0.53 rad s⁻¹, limited to 0.2)."""
        return cls(gear_ratio=1000.0)

    @classmethod
    def elevation_default(cls) -> AxisDrive:
        """Elevation drive: the default motor behind the 1:1,500 self-locking worm,
        which holds seed 002's ≈ 10.7 N m gravity torque unpowered."""
        return cls()

    @property
    def reverse_efficiency(self) -> float:
        """η_r = 2 − 1/η of a worm driven from the output [-]; ≤ 0 means self-locking."""
        return 2.0 - 1.0 / self.gear_efficiency

    @property
    def self_locking(self) -> bool:
        """True when the load cannot back-drive the gear (η_r ≤ 0)."""
        return self.reverse_efficiency <= 0.0


def _pair(tau: ArrayLike, omega: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    t, w = np.broadcast_arrays(np.asarray(tau, dtype=float), np.asarray(omega, dtype=float))
    return t, w


def motor_torque_nm(
    drive: AxisDrive, tau_out_nm: ArrayLike, omega_out_rad_s: ArrayLike
) -> NDArray[np.float64]:
    """Torque at the motor shaft for an output torque and speed [N m] (module
    docstring: forward efficiency when motoring, worm reverse efficiency when
    the load overhauls or is held)."""
    tau, w = _pair(tau_out_nm, omega_out_rad_s)
    n = drive.gear_ratio
    driving = tau / (n * drive.gear_efficiency)
    overhauled = tau * drive.reverse_efficiency / n
    # held still: a self-locking worm carries the load alone; otherwise the
    # motor supplies what the gear's friction does not
    held = tau * 0.0 if drive.self_locking else overhauled  # (NaN stays NaN)
    return np.where(w == 0, held, np.where(tau * w > 0, driving, overhauled))


def motor_current_a(
    drive: AxisDrive, tau_out_nm: ArrayLike, omega_out_rad_s: ArrayLike
) -> NDArray[np.float64]:
    """Armature current for an output torque and speed [A].

    Parameters
    ----------
    drive : AxisDrive
    tau_out_nm : array_like
        Joint torque the drive must deliver [N m] (e.g. from
        :func:`sim.dynamics.inverse_dynamics`).
    omega_out_rad_s : array_like
        Joint speed [rad s⁻¹].

    Returns
    -------
    ndarray
        i = τ_m / k_t + i_0 sign(ω) [A], signed.
    """
    tau_m = motor_torque_nm(drive, tau_out_nm, omega_out_rad_s)
    w = np.broadcast_to(np.asarray(omega_out_rad_s, dtype=float), tau_m.shape)
    return tau_m / drive.torque_constant_nm_a + drive.no_load_current_a * np.sign(w)


def armature_voltage_v(
    drive: AxisDrive, tau_out_nm: ArrayLike, omega_out_rad_s: ArrayLike
) -> NDArray[np.float64]:
    """Armature voltage V = R i + k_e N ω_out the driver must apply [V]."""
    i = motor_current_a(drive, tau_out_nm, omega_out_rad_s)
    w = np.broadcast_to(np.asarray(omega_out_rad_s, dtype=float), i.shape)
    return drive.winding_resistance_ohm * i + drive.torque_constant_nm_a * drive.gear_ratio * w


def electrical_power_w(
    drive: AxisDrive, tau_out_nm: ArrayLike, omega_out_rad_s: ArrayLike
) -> NDArray[np.float64]:
    """Power drawn from the 24 V bus by the motor and its driver [W], ≥ 0.

    P = max(V i, 0) / η_driver: regenerated power is not recovered (module
    docstring). Holding with a non-self-locking gear costs R i²; with a
    self-locking worm it costs nothing. Standby is not included
    (``drive.standby_power_w``).
    """
    i = motor_current_a(drive, tau_out_nm, omega_out_rad_s)
    v = armature_voltage_v(drive, tau_out_nm, omega_out_rad_s)
    return np.maximum(v * i, 0.0) / drive.driver_efficiency


class DutyCommand(NamedTuple):
    """PWM command of :func:`duty_for`."""

    #: duty cycle in [−1, 1] [-], sign = direction (clipped)
    duty: NDArray[np.float64]
    #: False where the request exceeds the drive: voltage above the bus, output
    #: torque or speed above the ratings, or non-finite input
    feasible: NDArray[np.bool_]


def duty_for(
    drive: AxisDrive, tau_out_nm: ArrayLike, omega_out_rad_s: ArrayLike
) -> DutyCommand:
    """PWM duty that delivers an output torque at an output speed.

    The MD03 sets the average armature voltage as duty × V_bus (seed 000,
    section 2.4 and Fig. 17: duty ↔ speed linear), so d = V / V_bus.

    Parameters
    ----------
    drive : AxisDrive
    tau_out_nm : array_like
        Output torque [N m].
    omega_out_rad_s : array_like
        Output speed [rad s⁻¹].

    Returns
    -------
    DutyCommand
        ``duty`` clipped to [−1, 1] (NaN for NaN input) and ``feasible``.
    """
    tau, w = _pair(tau_out_nm, omega_out_rad_s)
    raw = armature_voltage_v(drive, tau, w) / drive.supply_voltage_v
    feasible = (
        np.isfinite(raw)
        & (np.abs(raw) <= 1.0)
        & (np.abs(tau) <= drive.max_output_torque_nm)
        & (np.abs(w) <= drive.max_output_speed_rad_s)
    )
    return DutyCommand(np.clip(raw, -1.0, 1.0), feasible)


def move_energy_wh(
    drive: AxisDrive, tau_out_nm: ArrayLike, omega_out_rad_s: ArrayLike, dt_s: float
) -> float:
    """Bus energy of a sampled move [Wh]: Σ P(τ_k, ω_k) Δt / 3600.

    Parameters
    ----------
    drive : AxisDrive
    tau_out_nm, omega_out_rad_s : array_like
        Output torque [N m] and speed [rad s⁻¹] at each sample, each held for
        ``dt_s`` (e.g. :func:`sim.dynamics.move_profile` through
        :func:`sim.dynamics.inverse_dynamics`).
    dt_s : float
        Sample step [s], > 0.

    Returns
    -------
    float
        [Wh]; standby not included.
    """
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s must be a positive number, got {dt_s}")
    power = electrical_power_w(drive, tau_out_nm, omega_out_rad_s)
    if not np.isfinite(power).all():
        raise ValueError("move_energy_wh: torque and speed must be finite")
    return float(np.sum(power) * dt_s / 3600.0)


def tracking_motion_energy(
    azimuth_joint_deg: ArrayLike,
    elevation_joint_deg: ArrayLike,
    p: TrackerInertia | None = None,
    azimuth_drive: AxisDrive | None = None,
    elevation_drive: AxisDrive | None = None,
    dead_band_deg: float = 0.0,
    max_rate_rad_s: float = 0.05,
    max_accel_rad_s2: float = 0.1,
    dt_s: float = 0.01,
    hours: float = 24.0,
) -> dict[str, float]:
    """Actuator energy of following a sequence of joint targets (e.g. one a minute).

    Each axis whose target is more than ``dead_band_deg`` from where it stands
    moves there on a trapezoidal profile (:func:`sim.dynamics.move_profile`),
    both axes starting together; the joint torques along the move come from
    seed 002's eq. 24 (:func:`sim.dynamics.inverse_dynamics`), the bus energy
    from :func:`move_energy_wh`. Between moves the axes are held (free with a
    self-locking worm).

    Parameters
    ----------
    azimuth_joint_deg, elevation_joint_deg : array_like, shape (n,)
        Joint targets in time order [°] (e.g. :func:`sim.kinematics.tracking_angles`).
    p : TrackerInertia, optional
        Default: seed 002, Table 1.
    azimuth_drive, elevation_drive : AxisDrive, optional
        Defaults: :meth:`AxisDrive.azimuth_default`, :meth:`AxisDrive.elevation_default`.
    dead_band_deg : float
        Move an axis only when its error exceeds this [°] (0: every target).
    max_rate_rad_s, max_accel_rad_s2 : float
        Slew limits of the moves [rad s⁻¹], [rad s⁻²].
    dt_s : float
        Sample step of the move profiles [s].
    hours : float
        Length of the period, for the standby line item [h].

    Returns
    -------
    dict
        ``moves`` (targets at which at least one axis moved), ``moving_time_s``,
        ``azimuth_travel_deg``, ``elevation_travel_deg``, ``azimuth_motion_wh``,
        ``elevation_motion_wh``, ``motion_wh``, ``standby_wh`` and ``total_wh``.
    """
    az = np.radians(np.asarray(azimuth_joint_deg, dtype=float).reshape(-1))
    el = np.radians(np.asarray(elevation_joint_deg, dtype=float).reshape(-1))
    if az.shape != el.shape or az.size == 0:
        raise ValueError(f"need equal, non-empty target series, got {az.shape}, {el.shape}")
    if not (np.isfinite(az).all() and np.isfinite(el).all()):
        raise ValueError("joint targets must be finite (stow the tracker at night, no NaN)")
    if not (math.isfinite(dead_band_deg) and dead_band_deg >= 0):
        raise ValueError(f"dead_band_deg must be >= 0, got {dead_band_deg}")
    p = TrackerInertia.seed002() if p is None else p
    drives = (
        AxisDrive.azimuth_default() if azimuth_drive is None else azimuth_drive,
        AxisDrive.elevation_default() if elevation_drive is None else elevation_drive,
    )
    band = math.radians(dead_band_deg)
    pos = [float(az[0]), float(el[0])]
    energy = [0.0, 0.0]
    travel = [0.0, 0.0]
    moves, moving_s = 0, 0.0
    for target in zip(az[1:], el[1:], strict=True):
        deltas = [float(target[j]) - pos[j] for j in range(2)]
        deltas = [d if abs(d) > band and d != 0.0 else 0.0 for d in deltas]
        if deltas == [0.0, 0.0]:
            continue
        profiles = [move_profile(d, max_rate_rad_s, max_accel_rad_s2, dt_s) for d in deltas]
        n = max(len(prof[0]) for prof in profiles)
        q = np.zeros((2, n))
        qd = np.zeros((2, n))
        qdd = np.zeros((2, n))
        for j, (_, qj, qdj, qddj) in enumerate(profiles):
            q[j, : len(qj)] = qj
            q[j, len(qj) :] = qj[-1]
            qd[j, : len(qdj)] = qdj
            qdd[j, : len(qddj)] = qddj
        tau = inverse_dynamics(pos[1] + q[1], qd[0], qd[1], qdd[0], qdd[1], p)
        for j in range(2):
            if deltas[j] != 0.0:
                energy[j] += move_energy_wh(drives[j], tau[j], qd[j], dt_s)
                travel[j] += abs(deltas[j])
            pos[j] += deltas[j]
        moves += 1
        moving_s += (n - 1) * dt_s
    standby = (drives[0].standby_power_w + drives[1].standby_power_w) * hours
    return {
        "moves": float(moves),
        "moving_time_s": moving_s,
        "azimuth_travel_deg": math.degrees(travel[0]),
        "elevation_travel_deg": math.degrees(travel[1]),
        "azimuth_motion_wh": energy[0],
        "elevation_motion_wh": energy[1],
        "motion_wh": energy[0] + energy[1],
        "standby_wh": standby,
        "total_wh": energy[0] + energy[1] + standby,
    }
