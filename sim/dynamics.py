"""Rigid-body dynamics of the dual-axis tracker as a 2-DOF manipulator.

Seed 002 (Fernández-Pizarro, Beltrán-González & Roldán-Mckinley 2019,
"Dynamic Modelling of an Orientable Solar Panel System as a 2-DOF
Manipulator", Scientia et Technica 24(2) 212–217), eq. 24 with Table 1:

    τ = M(q) q̈ + V(q, q̇) + G(q)

with q1 the azimuth joint and q2 the elevation joint (0 = the panel normal
x2 horizontal), both in radians inside this module, torques in N m.

Derivation (re-done here, not copied)
-------------------------------------
Kinematics are seed 002's D–H table (d1 = 355 mm, a2 = 91 mm, α1 = 90°) with
the *standard* D–H link transform
``A_i = Rot(z, θ_i) Trans(z, d_i) Trans(x, a_i) Rot(x, α_i)`` — the same as
:func:`sim.kinematics.dh_transform`. Its rotation part gives
``⁰R₂ = [[c1 c2, −c1 s2, s1], [s1 c2, −s1 s2, −c1], [s2, c2, 0]]`` (seed 002,
eq. 2, which is right). Then:

* link 1 turns about z0 (vertical); in its own frame z0 is y1, so its kinetic
  energy is ½ I12 q̇1². Its centre of gravity cg1 = −170.08 mm is read as an
  offset along y1, i.e. *on* the azimuth axis: it adds a constant potential
  and nothing to M (eq. 24 has no m1 term, which only this reading gives).
* link 2's angular velocity is ω2 = q̇1 z0 + q̇2 z1; in frame {2} it is
  (q̇1 s2, q̇1 c2, q̇2). Its centre of gravity is read, as eq. 24 implies, at a
  signed distance cg2 = −28.95 mm along x2 *from the elevation axis* (the
  origin of frame {1}, not of frame {2}: a2 does not enter eq. 24). It moves on
  a circle of radius |cg2 c2| about the azimuth axis at height cg2 s2 above the
  elevation axis.

Kinetic energy ``K = ½ M11(q2) q̇1² + ½ M22 q̇2²`` and potential energy
``U = m2 g cg2 s2`` (+ const.) give, with A = m2 cg2² + I22 − I21,

* M11 = I12 + m2 cg2² c2² + I21 s2² + I22 c2²,  M22 = m2 cg2² + I23, M12 = 0;
* V1 = −2 A s2 c2 q̇1 q̇2,  V2 = A s2 c2 q̇1²;
* G1 = 0,  G2 = m2 g cg2 c2,

which is seed 002's eq. 24 exactly. The independent check is
``tests/sim/test_dynamics.py`` (a sympy Lagrangian built from the D–H matrices
and the rigid-body kinetic energy of each link) and :mod:`sim.dynamics_check`
(pymunk as a second engine).

Corrections to the seed's text (eq. 24 itself is consistent):

* eq. 1: the printed D–H matrix mixes the joint and twist angles (``−cα sα``,
  ``cα sα``, ``−sα s_i``, ``s_i c_i`` in row 3); the standard matrix above is
  what reproduces its own eq. 2.
* eq. 18: the Christoffel form is
  ``V_i = Σ_j Σ_k (∂M_ij/∂q_k − ½ ∂M_jk/∂q_i) q̇_j q̇_k``; the printed
  ``∂M_ij/∂q_j`` would drop V1 here (M11 depends on q2, not on q1).
* eq. 20: gravity sums over the links, ``G_i = −Σ_j m_j gᵀ J_vj^(i)`` (mass
  index j, column i of link j's Jacobian); the printed ``m_i`` mixes indices.
* the text says there are "no Coriolis terms ... but centrifugal"; V1 ∝ q̇1 q̇2
  *is* a Coriolis term (a product of two different joint rates), V2 ∝ q̇1² is
  centrifugal. The "revolute joints only" argument does not hold.

Eq. 8 reading: eq. 8 writes ``ⁱIᵢ = m_i diag(...)``; the inertias of Table 1 are
used **in kg m² as printed** (not multiplied by m_i). Multiplying would give
I21 = 429 kg m² for a 38 kg panel; as printed, I21 ≈ I22 + I23 (11.36 vs
11.45 kg m²) is the perpendicular-axis theorem of a flat plate with the normal
along x2, as a panel should be.

Sign conventions: the equations are unchanged under q1 → −q1 (with τ1 → −τ1),
so q1 may be the D–H angle (counter-clockwise from east) or the public azimuth
(clockwise from north) — τ1 then follows the same sense. τ2 > 0 raises the
normal. With cg2 < 0 the centre of gravity is behind the elevation axis, so
gravity *raises* an unbraked panel (G2 < 0 at q2 = 0).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "TrackerInertia",
    "mass_matrix",
    "coriolis_matrix",
    "coriolis_centrifugal",
    "gravity",
    "inverse_dynamics",
    "joint_acceleration",
    "kinetic_energy",
    "potential_energy",
    "forward_dynamics",
    "move_profile",
    "trapezoid_motion",
    "trapezoid_duration",
    "TorqueFn",
]

#: Controller callback for :func:`forward_dynamics`: ``torque(t_s, q, qd)`` →
#: ``ndarray(2)`` of joint torques [N m], held constant over the step.
TorqueFn = Callable[[float, NDArray[np.float64], NDArray[np.float64]], ArrayLike]


@dataclass(frozen=True)
class TrackerInertia:
    """Masses, inertias and centres of gravity of the two links.

    Parameters
    ----------
    m1_kg, m2_kg : float
        Masses of link 1 (azimuth carriage) and link 2 (elevation frame +
        panel) [kg].
    i11_kg_m2, i12_kg_m2, i13_kg_m2 : float
        Principal inertias of link 1 about its centre of gravity, along x1,
        y1, z1 [kg m²]; y1 is the (vertical) azimuth axis, so only ``i12``
        enters the dynamics.
    i21_kg_m2, i22_kg_m2, i23_kg_m2 : float
        Principal inertias of link 2 about its centre of gravity, along x2
        (the panel normal), y2 and z2 (the elevation axis) [kg m²].
    cg1_m : float
        Centre of gravity of link 1 along y1, on the azimuth axis [m]
        (no dynamic effect; kept for completeness).
    cg2_m : float
        Signed centre of gravity of link 2 along x2, from the elevation axis [m].
    g_m_s2 : float
        Gravitational acceleration [m s⁻²] (seed 002, eq. 17: 9.81).
    """

    m1_kg: float
    m2_kg: float
    i11_kg_m2: float
    i12_kg_m2: float
    i13_kg_m2: float
    i21_kg_m2: float
    i22_kg_m2: float
    i23_kg_m2: float
    cg1_m: float
    cg2_m: float
    g_m_s2: float = 9.81

    def __post_init__(self) -> None:
        values = {name: getattr(self, name) for name in self.__dataclass_fields__}
        bad = [name for name, v in values.items() if not math.isfinite(float(v))]
        if bad:
            raise ValueError(f"TrackerInertia: non-finite {', '.join(bad)}")
        if self.m1_kg <= 0 or self.m2_kg <= 0:
            raise ValueError(f"masses must be > 0 kg, got {self.m1_kg}, {self.m2_kg}")
        inertias = ("i11_kg_m2", "i12_kg_m2", "i13_kg_m2", "i21_kg_m2", "i22_kg_m2", "i23_kg_m2")
        negative = [name for name in inertias if values[name] < 0]
        if negative:
            raise ValueError(f"inertias must be >= 0 kg m2: {', '.join(negative)}")
        if self.g_m_s2 < 0:
            raise ValueError(f"g_m_s2 must be >= 0, got {self.g_m_s2}")

    @classmethod
    def seed002(cls) -> TrackerInertia:
        """Seed 002, Table 1 (``../shared/reference/seed002_dynamics.json``);
        inertias in kg m² as printed, centres of gravity converted mm → m."""
        return cls(
            m1_kg=4.23619,
            m2_kg=37.73207,
            i11_kg_m2=0.05026,
            i12_kg_m2=0.00679,
            i13_kg_m2=0.05006,
            i21_kg_m2=11.36103,
            i22_kg_m2=3.02971,
            i23_kg_m2=8.42094,
            cg1_m=-0.17008,
            cg2_m=-0.02895,
        )

    @property
    def m22_kg_m2(self) -> float:
        """Constant elevation inertia about the elevation axis, M22 [kg m²]."""
        return self.m2_kg * self.cg2_m**2 + self.i23_kg_m2

    @property
    def coupling_kg_m2(self) -> float:
        """A = m2 cg2² + I22 − I21 [kg m²], the factor of V1, V2 and M11's q2 dependence."""
        return self.m2_kg * self.cg2_m**2 + self.i22_kg_m2 - self.i21_kg_m2


