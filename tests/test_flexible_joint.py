"""Flexible-joint effect, gravity compensators and posture-level linear analysis on small arms,
against seed 000's equations, hand-derived matrices and finite differences."""

import jax
import numpy as np
import pytest

import jflex
from jflex.effects import FlexibleJoints, FourierGravityCompensator, SpringGravityCompensator

_TOL = 1e-9


def planar(n, gravity=(0.0, -9.81, 0.0)):
    """n-link planar arm (z axes, links of 0.5 m along x), each link with mass and inertia."""
    rows = [[0.0, 0.0 if i == 0 else 0.5, 0.0, 0.0] for i in range(n)]
    inertias = [{"mass": 3.0 + i, "com": [0.25, 0.02, 0.0], "inertia": [0.1, 0.0, 0.2, 0.0, 0.0, 0.25]} for i in range(n)]
    return jflex.from_dh(rows, tool=[0.0, 0.5, 0.0, 0.0], inertias=inertias, gravity=gravity)


def test_one_link_augmented_dynamics_match_seed000():
    """J_l q'' + B_l q' + k (q - q_m) = 0, J_m q_m'' + B_m q_m' - k (q - q_m) = u (no gravity)."""
    robot = planar(1, gravity=(0.0, 0.0, -9.81))
    J_l = float(jflex.crba(robot, np.zeros(1))[0, 0])
    k, r, Im, B_l, B_m = 2e4, 50.0, 2e-4, 0.7, 0.3
    fj = FlexibleJoints([k], rotor_inertia=[Im], gear_ratio=[r], link_viscous=[B_l], motor_viscous=[B_m])
    model = jflex.Model(robot, [fj])
    assert model.layout.coord_names == ("joint1", "theta_joint1")
    x, xd, u = np.array([0.3, 0.29]), np.array([0.4, -0.2]), np.array([5.0])
    xdd, _ = jflex.model_forward_dynamics(model, 0.0, x, xd, np.zeros(0), u)
    J_m = r**2 * Im
    ref = [(-B_l * xd[0] - k * (x[0] - x[1])) / J_l, (u[0] - B_m * xd[1] + k * (x[0] - x[1])) / J_m]
    assert np.allclose(xdd, ref, rtol=_TOL)
    tau = jflex.model_inverse_dynamics(model, 0.0, x, xd, xdd, np.zeros(0))
    assert np.allclose(tau, [0.0, u[0]], atol=1e-9)


def test_two_link_mass_matrix_with_rotor_coupling():
    robot = planar(2)
    r, Im = np.array([80.0, 60.0]), np.array([3e-4, 2e-4])
    q = np.array([0.4, -0.9])
    full = jflex.Model(robot, [FlexibleJoints([1e4, 1e4], rotor_inertia=Im, gear_ratio=r)])
    spong = jflex.Model(robot, [FlexibleJoints([1e4, 1e4], rotor_inertia=Im, gear_ratio=r, coupling=False)])
    x = np.concatenate([q, q])
    Mr = np.asarray(jflex.crba(robot, q))
    # rotor 2 rides on link 1 (planar: its spin is r2 theta2' + q1'); rotor 1 on the fixed base
    ref = np.zeros((4, 4))
    ref[:2, :2] = Mr + np.diag([Im[1], 0.0])
    ref[2:, 2:] = np.diag(r**2 * Im)
    ref[0, 3] = ref[3, 0] = Im[1] * r[1]
    assert np.allclose(jflex.mass_matrix(full, x), ref, rtol=_TOL, atol=1e-12)
    ref_s = np.zeros((4, 4))
    ref_s[:2, :2], ref_s[2:, 2:] = Mr, np.diag(r**2 * Im)
    assert np.allclose(jflex.mass_matrix(spong, x), ref_s, rtol=_TOL, atol=1e-12)
    B = np.asarray(jflex.input_matrix(full))
    assert np.allclose(B, [[0, 0], [0, 0], [1, 0], [0, 1]])


