"""Equation-error identification: regressor, base parameters, least squares, physically
consistent estimates. References: Pinocchio's regressor and its rank, RNEA, planted parameters."""

import jax
import jax.numpy as jnp
import numpy as np
import pinocchio as pin
import pytest

import jflex
from jflex import identify as idf

from _identify_helpers import arm_urdf, staubli_like

_TOL = 1e-9


_rnea_vmapped = jax.jit(jax.vmap(jflex.rnea, in_axes=(None, 0, 0, 0)))


def _rnea_batch(robot, q, qd, qdd):
    return np.asarray(_rnea_vmapped(robot, jnp.asarray(q), jnp.asarray(qd), jnp.asarray(qdd)))


def test_regressor_matches_pinocchio_and_rank():
    xml = arm_urdf(3)
    robot = jflex.from_urdf_string(xml)
    model = pin.buildModelFromXML(xml)
    data = model.createData()
    reg = idf.Regressor(viscous=False, coulomb=False)
    q, qd, qdd = idf.random_samples(robot, 30, seed=1)
    rows_pin, rows = [], []
    for a, b, c in zip(q, qd, qdd):
        rows_pin.append(pin.computeJointTorqueRegressor(model, data, a, b, c).copy())
        rows.append(np.asarray(reg(robot, a, b, c)))
    Yp, Y = np.concatenate(rows_pin), np.concatenate(rows)
    assert np.abs(Y - Yp).max() < _TOL * max(1.0, np.abs(Yp).max())
    pi_pin = np.concatenate([model.inertias[i].toDynamicParameters() for i in range(1, 4)])
    tau_pin = np.stack([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    assert np.allclose(Y @ pi_pin, tau_pin.ravel(), atol=1e-8)
    bp = idf.base_parameters(robot)
    assert bp.rank == np.linalg.matrix_rank(Yp, tol=1e-8 * np.abs(Yp).max())


def test_base_count_matches_mayeda_formula():
    # Seed 003 App. A: 7N - 4 beta_1 - 2 for a first axis along gravity; beta_1 = 1 here.
    robot = staubli_like()
    bp = idf.base_parameters(robot)
    assert bp.rank == 7 * 3 - 4 * 1 - 2 == 15
    # Table A.1 grouping: psi_1 = I1zz + I2yy + I3yy + (m2 + m3) a1^2 + m3 a2^2.
    g = {d["base"]: d["terms"] for d in bp.groups()}["link1.Izz"]
    a1, a2 = 0.25, 0.95
    assert g["link2.Iyy"] == pytest.approx(1.0) and g["link3.Iyy"] == pytest.approx(1.0)
    assert g["link2.m"] == pytest.approx(a1**2) and g["link3.m"] == pytest.approx(a1**2 + a2**2)
    assert "link1.m" in [bp.names[i] for i in bp.zero]
    assert "psi_1" in bp.report()


def test_base_parameters_reproduce_full_torques():
    robot = staubli_like(4)
    reg = idf.Regressor(viscous=True, coulomb=True, compensator=(1, 3))
    bp = idf.base_parameters(robot, reg)
    assert bp.rank == 15 + 6 + 3
    theta = reg.vector(robot, fv=[5.0, 6.0, 7.0], fc=[1.0, 2.0, 3.0], compensator=[100.0, -20.0, 5.0])
    q, qd, qdd = idf.random_samples(robot, 25, seed=9)
    A = reg.stack(robot, q, qd, qdd)
    tau = np.asarray(A @ theta)
    tau_ref = _rnea_batch(robot, q, qd, qdd) + np.array([5.0, 6.0, 7.0]) * qd + np.array([1.0, 2.0, 3.0]) * np.sign(qd)
    tau_ref[:, 1] -= 100 * np.cos(q[:, 1]) - 20 * np.cos(2 * q[:, 1]) + 5 * np.cos(3 * q[:, 1])
    assert np.allclose(tau, tau_ref.ravel(), atol=1e-9)
    assert np.allclose(bp.columns(A) @ bp.project(theta), tau_ref.ravel(), atol=1e-8)
    assert np.allclose(bp.matrix() @ theta, bp.project(theta))


def _friction_data(robot, n_samples, seed, noise=None):
    fv, fc, B = np.array([8.0, 6.0, 3.0]), np.array([2.0, 4.0, 1.0]), np.array([150.0, -30.0, 10.0])
    q, qd, qdd = idf.random_samples(robot, n_samples, seed=seed)
    tau = _rnea_batch(robot, q, qd, qdd) + fv * qd + fc * np.sign(qd)
    tau[:, 1] -= sum(B[k] * np.cos((k + 1) * q[:, 1]) for k in range(3))
    if noise is not None:
        tau = tau + np.random.default_rng(seed + 1).normal(size=tau.shape) * noise
    return (q, qd, qdd), tau, (fv, fc, B)


def test_ols_noise_free_recovers_planted_base_parameters():
    robot = staubli_like(2)
    reg = idf.Regressor(compensator=(1, 3))
    bp = idf.base_parameters(robot, reg)
    samples, tau, (fv, fc, B) = _friction_data(robot, 60, 3)
    res = idf.ols(bp.columns(reg.stack(robot, *samples)), tau.ravel())
    truth = np.asarray(bp.project(reg.vector(robot, fv=fv, fc=fc, compensator=B)))
    assert np.abs(res.theta - truth).max() < 1e-9 * np.abs(truth).max()


@pytest.mark.parametrize("method", ["ols", "wls"])
def test_noisy_recovery_within_reported_std(method):
    robot = staubli_like(5)
    reg = idf.Regressor(compensator=(1, 3))
    bp = idf.base_parameters(robot, reg)
    sig = np.array([0.5, 2.0, 0.2])
    samples, tau, (fv, fc, B) = _friction_data(robot, 400, 7, noise=sig)
    A = bp.columns(reg.stack(robot, *samples))
    res = idf.ols(A, tau.ravel()) if method == "ols" else idf.wls(A, tau.ravel(), 3)
    truth = np.asarray(bp.project(reg.vector(robot, fv=fv, fc=fc, compensator=B)))
    z = np.abs(res.theta - truth) / res.std
    assert z.max() < 4.5
    assert np.mean(z < 2.0) > 0.8  # ~95 % expected for honest standard deviations
    if method == "wls":
        assert np.allclose(np.sqrt(res.sigma2), sig, rtol=0.15)


def test_instrumental_variables_removes_bias_of_noisy_regressor():
    robot = staubli_like(6)
    reg = idf.Regressor(viscous=True, coulomb=False)
    bp = idf.base_parameters(robot, reg)
    samples, tau, (fv, _, _) = _friction_data(robot, 1000, 11)
    tau = tau - np.array([2.0, 4.0, 1.0]) * np.sign(samples[1])
    tau[:, 1] += sum(c * np.cos((k + 1) * samples[0][:, 1]) for k, c in enumerate([150.0, -30.0, 10.0]))
    truth = np.asarray(bp.project(reg.vector(robot, fv=fv)))
    rng = np.random.default_rng(0)
    # Accelerations from double differentiation carry most of the noise; A is linear in them, so
    # the clean regressor is a valid instrument and OLS is biased (attenuated) while IV is not.
    noisy = [samples[0], samples[1], samples[2] + rng.normal(size=samples[2].shape) * 2.0]
    A_noisy = bp.columns(reg.stack(robot, *noisy))
    Z = bp.columns(reg.stack(robot, *samples))
    err_ols = np.linalg.norm(idf.ols(A_noisy, tau.ravel()).theta - truth)
    err_iv = np.linalg.norm(idf.instrumental_variables(A_noisy, tau.ravel(), Z).theta - truth)
    assert err_iv < 0.5 * err_ols


def test_log_cholesky_gives_consistent_bodies():
    rng = np.random.default_rng(0)
    for k in range(20):
        pi = np.asarray(idf.log_cholesky_to_inertia(jnp.asarray(rng.normal(size=10))))
        jflex.check_inertia(pi, f"sample {k}")  # independent check: raises if inconsistent
    pi = np.asarray(staubli_like(1).inertia[2])
    back = np.asarray(idf.log_cholesky_to_inertia(jnp.asarray(idf.inertia_to_log_cholesky(pi))))
    assert np.allclose(back, pi, rtol=1e-7, atol=1e-9)


def test_physical_fit_consistent_and_reproduces_torques():
    robot = staubli_like(8)
    reg = idf.Regressor(compensator=(1, 3))
    samples, tau, (fv, fc, B) = _friction_data(robot, 150, 13, noise=np.array([0.05, 0.05, 0.05]))
    A = reg.stack(robot, *samples)
    truth = np.asarray(reg.vector(robot, fv=fv, fc=fc, compensator=B))
    prior = truth * np.random.default_rng(2).uniform(0.7, 1.3, size=truth.shape)
    prior[:30] = np.asarray(staubli_like(9).inertia).ravel()  # a wrong but consistent CAD guess
    res = idf.physical_fit(A, tau.ravel(), 3, prior=prior, prior_weight=1e-4)
    for i in range(3):
        jflex.check_inertia(res.inertia[i], f"link {i}")
    bp = idf.base_parameters(robot, reg)
    psi_true, psi = np.asarray(bp.project(truth)), np.asarray(bp.project(res.theta))
    assert np.abs(psi - psi_true).max() < 0.05 * np.abs(psi_true).max()
    # Lifting base parameters back to a full consistent set.
    lift = idf.physical_fit(bp.matrix(), psi_true, 3, prior=prior, prior_weight=1e-5)
    assert np.allclose(bp.project(lift.theta), psi_true, atol=1e-3 * np.abs(psi_true).max())
    for i in range(3):
        jflex.check_inertia(lift.inertia[i], f"lifted link {i}")


def _cad_prior(truth):
    """The truth scattered by +-30 %, with a wrong but consistent CAD guess of the inertias."""
    prior = truth * np.random.default_rng(2).uniform(0.7, 1.3, size=truth.shape)
    prior[:30] = np.asarray(staubli_like(9).inertia).ravel()
    return prior


def _consistent_problem(n_samples):
    """``(A, y, prior)``: a 3-link arm with friction and a gravity compensator, noisy torques and a
    wrong but consistent CAD prior."""
    robot = staubli_like(8)
    reg = idf.Regressor(compensator=(1, 3))
    samples, tau, (fv, fc, B) = _friction_data(robot, n_samples, 13, noise=np.array([0.05, 0.05, 0.05]))
    A, y = np.asarray(reg.stack(robot, *samples)), tau.ravel()
    return A, y, _cad_prior(np.asarray(reg.vector(robot, fv=fv, fc=fc, compensator=B)))


def test_physical_fit_on_the_compressed_system_gives_the_full_answer():
    # |W(A th - y)|^2 = |R th - Q^T W y|^2 + const: same gradient and Gauss-Newton matrix, so the
    # QR-compressed fit (p rows a step) takes the steps the fit over every sample takes
    A, y, prior = _consistent_problem(60)
    w_joint = np.array([1.0, 0.5, 2.0])
    kw = dict(prior=prior, prior_weight=1e-4, max_steps=40)
    for weights in (None, w_joint):
        full = idf.physical_fit(A, y, 3, weights=weights, compress=False, **kw)
        small = idf.physical_fit(A, y, 3, weights=weights, compress=True, **kw)
        np.testing.assert_allclose(small.theta, full.theta, rtol=1e-6, atol=1e-8 * np.abs(full.theta).max())
        assert abs(small.cost - full.cost) <= 1e-9 * full.cost
    # the weights are the rows' weights: the same as weighting A and y by hand
    wr = np.tile(w_joint, A.shape[0] // 3)
    by_hand = idf.physical_fit(A * wr[:, None], y * wr, 3, compress=False, **kw)
    np.testing.assert_allclose(small.theta, by_hand.theta, rtol=1e-6, atol=1e-8 * np.abs(full.theta).max())
    for i in range(3):
        jflex.check_inertia(small.inertia[i], f"link {i}")
    with pytest.raises(jflex.ParameterError, match="weights"):
        idf.physical_fit(A, y, 3, weights=np.ones(7))


def test_physical_fit_stops_when_the_cost_stalls_within_a_fraction_of_one_chi_square():
    # a body whose best consistent fit lies on the boundary of consistency never meets the step
    # criterion; the fit stops once 20 steps gain less than 0.1 of chi-square, and what a much
    # longer run still gains is a small fraction of one chi-square unit (invisible to any test)
    A, y, prior = _consistent_problem(150)
    quick = idf.physical_fit(A, y, 3, prior=prior, prior_weight=1e-4)
    long = idf.physical_fit(A, y, 3, prior=prior, prior_weight=1e-4, max_steps=600, stall_chi2=0.0)
    assert quick.stop in ("converged", "cost stalled") and quick.steps <= long.steps
    chi2_gain = (quick.cost - long.cost) * A.shape[0] / long.cost
    assert -1e-9 <= chi2_gain < 0.5, (quick.steps, long.steps, chi2_gain)


def test_physical_fit_default_loop_reaches_optimistix_levenberg_marquardt():
    # the built-in compiled loop against optimistix's solver on the same problem: the same cost
    # (to a small fraction of one chi-square unit) and consistent bodies
    import optimistix as optx

    A, y, prior = _consistent_problem(150)
    ours = idf.physical_fit(A, y, 3, prior=prior, prior_weight=1e-4)
    ref = idf.physical_fit(A, y, 3, prior=prior, prior_weight=1e-4,
                           solver=optx.LevenbergMarquardt(rtol=1e-12, atol=1e-14))
    chi2 = abs(ours.cost - ref.cost) * A.shape[0] / ref.cost
    assert chi2 < 0.5, (ours.cost, ref.cost, ours.steps, ref.steps)
    assert ours.stop in ("converged", "cost stalled")
    assert (ours.result == optx.RESULTS.successful) == (ours.stop == "converged")
    for i in range(3):
        jflex.check_inertia(ours.inertia[i], f"link {i}")


def test_physical_fit_refuses_non_finite_data_and_a_misshapen_prior():
    rng = np.random.default_rng(0)
    A, y = rng.normal(size=(200, 30)), rng.normal(size=200)
    bad = A.copy()
    bad[3, 4] = np.nan
    with pytest.raises(jflex.DataError, match=r"A contains NaN/inf \(first at index \(3, 4\)\)"):
        idf.physical_fit(bad, y, 3)
    with pytest.raises(jflex.DataError, match="y contains NaN/inf"):
        idf.physical_fit(A, np.where(np.arange(200) == 7, np.inf, y), 3)
    with pytest.raises(jflex.ParameterError, match="prior must be 30 finite numbers"):
        idf.physical_fit(A, y, 3, prior=np.ones(29))