def _f(x: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(x, dtype=float)


def mass_matrix(q2: ArrayLike, p: TrackerInertia) -> NDArray[np.float64]:
    """Inertia matrix M(q2) (seed 002, eq. 24, first matrix).

    Parameters
    ----------
    q2 : array_like
        Elevation joint [rad], any shape ``S``.
    p : TrackerInertia

    Returns
    -------
    ndarray, shape ``S + (2, 2)``
        [kg m²]; diagonal (M12 = 0 for this geometry).
    """
    q = _f(q2)
    c, s = np.cos(q), np.sin(q)
    out = np.zeros(q.shape + (2, 2))
    # seed 002, eq. 24: M11 = I12 + m2 cg2² c2² + I21 s2² + I22 c2²
    out[..., 0, 0] = (
        p.i12_kg_m2 + p.m2_kg * p.cg2_m**2 * c**2 + p.i21_kg_m2 * s**2 + p.i22_kg_m2 * c**2
    )
    out[..., 1, 1] = p.m22_kg_m2  # M22 = m2 cg2² + I23
    return out


def coriolis_matrix(
    q2: ArrayLike, qd1: ArrayLike, qd2: ArrayLike, p: TrackerInertia
) -> NDArray[np.float64]:
    """Coriolis/centrifugal matrix C(q, q̇) from the Christoffel symbols, V = C q̇.

    With this C, Ṁ − 2C is skew-symmetric (the passivity property controllers
    rely on). Corrected seed 002 eq. 18 (module docstring):
    ``C_ij = Σ_k ½ (∂M_ij/∂q_k + ∂M_ik/∂q_j − ∂M_jk/∂q_i) q̇_k``.

    Parameters
    ----------
    q2 : array_like
        Elevation joint [rad].
    qd1, qd2 : array_like
        Joint rates [rad s⁻¹]; broadcast together with ``q2`` to shape ``S``.
    p : TrackerInertia

    Returns
    -------
    ndarray, shape ``S + (2, 2)``
        [kg m² s⁻¹].
    """
    q, w1, w2 = np.broadcast_arrays(_f(q2), _f(qd1), _f(qd2))
    h = p.coupling_kg_m2 * np.sin(q) * np.cos(q)  # −½ ∂M11/∂q2
    out = np.zeros(q.shape + (2, 2))
    out[..., 0, 0] = -h * w2
    out[..., 0, 1] = -h * w1
    out[..., 1, 0] = h * w1
    return out


def coriolis_centrifugal(
    q2: ArrayLike, qd1: ArrayLike, qd2: ArrayLike, p: TrackerInertia
) -> NDArray[np.float64]:
    """Coriolis and centrifugal torques V(q, q̇) (seed 002, eq. 24, second vector).

    V1 = −2 A s2 c2 q̇1 q̇2 (Coriolis), V2 = A s2 c2 q̇1² (centrifugal), with
    A = m2 cg2² + I22 − I21.

    Parameters
    ----------
    q2 : array_like
        Elevation joint [rad].
    qd1, qd2 : array_like
        Joint rates [rad s⁻¹]; broadcast with ``q2`` to shape ``S``.
    p : TrackerInertia

    Returns
    -------
    ndarray, shape ``S + (2,)``
        [N m].
    """
    q, w1, w2 = np.broadcast_arrays(_f(q2), _f(qd1), _f(qd2))
    h = p.coupling_kg_m2 * np.sin(q) * np.cos(q)
    return np.stack([-2.0 * h * w1 * w2, h * w1**2], axis=-1)


def gravity(q2: ArrayLike, p: TrackerInertia) -> NDArray[np.float64]:
    """Gravity torques G(q) (seed 002, eq. 24, third vector): G1 = 0, G2 = m2 g cg2 c2.

    Parameters
    ----------
    q2 : array_like
        Elevation joint [rad], shape ``S``.
    p : TrackerInertia

    Returns
    -------
    ndarray, shape ``S + (2,)``
        [N m]; the torque the motors must supply to hold the pose.
    """
    q = _f(q2)
    g2 = p.m2_kg * p.g_m_s2 * p.cg2_m * np.cos(q)
    return np.stack([np.zeros_like(g2), g2], axis=-1)


def inverse_dynamics(
    q2: ArrayLike,
    qd1: ArrayLike,
    qd2: ArrayLike,
    qdd1: ArrayLike,
    qdd2: ArrayLike,
    p: TrackerInertia,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Joint torques for a motion, τ = M q̈ + V + G (seed 002, eqs. 5 and 24).

    Parameters
    ----------
    q2 : array_like
        Elevation joint [rad].
    qd1, qd2 : array_like
        Azimuth and elevation rates [rad s⁻¹].
    qdd1, qdd2 : array_like
        Azimuth and elevation accelerations [rad s⁻²].
    p : TrackerInertia

    Returns
    -------
    tau_azimuth, tau_elevation : ndarray
        Broadcast shape of the inputs [N m].
    """
    q, w1, w2, a1, a2 = np.broadcast_arrays(_f(q2), _f(qd1), _f(qd2), _f(qdd1), _f(qdd2))
    m = mass_matrix(q, p)
    v = coriolis_centrifugal(q, w1, w2, p)
    g = gravity(q, p)
    tau1 = m[..., 0, 0] * a1 + m[..., 0, 1] * a2 + v[..., 0] + g[..., 0]
    tau2 = m[..., 1, 0] * a1 + m[..., 1, 1] * a2 + v[..., 1] + g[..., 1]
    return tau1, tau2


def joint_acceleration(
    q2: ArrayLike,
    qd1: ArrayLike,
    qd2: ArrayLike,
    tau1: ArrayLike,
    tau2: ArrayLike,
    p: TrackerInertia,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Forward dynamics at one state, q̈ = M⁻¹ (τ − V − G) (seed 002, eq. 23).

    Parameters
    ----------
    q2 : array_like
        Elevation joint [rad].
    qd1, qd2 : array_like
        Joint rates [rad s⁻¹].
    tau1, tau2 : array_like
        Azimuth and elevation joint torques [N m].
    p : TrackerInertia

    Returns
    -------
    qdd1, qdd2 : ndarray
        Joint accelerations [rad s⁻²].
    """
    q, w1, w2, t1, t2 = np.broadcast_arrays(_f(q2), _f(qd1), _f(qd2), _f(tau1), _f(tau2))
    m = mass_matrix(q, p)
    rhs = np.stack([t1, t2], axis=-1) - coriolis_centrifugal(q, w1, w2, p) - gravity(q, p)
    acc = np.asarray(np.linalg.solve(m, rhs[..., None])[..., 0], dtype=float)
    return acc[..., 0], acc[..., 1]


def kinetic_energy(
    q2: ArrayLike, qd1: ArrayLike, qd2: ArrayLike, p: TrackerInertia
) -> NDArray[np.float64]:
    """Kinetic energy ½ q̇ᵀ M q̇ of both links [J] (seed 002, eqs. 6 and 16)."""
    q, w1, w2 = np.broadcast_arrays(_f(q2), _f(qd1), _f(qd2))
    m = mass_matrix(q, p)
    return 0.5 * (m[..., 0, 0] * w1**2 + m[..., 1, 1] * w2**2)


def potential_energy(q2: ArrayLike, p: TrackerInertia) -> NDArray[np.float64]:
    """Potential energy of link 2 relative to the height of the elevation axis,
    U = m2 g cg2 s2 [J] (seed 002, eq. 17; link 1's is constant and left out)."""
    return p.m2_kg * p.g_m_s2 * p.cg2_m * np.sin(_f(q2))


def _rk4_step(
    q1: float,
    q2: float,
    w1: float,
    w2: float,
    t1: float,
    t2: float,
    dt: float,
    k: tuple[float, float, float, float, float, float],
) -> tuple[float, float, float, float]:
    """One RK4 step of the scalar state with the torque held (zero-order hold).

    ``k`` = (I12, I21, I22, m2 cg2², M22, m2 g cg2); the same equations as
    :func:`joint_acceleration`, unrolled in floats for speed.
    """
    i12, i21, i22, mc2, m22, mgc = k
    a = mc2 + i22 - i21

    def acc(qq2: float, ww1: float, ww2: float) -> tuple[float, float]:
        c, s = math.cos(qq2), math.sin(qq2)
        m11 = i12 + mc2 * c * c + i21 * s * s + i22 * c * c
        h = a * s * c
        return (t1 + 2.0 * h * ww1 * ww2) / m11, (t2 - h * ww1 * ww1 - mgc * c) / m22

    a1, b1 = acc(q2, w1, w2)
    a2, b2 = acc(q2 + 0.5 * dt * w2, w1 + 0.5 * dt * a1, w2 + 0.5 * dt * b1)
    a3, b3 = acc(q2 + 0.5 * dt * (w2 + 0.5 * dt * b1), w1 + 0.5 * dt * a2, w2 + 0.5 * dt * b2)
    a4, b4 = acc(q2 + dt * (w2 + 0.5 * dt * b2), w1 + dt * a3, w2 + dt * b3)
    # position derivatives at the four stages are the stage velocities
    v1 = (w1 + 2.0 * (w1 + 0.5 * dt * a1) + 2.0 * (w1 + 0.5 * dt * a2) + (w1 + dt * a3)) / 6.0
    v2 = (w2 + 2.0 * (w2 + 0.5 * dt * b1) + 2.0 * (w2 + 0.5 * dt * b2) + (w2 + dt * b3)) / 6.0
    return (
        q1 + dt * v1,
        q2 + dt * v2,
        w1 + dt * (a1 + 2.0 * a2 + 2.0 * a3 + a4) / 6.0,
        w2 + dt * (b1 + 2.0 * b2 + 2.0 * b3 + b4) / 6.0,
    )


def forward_dynamics(
    q0: ArrayLike,
    qd0: ArrayLike,
    torque: TorqueFn,
    dt_s: float,
    n_steps: int,
    p: TrackerInertia,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Integrate q̈ = M⁻¹ (τ − V − G) (seed 002, eq. 23) with fixed-step RK4.

    The torque callback is called once per step, at the start of the step,
    with the current time and state, and its value is held over the step (a
    digital controller with a zero-order hold at 1/dt).

    Parameters
    ----------
    q0, qd0 : array_like, shape (2,)
        Initial joint angles [rad] and rates [rad s⁻¹], (azimuth, elevation).
    torque : callable
        ``torque(t_s, q, qd) -> ndarray(2)`` joint torques [N m].
    dt_s : float
        Step [s], > 0.
    n_steps : int
        Number of steps, >= 0.
    p : TrackerInertia

    Returns
    -------
    q, qd : ndarray, shape (n_steps + 1, 2)
        Joint angles [rad] and rates [rad s⁻¹] at ``t = k dt_s``.
    """
    q_init = np.asarray(q0, dtype=float).reshape(-1)
    w_init = np.asarray(qd0, dtype=float).reshape(-1)
    if q_init.shape != (2,) or w_init.shape != (2,):
        raise ValueError(f"q0 and qd0 must have 2 elements, got {q_init.shape}, {w_init.shape}")
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s must be a positive number, got {dt_s}")
    if int(n_steps) != n_steps or n_steps < 0:
        raise ValueError(f"n_steps must be a non-negative integer, got {n_steps}")
    n = int(n_steps)
    k = (
        p.i12_kg_m2,
        p.i21_kg_m2,
        p.i22_kg_m2,
        p.m2_kg * p.cg2_m**2,
        p.m22_kg_m2,
        p.m2_kg * p.g_m_s2 * p.cg2_m,
    )
    q = np.empty((n + 1, 2))
    qd = np.empty((n + 1, 2))
    q[0], qd[0] = q_init, w_init
    q1, q2 = float(q_init[0]), float(q_init[1])
    w1, w2 = float(w_init[0]), float(w_init[1])
    for i in range(n):
        tau = np.asarray(torque(i * dt_s, q[i].copy(), qd[i].copy()), dtype=float).reshape(-1)
        if tau.shape != (2,):
            raise ValueError(f"torque callback must return 2 values, got shape {tau.shape}")
        q1, q2, w1, w2 = _rk4_step(q1, q2, w1, w2, float(tau[0]), float(tau[1]), dt_s, k)
        q[i + 1, 0], q[i + 1, 1] = q1, q2
        qd[i + 1, 0], qd[i + 1, 1] = w1, w2
    return q, qd


def move_profile(
    delta_rad: float, max_rate_rad_s: float, max_accel_rad_s2: float, dt_s: float
) -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
]:
    """Trapezoidal (or, for short moves, triangular) slew profile of one joint.

    Accelerate at ``max_accel`` to ``max_rate``, cruise, decelerate; a move too
    short to reach ``max_rate`` peaks at ``sqrt(|Δ| a)``. Used to cost a move
    (torques from :func:`inverse_dynamics`, energy from :mod:`sim.motors`) and
    as the reference of the cross-check moves (:mod:`sim.dynamics_check`).

    Parameters
    ----------
    delta_rad : float
        Signed displacement [rad].
    max_rate_rad_s : float
        Rate limit [rad s⁻¹], > 0.
    max_accel_rad_s2 : float
        Acceleration limit [rad s⁻²], > 0.
    dt_s : float
        Sample step [s], > 0.

    Returns
    -------
    t, q, qd, qdd : ndarray, shape (n + 1,)
        Time from the start [s] and the displacement from the start [rad],
        rate [rad s⁻¹] and acceleration [rad s⁻²], sampled at ``k dt_s`` up to
        the first sample at or after the end of the move (``q[-1] = delta``).
        A zero move gives one sample at rest.
    """
    for name, value in (
        ("max_rate_rad_s", max_rate_rad_s),
        ("max_accel_rad_s2", max_accel_rad_s2),
        ("dt_s", dt_s),
    ):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value}")
    if not math.isfinite(delta_rad):
        raise ValueError(f"delta_rad must be finite, got {delta_rad}")
    total = float(trapezoid_duration(delta_rad, max_rate_rad_s, max_accel_rad_s2))
    if total == 0.0:
        z = np.zeros(1)
        return z, z.copy(), z.copy(), z.copy()
    n = math.ceil(total / dt_s - 1e-9)
    t = np.arange(n + 1, dtype=float) * dt_s
    q, qd, qdd = trapezoid_motion(delta_rad, max_rate_rad_s, max_accel_rad_s2, t)
    return t, q, qd, qdd


_TINY = float(np.finfo(float).tiny)
_FloatOrArray = float | NDArray[np.float64]


def _trapezoid_phases(
    delta: ArrayLike, max_rate: _FloatOrArray, max_accel: _FloatOrArray
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Peak rate, acceleration time, cruise time and |Δ| of trapezoidal moves (broadcast).

    The peak rate is ``min(max_rate, sqrt(|Δ| max_accel))`` (a triangle when the
    move is too short to reach ``max_rate``); a zero move has all four zero.
    """
    dist: NDArray[np.float64] = np.abs(np.asarray(delta, dtype=float))
    v: NDArray[np.float64] = np.minimum(max_rate, np.sqrt(dist * max_accel))
    ta: NDArray[np.float64] = v / max_accel
    # v = 0 only for a zero move (|Δ| = 0, so tc = 0); any v > 0 is far above _TINY
    tc: NDArray[np.float64] = dist / np.maximum(v, _TINY) - ta
    return v, ta, tc, dist


def trapezoid_duration(delta: ArrayLike, max_rate: _FloatOrArray, max_accel: _FloatOrArray
                       ) -> NDArray[np.float64]:
    """Duration of trapezoidal moves [s] (broadcast; 0 for a zero move).

    ``delta``, ``max_rate`` [per s] and ``max_accel`` [per s²] in one angle unit
    (rad or °): the profile of :func:`trapezoid_motion`.
    """
    _, ta, tc, _ = _trapezoid_phases(delta, max_rate, max_accel)
    return 2.0 * ta + tc


def trapezoid_motion(
    delta: ArrayLike, max_rate: _FloatOrArray, max_accel: _FloatOrArray, t_s: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Displacement, rate and acceleration of trapezoidal moves at ``t_s`` (the one profile).

    Accelerate at ``max_accel`` to the peak rate (see :func:`trapezoid_duration`),
    cruise, decelerate at ``max_accel`` to rest. Every caller — :func:`move_profile`,
    the tracker's axes and the move energies in :mod:`sim.tracking` — evaluates
    this function, so the three cannot drift apart. The rule is unit-agnostic:
    ``delta`` (signed), ``max_rate`` [per s] and ``max_accel`` [per s²] in one
    angle unit (rad or °); all arguments broadcast.

    Parameters
    ----------
    t_s : array_like
        Time since the move's start [s]; before 0 the move has not started
        (rest at 0), at or after the end it is over (rest at ``delta``).

    Returns
    -------
    q, qd, qdd : ndarray
        Signed displacement from the start, rate and acceleration; ``|q|``
        never exceeds ``|delta|``.
    """
    delta_ = np.asarray(delta, dtype=float)
    v, ta, tc, dist = _trapezoid_phases(delta_, max_rate, max_accel)
    a = np.asarray(max_accel, dtype=float)
    t = np.asarray(t_s, dtype=float)
    total = 2.0 * ta + tc
    tt = np.minimum(np.maximum(t, 0.0), total)
    t3 = np.maximum(tt - ta - tc, 0.0)  # time into deceleration
    acc_phase = tt < ta
    dec_phase = tt > ta + tc
    q_acc = 0.5 * a * tt**2
    q_cruise = 0.5 * a * ta**2 + v * (tt - ta)
    q_dec = 0.5 * a * ta**2 + v * tc + v * t3 - 0.5 * a * t3**2
    q = np.where(acc_phase, q_acc, np.where(dec_phase, q_dec, q_cruise))
    qd = np.where(acc_phase, a * tt, np.where(dec_phase, v - a * t3, v))
    qdd = np.where(acc_phase, a, np.where(dec_phase, -a, 0.0))
    done = t >= total
    q = np.where(done, dist, np.minimum(q, dist))
    qd = np.where(done, 0.0, qd)
    qdd = np.where(done, 0.0, qdd)
    sign = np.where(delta_ < 0, -1.0, 1.0)
    return sign * q, sign * qd, sign * qdd