def test_held_linearisation_gravity_stiffness_against_finite_differences():
    robot = planar(2)
    K = np.array([3e3, 2e3])
    Bgc = np.array([4.0, -1.0, 0.5])
    model = jflex.Model(robot, [FlexibleJoints(K, [5.0, 3.0]), FourierGravityCompensator(Bgc, joint=1)])
    q = np.array([0.7, -0.4])
    assert jflex.linear.resolve_hold(model, "actuated") == ("theta_joint1", "theta_joint2")
    lin = jax.jit(lambda q: jflex.linear.linearization(model, q, hold="actuated")[1][:3])(q)
    lin = type("Lin", (), dict(M=lin[0], C=lin[1], K=lin[2]))
    h = 1e-6
    dG = np.stack([(np.asarray(jflex.gravity(robot, q + h * e)) - np.asarray(jflex.gravity(robot, q - h * e))) / (2 * h)
                   for e in np.eye(2)], axis=1)
    n = np.arange(1, 4)
    dgc = np.zeros((2, 2))
    dgc[1, 1] = np.sum(n * Bgc * np.sin(n * q[1]))  # -d/dq (sum B_n cos n q)
    assert np.allclose(lin.K, np.diag(K) + dG + dgc, rtol=1e-7, atol=1e-6)
    assert np.allclose(lin.C, np.diag([5.0, 3.0]), atol=1e-12)
    assert np.allclose(lin.M, jflex.crba(robot, q), rtol=_TOL)


def test_spring_compensator_torque_is_eq_2_10():
    robot = planar(2)
    L, kc, rr, x0 = 0.4, 2e4, 0.15, 0.2
    gc = SpringGravityCompensator(kc, L, rr, x0, joint=1)
    model = jflex.Model(robot, [gc])
    q = np.array([0.1, 0.8])
    h = jflex.bias_forces(model, 0.0, q, np.zeros(2), np.zeros(0)) - jflex.gravity(robot, q)
    tau_gc = L * kc * rr * np.cos(q[1]) * (1 - x0 / np.sqrt(L**2 + rr**2 - 2 * L * rr * np.sin(q[1])))
    assert np.allclose(-np.asarray(h), [0.0, tau_gc], rtol=1e-10, atol=1e-10)


def test_stiff_joints_tend_to_the_rigid_model():
    """Held motors: f_r ~ sqrt(s) as K = s K1 grows; tool FRF at low frequency -> J K^-1 J^T."""
    robot = planar(2)
    q = np.array([0.3, 1.1])
    K1 = np.array([1e4, 6e3])
    fn = jax.jit(lambda s: jflex.modal_analysis(jflex.Model(robot, [FlexibleJoints(s * K1, [1.0, 1.0])]), q,
                                                hold="actuated").frequency)
    M0 = np.asarray(jflex.crba(robot, q))
    from scipy.linalg import eigh

    ref = np.sqrt(eigh(np.diag(K1), M0, eigvals_only=True)) / (2 * np.pi)
    errs = [np.max(np.abs(np.asarray(fn(s)) / np.sqrt(s) - ref) / ref) for s in (1.0, 1e2, 1e4)]
    assert errs[0] > errs[1] > errs[2] and errs[2] < 1e-4
    w = np.array([1e-3, 1e-2])
    J = np.asarray(jflex.jacobian(robot, q, "tool"))[:3]
    frf = jax.jit(lambda s: jflex.frf(jflex.Model(robot, [FlexibleJoints(s * K1, [1.0, 1.0])]), q, w,
                                      hold="actuated", frame="tool"))
    for s in (1e2, 1e4):
        G = np.asarray(frf(s))[0]
        ref_G = J @ np.diag(1 / (s * K1)) @ J.T
        rel = np.linalg.norm(G - ref_G) / np.linalg.norm(ref_G)
        assert rel < 50 / s  # the gravity stiffness, relatively 1/s, is what remains


