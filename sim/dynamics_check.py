"""Cross-check of the analytic plant (:mod:`sim.dynamics`) against pymunk.

Seed 002 (Fernández-Pizarro et al. 2019, section III, Figs. 6–8) validates its
eq. 24 plant against a second engine (SimMechanics) driven by the same PID
controller. pymunk (Chipmunk2D) plays that role here.

How the 3-D tracker is put into a 2-D engine
--------------------------------------------
pymunk is planar, so the tracker is split into two planar mechanisms, each
built from the *physical* description (masses, Table 1's inertia tensors, the
centre of gravity, gravity) and not from eq. 24:

* **Elevation** (a vertical plane through the panel normal): link 2 is one
  rigid body of mass m2 and moment I23 about its centre of gravity, which sits
  at cg2 along the body's x axis (the normal); the body's origin is pinned to
  the ground by a ``PivotJoint`` (the elevation axis) and the space has
  gravity (0, −g). pymunk's constraint solver supplies the parallel-axis term
  and the weight's moment, so this checks **M22 = m2 cg2² + I23** and
  **G2 = m2 g cg2 cos q2**.
* **Azimuth** (top view, no gravity): a turntable body (link 1: m1, I12, centre
  on the axis) pinned at the origin, and link 2's top-view body locked to it by
  a ``PivotJoint`` at the axis plus a ``GearJoint`` (ratio 1). Link 2's body
  has its centre of gravity at the horizontal projection cg2 cos q2 and, as its
  own moment, the vertical component of Table 1's tensor rotated by the D–H
  rotation ⁰R₂ of :func:`sim.kinematics.dh_transform` (``(R I Rᵀ)_zz``), with
  q2 taken from the elevation mechanism every step. pymunk composes the two
  bodies through the joints, so this checks **M11(q2) = I12 + m2 cg2² c2² +
  I21 s2² + I22 c2²** (the parallel-axis term and the rotated tensor).

Coupling the two planes (the velocity-product terms V): every step the top
view takes q2 from the elevation plane and re-shapes link 2; the re-shape is
internal to the rotating assembly, so the angular momentum about the azimuth
axis (computed from pymunk's bodies) is kept, ω ← ω I_old / I_new — that *is*
the Coriolis term V1 = −2 A s2 c2 q̇1 q̇2. The elevation plane does not rotate;
it receives the rotating frame's centrifugal pseudo-torque ½ Ω² ∂I_az/∂q2,
with Ω pymunk's turntable rate and ∂I_az/∂q2 a finite difference of the top
view's parallel-axis moment — that is V2 = A s2 c2 q̇1². Both are generic
physics applied to pymunk's state (not eq. 24's expressions), but they are
added by us, so the V check is weaker than the M and G checks; V is also
checked by the independent sympy Lagrangian and the conservation laws in
``tests/sim/test_dynamics.py``. Not in either plant: the gyroscopic coupling
of a 3-D body beyond these two terms (none exists for this joint layout),
motors, friction and backlash.

Both plants are stepped at the same ``dt_s`` and driven by the same controller,
evaluated once per step from each plant's own state and held over the step
(pymunk zeroes ``body.torque`` after every step, so it is set every step). The
analytic plant integrates with RK4, pymunk with its semi-implicit Euler and
iterative constraint solver: the residual difference is pymunk's integration
and constraint error.

Reference moves (seed 002, section III; ``../shared/reference``):

* ``seed002_azimuth_return``: azimuth −244° → −115.5° at elevation 9.9°
  (Puerto Colombia, 1 Jan 2017, the day's azimuth sweep reversed at 19:00);
* ``elevation_slew_0_60``: elevation 0° → 60° with the azimuth held;
* ``coupled_slew`` (ours): azimuth 0° → 60° while the elevation goes
  10° → 40°, so that V is exercised.

Each follows a trapezoidal profile (:func:`sim.dynamics.move_profile`) with the
rate and acceleration limits below (assumptions: the seed does not state its
time axis) under seed 002's PD gains Kp = 20, Kd = 10 (N m rad⁻¹, N m s rad⁻¹)
plus gravity compensation, then settles for ``SETTLE_S``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pymunk
from numpy.typing import NDArray

from sim.dynamics import TrackerInertia, forward_dynamics, gravity, move_profile
from sim.kinematics import dh_transform

__all__ = [
    "KP_SEED002",
    "KD_SEED002",
    "PymunkTracker",
    "JointController",
    "reference_moves",
    "run_move",
    "check",
    "elevation_hold",
    "gravity_hold_study",
]

#: seed 002, section III: Kp = 20 I, Ki = 0, Kd = 10 I.
KP_SEED002 = 20.0
KD_SEED002 = 10.0
#: Slew limits of the reference moves (assumption: 0.1 rad/s ≈ 5.7 °/s, a
#: fast small tracker; seed 002 gives no time axis) [rad s⁻¹], [rad s⁻²].
REFERENCE_RATE_RAD_S = 0.1
REFERENCE_ACCEL_RAD_S2 = 0.2
#: Time after the end of the profile for the plants to settle [s].
SETTLE_S = 1.0


class _Link2VerticalInertia:
    """Moment of link 2 about the vertical through its centre of gravity [kg m²].

    ``(R I Rᵀ)_zz`` with ``⁰R₂ = ⁰R₁ Rot(z, q2)`` — ⁰R₁ from the D–H chain
    (:func:`sim.kinematics.dh_transform`, seed 002 eq. 2 with α1 = 90°) and
    Table 1's principal tensor (seed 002, eq. 7). Only the third row of ⁰R₂
    matters; it is formed in floats for speed.
    """

    def __init__(self, p: TrackerInertia) -> None:
        r01 = dh_transform(0.0, 0.0, 0.0, math.pi / 2.0)[:3, :3]
        self.row = [float(x) for x in r01[2]]
        self.principal = (p.i21_kg_m2, p.i22_kg_m2, p.i23_kg_m2)

    def __call__(self, q2_rad: float) -> float:
        c, s = math.cos(q2_rad), math.sin(q2_rad)
        r0, r1, r2 = self.row
        # third row of ⁰R₁ · Rot(z, q2)
        z = (r0 * c + r1 * s, -r0 * s + r1 * c, r2)
        return sum(zk * zk * ik for zk, ik in zip(z, self.principal, strict=True))


class PymunkTracker:
    """The tracker as two planar pymunk mechanisms (module docstring).

    Parameters
    ----------
    p : TrackerInertia
    q0, qd0 : sequence of 2 floats
        Initial (azimuth, elevation) angles [rad] and rates [rad s⁻¹].
    iterations : int
        pymunk constraint-solver iterations per step.
    """

    def __init__(
        self,
        p: TrackerInertia,
        q0: tuple[float, float],
        qd0: tuple[float, float],
        iterations: int = 20,
    ) -> None:
        self.p = p
        # elevation: vertical plane with gravity
        self.elevation_space = pymunk.Space()
        self.elevation_space.gravity = (0.0, -p.g_m_s2)
        self.elevation_space.iterations = iterations
        self.panel = pymunk.Body(mass=p.m2_kg, moment=p.i23_kg_m2)
        self.panel.center_of_gravity = (p.cg2_m, 0.0)
        self._place(self.panel, q0[1], qd0[1])
        pivot = pymunk.PivotJoint(self.elevation_space.static_body, self.panel, (0, 0), (0, 0))
        self.elevation_space.add(self.panel, pivot)
        # azimuth: top view, no gravity
        self.azimuth_space = pymunk.Space()
        self.azimuth_space.iterations = iterations
        self.turntable = pymunk.Body(mass=p.m1_kg, moment=max(p.i12_kg_m2, 1e-12))
        self._place(self.turntable, q0[0], qd0[0])
        self._vertical_inertia = _Link2VerticalInertia(p)
        self.link2_top = pymunk.Body(mass=p.m2_kg, moment=self._vertical_inertia(q0[1]))
        self.link2_top.center_of_gravity = (p.cg2_m * math.cos(q0[1]), 0.0)
        self._place(self.link2_top, q0[0], qd0[0])
        axis = pymunk.PivotJoint(self.azimuth_space.static_body, self.turntable, (0, 0), (0, 0))
        carry = pymunk.PivotJoint(self.turntable, self.link2_top, (0, 0), (0, 0))
        lock = pymunk.GearJoint(self.turntable, self.link2_top, 0.0, 1.0)
        self.azimuth_space.add(self.turntable, self.link2_top, axis, carry, lock)

    @staticmethod
    def _place(body: pymunk.Body, angle: float, rate: float) -> None:
        """Put ``body``'s origin on the pivot at ``angle`` turning at ``rate``.

        The angle is set before the position: pymunk stores the centre of
        gravity's position, so the origin's position is converted with the
        current angle. The centre's velocity is ω × r.
        """
        body.angle = angle
        body.position = (0.0, 0.0)
        body.angular_velocity = rate
        cx, cy = body.local_to_world(body.center_of_gravity)
        body.velocity = (-rate * cy, rate * cx)

    def _reshape_link2(self, q2_rad: float) -> None:
        """Link 2 seen from above at elevation ``q2_rad``: centre at cg2 cos q2 and
        the rotated tensor's vertical moment. The reshape is internal to the
        rotating assembly (the elevation joint's forces), so the angular
        momentum about the azimuth axis is kept: ω_new = ω_old I_old / I_new —
        this is what carries the Coriolis term V1 into the top view."""
        i_old = self._azimuth_moment()
        self.link2_top.moment = self._vertical_inertia(q2_rad)
        self.link2_top.center_of_gravity = (self.p.cg2_m * math.cos(q2_rad), 0.0)
        rate = self.turntable.angular_velocity * i_old / self._azimuth_moment()
        self.turntable.angular_velocity = rate
        self._place(self.link2_top, self.turntable.angle, rate)

    def _azimuth_moment(self) -> float:
        """Moment of the rotating assembly about the azimuth axis, from pymunk's
        bodies: Σ (I_cg + m |r_cg|²) (parallel axes) [kg m²]."""
        total = 0.0
        for body in (self.turntable, self.link2_top):
            # both origins are pinned on the axis, so |r_cg| = |local centre of gravity|
            cx, cy = body.center_of_gravity
            total += body.moment + body.mass * (cx * cx + cy * cy)
        return total

    def _centrifugal_torque(self) -> float:
        """Rotating-frame pseudo-torque on the elevation axis, ½ Ω² ∂I_az/∂q2 [N m].

        Ω is pymunk's turntable rate; ∂I_az/∂q2 by central differences of the
        top view's moment (:meth:`_azimuth_moment`'s parallel-axis sum with link
        2 re-shaped at q2 ± h) — the centrifugal potential −½ Ω² I_az(q2) of the
        rotating frame, not eq. 24's V2.
        """
        omega = self.turntable.angular_velocity
        if omega == 0.0:
            return 0.0
        q2, h = self.panel.angle, 1e-5

        def moment(q: float) -> float:
            r = self.p.cg2_m * math.cos(q)
            return self.turntable.moment + self._vertical_inertia(q) + self.p.m2_kg * r * r

        return 0.5 * omega * omega * (moment(q2 + h) - moment(q2 - h)) / (2.0 * h)

    @property
    def q(self) -> NDArray[np.float64]:
        """(azimuth, elevation) [rad]."""
        return np.array([self.turntable.angle, self.panel.angle])

    @property
    def qd(self) -> NDArray[np.float64]:
        """(azimuth, elevation) rates [rad s⁻¹]."""
        return np.array([self.turntable.angular_velocity, self.panel.angular_velocity])

    def step(self, tau_nm: NDArray[np.float64], dt_s: float) -> None:
        """Advance by ``dt_s`` with joint torques ``tau_nm`` held over the step."""
        self.turntable.torque = float(tau_nm[0])
        self.panel.torque = float(tau_nm[1]) + self._centrifugal_torque()
        self.azimuth_space.step(dt_s)
        self.elevation_space.step(dt_s)
        self._reshape_link2(self.panel.angle)


@dataclass(frozen=True)
class JointController:
    """PID on both joints with optional gravity compensation, tracking a reference.

    ``τ = Kp e + Ki ∫e + Kd ė + Ĝ(q)`` with e = q_ref − q (seed 002, section III,
    Figs. 3–4; Ĝ from :func:`sim.dynamics.gravity` when ``gravity_compensation``).
    The reference is sampled at the step index; the integral is a running sum
    (forward Euler), so the controller keeps state: use :meth:`callback` to get
    a fresh one per run.
    """

    q_ref: NDArray[np.float64]  # (n, 2) [rad]
    qd_ref: NDArray[np.float64]  # (n, 2) [rad s⁻¹]
    dt_s: float
    p: TrackerInertia
    kp: float = KP_SEED002
    kd: float = KD_SEED002
    ki: float = 0.0
    gravity_compensation: bool = True

    def callback(self) -> Callable[[float, NDArray[np.float64], NDArray[np.float64]], NDArray]:
        """A ``torque(t_s, q, qd)`` function with its own integrator state."""
        integral = np.zeros(2)
        last = len(self.q_ref) - 1

        kp, kd, ki = self.kp, self.kd, self.ki
        # seed 002 eq. 24's G2 = m2 g cg2 cos q2 (as sim.dynamics.gravity), in floats
        mgc = self.p.m2_kg * self.p.g_m_s2 * self.p.cg2_m if self.gravity_compensation else 0.0
        q_ref, qd_ref, dt = self.q_ref, self.qd_ref, self.dt_s

        def torque(t_s: float, q: NDArray[np.float64], qd: NDArray[np.float64]) -> NDArray:
            k = min(int(round(t_s / dt)), last)
            e0, e1 = q_ref[k, 0] - q[0], q_ref[k, 1] - q[1]
            integral[0] += e0 * dt
            integral[1] += e1 * dt
            return np.array(
                [
                    kp * e0 + kd * (qd_ref[k, 0] - qd[0]) + ki * integral[0],
                    kp * e1 + kd * (qd_ref[k, 1] - qd[1]) + ki * integral[1]
                    + mgc * math.cos(q[1]),
                ]
            )

        return torque


def reference_moves(dt_s: float) -> list[dict[str, Any]]:
    """The reference moves as joint references sampled at ``dt_s``.

    The two moves of issue 11 (one axis at a time) and ``coupled_slew``, both
    axes at once (azimuth 0° → 60° while the elevation goes 10° → 40°), which
    exercises the Coriolis and centrifugal terms V. Each axis follows its own
    trapezoid, both starting at t = 0, then the pose is held for ``SETTLE_S``.

    Returns
    -------
    list of dict
        ``name``, ``q_ref`` (n, 2) [rad], ``qd_ref`` (n, 2) [rad s⁻¹].
    """
    cases = (
        ("seed002_azimuth_return", (-244.0, 9.9), (-115.5, 9.9)),
        ("elevation_slew_0_60", (0.0, 0.0), (0.0, 60.0)),
        ("coupled_slew", (0.0, 10.0), (60.0, 40.0)),
    )
    n_settle = int(round(SETTLE_S / dt_s))
    moves = []
    for name, start_deg, end_deg in cases:
        start = np.radians(start_deg)
        delta = np.radians(end_deg) - start
        profiles = [
            move_profile(float(d), REFERENCE_RATE_RAD_S, REFERENCE_ACCEL_RAD_S2, dt_s)
            for d in delta
        ]
        n = max(len(prof[0]) for prof in profiles) + n_settle
        q_ref = np.tile(start, (n, 1))
        qd_ref = np.zeros((n, 2))
        for axis, (_, q, qd, _) in enumerate(profiles):
            q_ref[: len(q), axis] += q
            q_ref[len(q) :, axis] += q[-1]
            qd_ref[: len(qd), axis] = qd
        moves.append({"name": name, "q_ref": q_ref, "qd_ref": qd_ref})
    return moves


def run_move(
    q_ref: NDArray[np.float64],
    qd_ref: NDArray[np.float64],
    dt_s: float,
    p: TrackerInertia,
    engine: str,
    controller: JointController | None = None,
) -> dict[str, NDArray[np.float64]]:
    """Drive one plant along a reference from rest at ``q_ref[0]``.

    Parameters
    ----------
    q_ref, qd_ref : ndarray, shape (n, 2)
        Reference angles [rad] and rates [rad s⁻¹].
    dt_s : float
        Step [s].
    p : TrackerInertia
    engine : {"analytic", "pymunk"}
    controller : JointController, optional
        Default: seed 002's PD gains with gravity compensation.

    Returns
    -------
    dict
        ``q`` (n, 2) [rad] and ``tau`` (n, 2) [N m] at the start of each step.
    """
    if controller is None:
        controller = JointController(q_ref, qd_ref, dt_s, p)
    torque = controller.callback()
    n = len(q_ref) - 1
    q0 = (float(q_ref[0, 0]), float(q_ref[0, 1]))
    taus = np.zeros((n + 1, 2))
    if engine == "analytic":

        def logged(t_s: float, q: NDArray[np.float64], qd: NDArray[np.float64]) -> NDArray:
            tau = torque(t_s, q, qd)
            taus[int(round(t_s / dt_s))] = tau
            return tau

        q, qd = forward_dynamics(q0, (0.0, 0.0), logged, dt_s, n, p)
        taus[n] = torque(n * dt_s, q[n], qd[n])
        return {"q": q, "tau": taus}
    if engine == "pymunk":
        plant = PymunkTracker(p, q0, (0.0, 0.0))
        qs = np.zeros((n + 1, 2))
        for k in range(n + 1):
            qs[k] = plant.q
            taus[k] = torque(k * dt_s, qs[k], plant.qd)
            if k < n:
                plant.step(taus[k], dt_s)
        return {"q": qs, "tau": taus}
    raise ValueError(f"engine must be 'analytic' or 'pymunk', got {engine!r}")


def check(dt_s: float = 1e-3, p: TrackerInertia | None = None) -> dict[str, Any]:
    """Run the reference moves (:func:`reference_moves`) on both plants and compare.

    Per move and axis: torque RMS difference in % of that axis's peak |τ|
    (axes that carry no torque in either plant are skipped) and angle RMS
    difference [mrad]; the move's figures are the worse axis, the top-level
    figures the worst move (of all three, the coupled one included).

    Parameters
    ----------
    dt_s : float
        Step of both plants [s] (the criterion of issue 11 is at 1 ms).
    p : TrackerInertia, optional
        Default: seed 002, Table 1.

    Returns
    -------
    dict
        ``torque_rms_diff_pct_of_peak``, ``angle_rms_diff_mrad``, ``dt_s`` and
        ``moves``: a list of dicts with ``name``, the same two figures,
        ``peak_torque_azimuth_nm``, ``peak_torque_elevation_nm``,
        ``peak_torque_nm`` and ``duration_s``.
    """
    if not (math.isfinite(dt_s) and 0 < dt_s <= 0.05):
        raise ValueError(f"dt_s must be in (0, 0.05] s, got {dt_s}")
    p = TrackerInertia.seed002() if p is None else p
    results = []
    for move in reference_moves(dt_s):
        a = run_move(move["q_ref"], move["qd_ref"], dt_s, p, "analytic")
        b = run_move(move["q_ref"], move["qd_ref"], dt_s, p, "pymunk")
        peak = np.max(np.abs(a["tau"]), axis=0)
        torque_pct = [
            100.0 * float(np.sqrt(np.mean((a["tau"][:, j] - b["tau"][:, j]) ** 2))) / peak[j]
            for j in range(2)
            if peak[j] > 1e-9
        ]
        angle_mrad = 1e3 * np.sqrt(np.mean((a["q"] - b["q"]) ** 2, axis=0))
        results.append(
            {
                "name": move["name"],
                "torque_rms_diff_pct_of_peak": max(torque_pct),
                "angle_rms_diff_mrad": float(np.max(angle_mrad)),
                "peak_torque_azimuth_nm": float(peak[0]),
                "peak_torque_elevation_nm": float(peak[1]),
                "peak_torque_nm": float(np.max(peak)),
                "duration_s": (len(move["q_ref"]) - 1) * dt_s,
            }
        )
    return {
        "torque_rms_diff_pct_of_peak": max(m["torque_rms_diff_pct_of_peak"] for m in results),
        "angle_rms_diff_mrad": max(m["angle_rms_diff_mrad"] for m in results),
        "dt_s": dt_s,
        "moves": results,
    }


def elevation_hold(
    elevation_deg: float,
    p: TrackerInertia | None = None,
    kp: float = KP_SEED002,
    kd: float = KD_SEED002,
    ki: float = 0.0,
    gravity_compensation: bool = False,
    duration_s: float = 30.0,
    dt_s: float = 5e-3,
    engine: str = "analytic",
) -> float:
    """Elevation error after holding a pose under a PID, started at rest on target.

    Parameters
    ----------
    elevation_deg : float
        Commanded elevation [°].
    p : TrackerInertia, optional
    kp, kd, ki : float
        Gains [N m rad⁻¹], [N m s rad⁻¹], [N m rad⁻¹ s⁻¹].
    gravity_compensation : bool
        Add Ĝ(q) to the torque.
    duration_s, dt_s : float
        Simulated time and step [s].
    engine : {"analytic", "pymunk"}

    Returns
    -------
    float
        Actual minus commanded elevation at the end [°] (> 0: the panel tipped
        up, as it does with cg2 < 0).
    """
    p = TrackerInertia.seed002() if p is None else p
    n = int(round(duration_s / dt_s))
    q_ref = np.tile([0.0, math.radians(elevation_deg)], (n + 1, 1))
    ctrl = JointController(
        q_ref, np.zeros_like(q_ref), dt_s, p, kp=kp, kd=kd, ki=ki,
        gravity_compensation=gravity_compensation,
    )
    out = run_move(q_ref, np.zeros_like(q_ref), dt_s, p, engine, ctrl)
    return math.degrees(float(out["q"][-1, 1] - q_ref[-1, 1]))


def gravity_hold_study(p: TrackerInertia | None = None) -> dict[str, Any]:
    """Seed 002's PD alone vs PD + gravity compensation vs PID, holding 9.9° and 60°.

    Returns
    -------
    dict
        Per elevation (``"9.9"``, ``"60.0"``): the final error [°] of
        ``pd_analytic``, ``pd_pymunk`` (the same PD in the second engine),
        ``pd_equilibrium`` (the root of Kp e = −G2(q), no simulation),
        ``pd_gravity`` (PD + Ĝ) and ``pid_30s``/``pid_120s`` (Ki = 5, no Ĝ).
    """
    p = TrackerInertia.seed002() if p is None else p
    out: dict[str, Any] = {"kp": KP_SEED002, "kd": KD_SEED002, "ki_pid": 5.0}
    for el in (9.9, 60.0):
        target = math.radians(el)
        # static equilibrium of PD alone: Kp (q_ref − q) = G2(q), bisection
        lo, hi = target, target + abs(p.m2_kg * p.g_m_s2 * p.cg2_m) / KP_SEED002
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if KP_SEED002 * (target - mid) - float(gravity(mid, p)[1]) > 0:
                lo = mid
            else:
                hi = mid
        out[f"{el:.1f}"] = {
            "pd_analytic": elevation_hold(el, p),
            "pd_pymunk": elevation_hold(el, p, engine="pymunk"),
            "pd_equilibrium": math.degrees(0.5 * (lo + hi) - target),
            "pd_gravity": elevation_hold(el, p, gravity_compensation=True),
            "pid_30s": elevation_hold(el, p, ki=5.0, duration_s=30.0),
            "pid_120s": elevation_hold(el, p, ki=5.0, duration_s=120.0),
        }
    return out
