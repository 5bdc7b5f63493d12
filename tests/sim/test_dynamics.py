"""sim.dynamics against an independent derivation, seed 002's numbers and the
structural properties of a Lagrangian system (never the module against itself).

The independent derivation is a sympy Lagrangian built here from the standard
D–H matrices and the rigid-body kinetic energy ½ m v·v + ½ ωᵀ (R I Rᵀ) ω of each
link, with ω taken from Ṙ Rᵀ — no use of eq. 24 or of the module's formulas.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from sim.dynamics import (
    TrackerInertia,
    coriolis_centrifugal,
    coriolis_matrix,
    forward_dynamics,
    gravity,
    inverse_dynamics,
    joint_acceleration,
    kinetic_energy,
    mass_matrix,
    move_profile,
    potential_energy,
    trapezoid_duration,
    trapezoid_motion,
)

# seed 002, section II-A and Table 1 (../shared/reference/seed002_dynamics.json)
D1_M, A2_M = 0.355, 0.091
M1, M2 = 4.23619, 37.73207
I1 = (0.05026, 0.00679, 0.05006)
I2 = (11.36103, 3.02971, 8.42094)
CG1_M, CG2_M = -0.17008, -0.02895
G = 9.81

P = TrackerInertia.seed002()


def test_seed002_parameters_are_table_1() -> None:
    assert (P.m1_kg, P.m2_kg) == (M1, M2)
    assert (P.i11_kg_m2, P.i12_kg_m2, P.i13_kg_m2) == I1
    assert (P.i21_kg_m2, P.i22_kg_m2, P.i23_kg_m2) == I2
    assert (P.cg1_m, P.cg2_m, P.g_m_s2) == (CG1_M, CG2_M, G)


def _dh(sp, theta, d, a, alpha):  # standard D–H, written out here independently
    ct, st, ca, sa = sp.cos(theta), sp.sin(theta), sp.cos(alpha), sp.sin(alpha)
    return sp.Matrix(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0, sa, ca, d],
            [0, 0, 0, 1],
        ]
    )


@functools.cache
def _sympy_tau():
    """τ(q1, q2, q̇1, q̇2, q̈1, q̈2) from L = K − U and Lagrange's equations (seed 002, eq. 4).

    τ_i = Σ_j ∂²L/∂q̇_i∂q̇_j q̈_j + Σ_j ∂²L/∂q̇_i∂q_j q̇_j − ∂L/∂q_i (the total time
    derivative written out, so plain symbols suffice). sympy is a test-only
    dependency; without it only these tests are skipped.
    """
    sp = pytest.importorskip("sympy")
    q = sp.symbols("q1 q2")
    w = sp.symbols("w1 w2")
    acc = sp.symbols("a1 a2")
    a1 = _dh(sp, q[0], D1_M, 0, sp.pi / 2)
    t02 = a1 * _dh(sp, q[1], 0, A2_M, 0)
    r1, r2 = a1[:3, :3], t02[:3, :3]
    o1 = a1[:3, 3]
    # centres of gravity: link 1 along y1 (on the azimuth axis), link 2 along x2
    # from the elevation axis (the reading of cg_i that seed 002 uses)
    p1 = o1 + CG1_M * r1[:, 1]
    p2 = o1 + CG2_M * r2[:, 0]
    kinetic = sp.Integer(0)
    potential = sp.Integer(0)
    for m, inertia, rot, pos in ((M1, I1, r1, p1), (M2, I2, r2, p2)):
        rdot = sum((rot.diff(qi) * wi for qi, wi in zip(q, w, strict=True)), sp.zeros(3, 3))
        w_skew = rdot * rot.T
        omega = sp.Matrix([w_skew[2, 1], w_skew[0, 2], w_skew[1, 0]])
        v = pos.jacobian(sp.Matrix(q)) * sp.Matrix(w)
        i_world = rot * sp.diag(*inertia) * rot.T
        kinetic += sp.Rational(1, 2) * (m * (v.T * v)[0] + (omega.T * i_world * omega)[0])
        potential += m * G * pos[2]
    lag = sp.expand(kinetic - potential)
    taus = []
    for i in range(2):
        dl_dw = sp.diff(lag, w[i])
        taus.append(
            sum(sp.diff(dl_dw, w[j]) * acc[j] + sp.diff(dl_dw, q[j]) * w[j] for j in range(2))
            - sp.diff(lag, q[i])
        )
    return sp.lambdify((*q, *w, *acc), taus, "numpy")


STATES = np.random.default_rng(11).uniform(
    [-np.pi, -0.2, -0.5, -0.5, -2.0, -2.0], [np.pi, 1.7, 0.5, 0.5, 2.0, 2.0], size=(40, 6)
)


def test_inverse_dynamics_matches_independent_lagrangian() -> None:
    tau_ref = _sympy_tau()
    q1, q2, w1, w2, a1, a2 = STATES.T
    ref1, ref2 = (np.broadcast_to(x, q1.shape) for x in tau_ref(q1, q2, w1, w2, a1, a2))
    tau1, tau2 = inverse_dynamics(q2, w1, w2, a1, a2, P)
    np.testing.assert_allclose(tau1, ref1, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(tau2, ref2, rtol=1e-12, atol=1e-12)


def test_terms_separately_match_lagrangian() -> None:
    tau_ref = _sympy_tau()
    q2 = np.linspace(-0.3, 1.6, 9)
    z = np.zeros_like(q2)
    # G = τ at rest; M columns = τ(q̈ = e_i) − G; V = τ(q̈ = 0) − G
    g_ref = np.stack(np.broadcast_arrays(*tau_ref(z, q2, z, z, z, z)), axis=-1)
    np.testing.assert_allclose(gravity(q2, P), g_ref, atol=1e-12)
    m = mass_matrix(q2, P)
    for j in range(2):
        acc = [z + (j == 0), z + (j == 1)]
        col = np.stack(np.broadcast_arrays(*tau_ref(z, q2, z, z, *acc)), axis=-1) - g_ref
        np.testing.assert_allclose(m[..., :, j], col, atol=1e-12)
    w1, w2 = z + 0.3, z - 0.7
    v_ref = np.stack(np.broadcast_arrays(*tau_ref(z, q2, w1, w2, z, z)), axis=-1) - g_ref
    np.testing.assert_allclose(coriolis_centrifugal(q2, w1, w2, P), v_ref, atol=1e-12)


def test_eq24_hand_values_at_seed_pose() -> None:
    # Table 1 numbers put by hand into seed 002's eq. 24 at q2 = 9.9 deg
    q2 = np.radians(9.9)
    c, s = np.cos(q2), np.sin(q2)
    m11 = I1[1] + M2 * CG2_M**2 * c**2 + I2[0] * s**2 + I2[1] * c**2
    assert mass_matrix(q2, P)[0, 0] == pytest.approx(m11, rel=1e-14)
    assert m11 == pytest.approx(3.3135, abs=1e-4)
    assert mass_matrix(q2, P)[1, 1] == pytest.approx(M2 * CG2_M**2 + I2[2], rel=1e-14)
    assert gravity(0.0, P)[1] == pytest.approx(-10.7159, abs=1e-4)  # m2 g cg2


def test_mass_matrix_symmetric_positive_definite() -> None:
    m = mass_matrix(np.linspace(-np.pi, np.pi, 721), P)
    np.testing.assert_array_equal(m, np.swapaxes(m, -1, -2))
    eig = np.linalg.eigvalsh(m)
    assert eig.min() > 0.0
    # M11 spans I12 + I22 + m2 cg2² (normal horizontal) … I12 + I21 (normal vertical)
    assert eig.min() == pytest.approx(I1[1] + I2[1] + M2 * CG2_M**2, rel=1e-12)


def test_mdot_minus_2c_skew_symmetric() -> None:
    rng = np.random.default_rng(2)
    for q2, w1, w2 in rng.uniform([-1.5, -1, -1], [1.5, 1, 1], size=(20, 3)):
        h = 1e-6
        # Ṁ = ∂M/∂q2 · q̇2 by central finite differences
        mdot = (mass_matrix(q2 + h, P) - mass_matrix(q2 - h, P)) / (2 * h) * w2
        n = mdot - 2.0 * coriolis_matrix(q2, w1, w2, P)
        np.testing.assert_allclose(n, -n.T, atol=1e-8)
        # and C q̇ is the V vector of eq. 24
        np.testing.assert_allclose(
            coriolis_matrix(q2, w1, w2, P) @ [w1, w2], coriolis_centrifugal(q2, w1, w2, P),
            atol=1e-14,
        )


def test_unforced_energy_conserved_under_rk4() -> None:
    q, qd = forward_dynamics([0.0, 0.4], [0.8, -0.5], lambda t, q, qd: np.zeros(2), 1e-3, 3000, P)
    energy = kinetic_energy(q[:, 1], qd[:, 0], qd[:, 1], P) + potential_energy(q[:, 1], P)
    assert np.ptp(energy) < 1e-9 * (abs(energy[0]) + 1.0)
    # the motion is not trivial: the panel swings and the azimuth rate changes
    assert np.ptp(q[:, 1]) > 0.5 and np.ptp(qd[:, 0]) > 0.1


def test_unforced_angular_momentum_about_vertical_conserved() -> None:
    # q1 is cyclic: p1 = M11(q2) q̇1 is constant (Noether), a check of V1
    q, qd = forward_dynamics([0.0, 1.0], [0.5, 0.0], lambda t, q, qd: np.zeros(2), 1e-3, 3000, P)
    p1 = mass_matrix(q[:, 1], P)[:, 0, 0] * qd[:, 0]
    assert np.ptp(p1) < 1e-10
    assert np.ptp(qd[:, 0]) > 0.1


def test_inverse_of_forward_recovers_torque() -> None:
    def torque(t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return np.array([0.4 * np.sin(2 * t), 2.0 * np.cos(t)])

    dt = 1e-3
    q, qd = forward_dynamics([0.0, 0.3], [0.0, 0.0], torque, dt, 2000, P)
    # over step k the torque is held: the mean acceleration over the step,
    # taken at the step's midpoint state, must give back the held torque
    qdd = np.diff(qd, axis=0) / dt
    qm, qdm = 0.5 * (q[1:] + q[:-1]), 0.5 * (qd[1:] + qd[:-1])
    tau1, tau2 = inverse_dynamics(qm[:, 1], qdm[:, 0], qdm[:, 1], qdd[:, 0], qdd[:, 1], P)
    held = np.array([torque(k * dt, q[k], qd[k]) for k in range(2000)])
    np.testing.assert_allclose(tau1, held[:, 0], atol=1e-6)
    np.testing.assert_allclose(tau2, held[:, 1], atol=1e-6)
    assert np.ptp(q[:, 0]) > 0.05 and np.ptp(q[:, 1]) > 0.05


def test_joint_acceleration_inverts_inverse_dynamics() -> None:
    q1, q2, w1, w2, a1, a2 = STATES.T
    tau1, tau2 = inverse_dynamics(q2, w1, w2, a1, a2, P)
    b1, b2 = joint_acceleration(q2, w1, w2, tau1, tau2, P)
    np.testing.assert_allclose(b1, a1, atol=1e-12)
    np.testing.assert_allclose(b2, a2, atol=1e-12)


def test_pendulum_period_about_elevation_axis() -> None:
    # small swings of the unbraked panel about its stable pose (CoG below the
    # axis: cg2 < 0 along x2 ⇒ stable at q2 = +90°): T = 2π sqrt(M22 / (m2 g |cg2|))
    expected = 2 * np.pi * np.sqrt((M2 * CG2_M**2 + I2[2]) / (M2 * G * abs(CG2_M)))
    dt = 1e-3
    q, _ = forward_dynamics(
        [0.0, np.pi / 2 + 0.01], [0.0, 0.0], lambda t, q, qd: np.zeros(2), dt, 12000, P
    )
    x = q[:, 1] - np.pi / 2
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    frac = -x[up] / (x[up + 1] - x[up])
    crossings = (up + frac) * dt
    period = np.mean(np.diff(crossings))
    assert period == pytest.approx(expected, rel=1e-4)


def test_nan_propagates_and_bad_input_raises() -> None:
    assert np.isnan(inverse_dynamics(np.nan, 0, 0, 0, 0, P)[1])
    with pytest.raises(ValueError, match="dt_s"):
        forward_dynamics([0, 0], [0, 0], lambda t, q, qd: np.zeros(2), 0.0, 10, P)
    with pytest.raises(ValueError, match="2 elements"):
        forward_dynamics([0, 0, 0], [0, 0], lambda t, q, qd: np.zeros(2), 1e-3, 10, P)
    with pytest.raises(ValueError, match="2 values"):
        forward_dynamics([0, 0], [0, 0], lambda t, q, qd: np.zeros(3), 1e-3, 10, P)
    with pytest.raises(ValueError, match="masses"):
        TrackerInertia(0, 1, 1, 1, 1, 1, 1, 1, 0, 0)


@pytest.mark.parametrize("delta", [2.243, -0.8, 0.01])
def test_move_profile_trapezoid(delta: float) -> None:
    rate, accel, dt = 0.1, 0.05, 1e-3
    t, q, qd, qdd = move_profile(delta, rate, accel, dt)
    assert q[0] == 0.0 and q[-1] == pytest.approx(delta, abs=1e-15)
    assert qd[0] == 0.0 and qd[-1] == 0.0
    assert np.abs(qd).max() <= rate + 1e-15
    assert np.abs(qdd).max() <= accel
    # the rate integrates to the displacement and the acceleration to the rate
    np.testing.assert_allclose(np.trapezoid(qd, t), delta, rtol=1e-4)
    np.testing.assert_allclose(np.gradient(q, t)[1:-1], qd[1:-1], atol=accel * dt)
    dist = abs(delta)
    v = min(rate, np.sqrt(dist * accel))
    assert t[-1] == pytest.approx(dist / v + v / accel, abs=dt)


def test_move_profile_zero_and_errors() -> None:
    t, q, qd, qdd = move_profile(0.0, 0.1, 0.05, 1e-3)
    assert t.shape == (1,) and q[0] == 0.0
    with pytest.raises(ValueError, match="max_rate"):
        move_profile(1.0, 0.0, 0.05, 1e-3)
    with pytest.raises(ValueError, match="delta"):
        move_profile(float("nan"), 0.1, 0.05, 1e-3)


def test_trapezoid_motion_is_the_profile_of_every_caller() -> None:
    """One profile for a batch of moves at arbitrary times: rest before 0 and at Δ from the
    end on, the rate integrates to the displacement, and move_profile samples it exactly."""
    rate, accel = 0.05, 0.1
    deltas = np.array([-0.7, -0.01, 0.0, 1e-4, 0.02, 0.025, 0.3, 2.0])  # triangles and trapezoids
    ends = trapezoid_duration(deltas, rate, accel)
    peak = np.minimum(rate, np.sqrt(np.abs(deltas) * accel))
    np.testing.assert_allclose(ends, np.where(peak > 0, np.abs(deltas) / np.where(peak > 0, peak, 1)
                                              + peak / accel, 0.0), rtol=1e-15)
    t = np.linspace(-1.0, ends.max() + 1.0, 200_001)
    q, qd, qdd = trapezoid_motion(deltas[:, None], rate, accel, t[None, :])
    assert q.shape == qd.shape == qdd.shape == (deltas.size, t.size)
    np.testing.assert_array_equal(q[:, t < 0], 0.0)
    after = t[None, :] >= ends[:, None]
    np.testing.assert_array_equal(q[after], np.broadcast_to(deltas[:, None], q.shape)[after])
    assert np.all(np.abs(q) <= np.abs(deltas)[:, None])
    assert np.all(np.abs(qd) <= rate) and np.all(np.abs(qdd) <= accel)
    dt = t[1] - t[0]
    for k, d in enumerate(deltas):
        # the rate's running integral is the displacement (to the trapezoid rule's error)
        integral = np.concatenate([[0.0], np.cumsum(0.5 * (qd[k, 1:] + qd[k, :-1])) * dt])
        np.testing.assert_allclose(integral, q[k], atol=accel * dt**2 + 1e-15)
        tk, qk, qdk, qddk = move_profile(float(d), rate, accel, 0.01)
        qq, qqd, qqdd = trapezoid_motion(float(d), rate, accel, tk)
        np.testing.assert_array_equal(qq, qk)
        np.testing.assert_array_equal(qqd, qdk)
        np.testing.assert_array_equal(qqdd, qddk)