def test_free_motor_low_frequency_frf_tends_to_rigid_with_reflected_inertia():
    """Motors free: below the joint mode the link responds like a rigid link carrying J_l + r^2 I_m."""
    robot = planar(1, gravity=(0.0, 0.0, -9.81))
    J_l = float(jflex.crba(robot, np.zeros(1))[0, 0])
    r, Im = 100.0, 1e-4
    w = np.array([0.5, 1.0])
    rigid = -1 / (w**2 * (J_l + r**2 * Im))  # torque on the motor, response of the link
    errs = []
    for k in (1e3, 1e5):
        model = jflex.Model(robot, [FlexibleJoints([k], rotor_inertia=[Im], gear_ratio=[r])])
        G = np.asarray(jax.jit(lambda q: jflex.frf(model, q, w))(np.zeros(1)))  # free: coordinates (q, theta)
        errs.append(np.max(np.abs(G[:, 0, 1] - rigid) / np.abs(rigid)))
    assert errs[1] < errs[0] and errs[1] < 1e-4


def test_modal_analysis_tool_shapes_and_frf_consistency():
    robot = planar(2)
    model = jflex.Model(robot, [FlexibleJoints([3e3, 2e3], [4.0, 2.0], rotor_inertia=[1e-4] * 2, gear_ratio=[50.0] * 2)])
    q = np.array([0.2, 0.5])
    md = jax.jit(lambda q: jflex.modal_analysis(model, q, hold="theta_*", frame="tool"))(q)
    J = np.asarray(jflex.jacobian(robot, q, "tool"))[:3]
    assert np.allclose(md.tool_shape, J @ np.asarray(md.shape), atol=1e-12)
    w = np.linspace(1.0, 200.0, 7)
    Gd, Gm = jax.jit(lambda q: (jflex.frf(model, q, w, hold="actuated", frame="tool"),
                                jflex.frf(model, q, w, hold="actuated", frame="tool", method="modal")))(q)
    assert np.allclose(Gd, Gm, rtol=1e-7, atol=1e-14)


def test_batched_over_postures_matches_single_calls():
    robot = planar(2)
    model = jflex.Model(robot, [FlexibleJoints([3e3, 2e3], [4.0, 2.0])])
    Q = np.array([[0.1, 0.2], [0.5, -1.0], [1.2, 0.3]])
    batch = jax.jit(jax.vmap(lambda q: jflex.modal_analysis(model, q, hold="actuated").frequency))(Q)
    lins = jax.jit(jax.vmap(lambda q: jflex.linear.linearization(model, q, hold="actuated")[1][:3]))(Q)
    for i, fb in enumerate(np.asarray(batch)):
        lin = type("Lin", (), dict(M=np.asarray(lins[0][i]), C=np.asarray(lins[1][i]), K=np.asarray(lins[2][i])))
        ref = np.sort(np.abs(np.linalg.eigvals(
            np.block([[np.zeros((2, 2)), np.eye(2)], [-np.linalg.solve(lin.M, lin.K), -np.linalg.solve(lin.M, lin.C)]])
        )))[::2] / (2 * np.pi)
        assert np.allclose(fb, ref, rtol=1e-9)


def test_bad_inputs_raise_clear_errors():
    robot = planar(2)
    with pytest.raises(jflex.ParameterError, match="stiffness"):
        FlexibleJoints([1e3, 0.0])
    with pytest.raises(jflex.ParameterError, match="stiffness"):
        FlexibleJoints([[1e3, 0.0], [0.0, -1.0]])
    with pytest.raises(jflex.ParameterError, match="gear_ratio"):
        FlexibleJoints([1e3, 1e3], gear_ratio=[0.0, 1.0])
    with pytest.raises(jflex.ShapeError, match="rotor_inertia"):
        FlexibleJoints([1e3, 1e3], rotor_inertia=[1.0, 2.0, 3.0])
    model = jflex.Model(robot, [FlexibleJoints([1e3, 1e3])])
    with pytest.raises(jflex.ShapeError, match="posture must have shape"):
        jflex.modal_analysis(model, np.zeros(3))
    with pytest.raises(jflex.ShapeError, match="matches no coordinate"):
        jflex.modal_analysis(model, np.zeros(2), hold="motor_*")
    with pytest.raises(jflex.ParameterError, match="strictly increasing"):
        jflex.frf(model, np.zeros(2), np.array([1.0, 3.0, 2.0]))
    with pytest.raises(jflex.ParameterError, match=">= 0"):
        jflex.frf(model, np.zeros(2), np.array([-1.0, 3.0]))
