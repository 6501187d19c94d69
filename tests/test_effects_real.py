"""Real robots' linear effects (jflex.effects TorqueOffset, AsymmetricCoulomb, CoupledDrive):
each torque against a NumPy formula written here, through the Model as every analysis reads it;
the regressor columns against the effect's own torque (tau = Y theta) and finite differences;
the identification's base parameters and least squares with them against Pinocchio + NumPy data;
the plausible ranges."""

import pathlib
import sys

import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex import effects as E
from jflex import identify as idf

pin = pytest.importorskip("pinocchio")
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import robots as R  # noqa: E402

EPS = 0.01  # [rad/s] smooth-sign width used throughout


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    model, tool, home = R.true_model("ur5")
    p = tmp_path_factory.mktemp("ur5") / "robot.urdf"
    p.write_text(R.urdf_text(model, tool, "ur5"))
    return jflex.load_urdf(p), model, home


def _samples(n, N=12, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(N, n)), rng.normal(size=(N, n)), rng.normal(size=(N, n))


def _numpy_torque(kind, q, qd, qdd, p):
    """The law, written independently of jflex (joint-torque sign: what the motors supply)."""
    out = np.zeros_like(qd)
    if kind == "offset":
        out[:, p["idx"]] = p["offset"]
    elif kind == "asym":
        s = np.tanh(qd[:, p["idx"]] / EPS)
        out[:, p["idx"]] = p["pos"] * 0.5 * (1 + s) - p["neg"] * 0.5 * (1 - s)
    else:
        K = np.asarray(p["K"])
        for k in range(len(qd)):
            w, wd = K @ qd[k, p["idx"]], K @ qdd[k, p["idx"]]
            out[k, p["idx"]] = K.T @ (p["Ia"] * wd + p["fv"] * w + p["fc"] * np.tanh(w / EPS))
    return out


def _cases(names):
    return [
        ("offset", E.TorqueOffset(names[1:3], [0.7, -1.3]), dict(idx=[1, 2], offset=np.array([0.7, -1.3]))),
        ("asym", E.AsymmetricCoulomb([names[0], names[4]], [2.0, 0.5], [0.8, 1.1], EPS),
         dict(idx=[0, 4], pos=np.array([2.0, 0.5]), neg=np.array([0.8, 1.1]))),
        # the Staubli TX40's wrist: motor 6 turns with joints 5 and 6 (w6 = qd5 + qd6); a second
        # motor with another ratio checks the matrix form
        ("coupled", E.CoupledDrive(names[4:6], [[1.0, 1.0], [0.0, -2.0]], inertia=[0.3, 0.1], viscous=[0.5, 0.2],
                                   coulomb=[0.7, 0.4], smoothing=EPS),
         dict(idx=[4, 5], K=[[1.0, 1.0], [0.0, -2.0]], Ia=np.array([0.3, 0.1]), fv=np.array([0.5, 0.2]),
              fc=np.array([0.7, 0.4]))),
    ]


def test_torques_equal_numpy_laws_through_the_model(arm):
    robot, model, _ = arm
    q, qd, qdd = _samples(robot.nq)
    for kind, eff, p in _cases(robot.joint_names):
        ref = _numpy_torque(kind, q, qd, qdd, p)
        got = np.stack([np.asarray(eff.torque(robot, *(jnp.asarray(a[k]) for a in (q, qd, qdd)))) for k in range(len(q))])
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12, err_msg=kind)
        # the model every analysis uses: inverse dynamics with the effect, less Pinocchio's rigid robot
        m = jflex.Model(robot, [eff])
        data = model.createData()
        for k in range(3):
            tau = np.asarray(jflex.model_inverse_dynamics(m, 0.0, q[k], qd[k], qdd[k], jflex.initial_state(m)))
            np.testing.assert_allclose(tau - pin.rnea(model, data, q[k], qd[k], qdd[k]), ref[k], atol=1e-9, err_msg=kind)


def test_regressor_columns_are_the_torque_and_its_finite_differences(arm):
    robot, _, _ = arm
    q, qd, qdd = _samples(robot.nq, N=4, seed=1)
    for kind, eff, _ in _cases(robot.joint_names):
        theta = np.asarray(eff.parameters())
        for k in range(len(q)):
            args = [jnp.asarray(a[k]) for a in (q, qd, qdd)]
            Y = np.asarray(eff.regressor(robot, *args))
            tau = np.asarray(eff.torque(robot, *args))
            np.testing.assert_allclose(Y @ theta, tau, atol=1e-12, err_msg=kind)
            h = 1e-4
            for i in range(theta.size):
                tp, tm = (np.asarray(eff.with_parameters(theta + s * h * np.eye(theta.size)[i]).torque(robot, *args))
                          for s in (1, -1))
                np.testing.assert_allclose((tp - tm) / (2 * h), Y[:, i], atol=1e-8, err_msg=f"{kind} column {i}")


def test_identification_recovers_planted_effects_in_base_parameters(arm):
    # torques from Pinocchio + the NumPy laws; least squares on the base regressor with the effects'
    # columns gives the true base parameters (the offset groups with the asymmetric Coulomb levels:
    # F+ s+ - F- s- = (F+ + F-) s+ - F-)
    robot, model, home = arm
    names = robot.joint_names
    n = robot.nq
    reg = idf.Regressor(viscous=False, coulomb=False,
                        effects=(E.TorqueOffset(names), E.AsymmetricCoulomb(names, smoothing=EPS),
                                 E.CoupledDrive(names[4:6], [[1.0, 1.0]], smoothing=EPS)))
    assert reg.n_params(n) == len(reg.names(robot)) == 10 * n + 3 * n + 3
    bp = idf.base_parameters(robot, reg, n_samples=120)
    groups = {g["base"]: g["terms"] for g in bp.groups()}
    for j in names:
        assert groups[f"{j}.offset"] == pytest.approx({f"{j}.offset": 1.0, f"{j}.negative": -1.0})
        assert groups[f"{j}.positive"] == pytest.approx({f"{j}.positive": 1.0, f"{j}.negative": 1.0})
    pair = f"{names[4]}+{names[5]}:motor1"
    assert all(f"{pair}.{a}" in groups for a in ("inertia", "viscous", "coulomb"))
    rng = np.random.default_rng(2)
    q, qd, qdd = (home + rng.normal(size=(300, n)) * 0.5), rng.normal(size=(300, n)), rng.normal(size=(300, n))
    p_off, p_pos, p_neg = rng.uniform(-1, 1, n), rng.uniform(0.2, 1, n), rng.uniform(0.2, 1, n)
    cd = dict(idx=[4, 5], K=[[1.0, 1.0]], Ia=np.array([0.05]), fv=np.array([0.3]), fc=np.array([0.4]))
    data = model.createData()
    tau = np.stack([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    tau += p_off + _numpy_torque("asym", q, qd, qdd, dict(idx=list(range(n)), pos=p_pos, neg=p_neg))
    tau += _numpy_torque("coupled", q, qd, qdd, cd)
    A = np.asarray(reg.stack(robot, q, qd, qdd))
    psi, *_ = np.linalg.lstsq(np.asarray(bp.columns(A)), tau.ravel(), rcond=None)
    theta_true = np.concatenate([pin_inertias(model), p_off, p_pos, p_neg,
                                 [0.05, 0.3, 0.4]])
    np.testing.assert_allclose(psi, np.asarray(bp.project(theta_true)), rtol=1e-7, atol=1e-8)


def pin_inertias(model):
    return np.concatenate([model.inertias[i].toDynamicParameters() for i in range(1, model.njoints)])


def test_plausible_ranges_name_the_parameter_value_and_range(arm):
    robot, _, _ = arm
    n = robot.nq
    sc = E.DataScale(tau_std=np.ones(n), tau_rms=np.full(n, 2.0), qd_std=np.ones(n), qdd_std=np.full(n, 4.0),
                     qd_max=np.full(n, 3.0), dt=0.004)
    names = robot.joint_names
    off = E.TorqueOffset(names[2:3])
    assert off.implausible(robot, [3.9], sc) is None
    msg = off.implausible(robot, [-4.5], sc)
    assert f"{names[2]}.offset" in msg and "-4.5" in msg and "[-4, 4]" in msg
    asym = E.AsymmetricCoulomb(names[:1], 1.0, 1.0)
    assert "negative" in asym.implausible(robot, [1.0, 5.0], sc)
    cd = E.CoupledDrive(names[4:6], [[1.0, 1.0]])
    # inertia bound: 2 x max std(tau) / std(K qdd), std(K qdd) = sqrt(2) x 4
    lo, hi = cd.plausible_ranges(robot, sc)[0]
    assert hi == pytest.approx(2.0 / (4.0 * np.sqrt(2)))
    assert "motor1.inertia" in cd.implausible(robot, [1.2 * hi, 0.0, 0.0], sc)


def test_offset_range_reaches_the_modelled_torque(arm):
    # a sensor that reports the effort net of the weight it carries reads ~0 while the model asks for
    # the weight: an offset of that size is plausible (bounded by the larger rms), a motor inertia
    # (bounded by the measured spread) is not widened
    robot, _, _ = arm
    n = robot.nq
    sc = E.DataScale(tau_std=np.ones(n), tau_rms=np.full(n, 2.0), qd_std=np.ones(n), qdd_std=np.full(n, 4.0),
                     qd_max=np.full(n, 3.0), dt=0.004, model_rms=np.full(n, 100.0))
    names = robot.joint_names
    assert E.TorqueOffset(names[:1]).implausible(robot, [-171.0], sc) is None
    assert E.TorqueOffset(names[:1]).implausible(robot, [-201.0], sc) is not None
    cd = E.CoupledDrive(names[4:6], [[1.0, 1.0]])
    assert cd.plausible_ranges(robot, sc)[0][1] == pytest.approx(2.0 / (4.0 * np.sqrt(2)))


@pytest.mark.parametrize("bad", [dict(offset=[np.nan]), dict(offset=[1.0, 2.0])])
def test_bad_offsets_are_refused(bad):
    with pytest.raises(jflex.JFlexError, match="TorqueOffset.offset"):
        E.TorqueOffset(["j1"], **bad)


def test_bad_coupled_drive_is_refused():
    with pytest.raises(jflex.JFlexError, match="CoupledDrive.coupling"):
        E.CoupledDrive(["a", "b"], [1.0, 1.0])
    with pytest.raises(jflex.JFlexError, match="CoupledDrive.coulomb"):
        E.CoupledDrive(["a", "b"], [[1.0, 1.0]], coulomb=-1.0)
    with pytest.raises(jflex.JFlexError, match="AsymmetricCoulomb.negative"):
        E.AsymmetricCoulomb(["a"], 1.0, -0.1)


def test_coupled_drive_matches_the_tx40_coupling_columns(arm):
    # FIGAROH's Staubli TX40 model (read, not copied: motor 6 turns with joints 5 and 6, w6 = qd5 + qd6)
    # adds three columns: joint 5 gets (qdd6, qd6, sign(qd5 + qd6)), joint 6 gets (qdd5, qd5,
    # sign(qd5 + qd6)); the diagonal parts (qdd5 on joint 5, ...) sit in the joints' own armature and
    # viscous friction. K^T (Ia K qdd + fv K qd + fc sign(K qd)) is those columns plus the diagonal parts.
    robot, _, _ = arm
    cd = E.CoupledDrive(robot.joint_names[4:6], [[1.0, 1.0]], smoothing=1e-9)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, qd, qdd = rng.normal(size=6), rng.normal(size=6), rng.normal(size=6)
        Y = np.asarray(cd.regressor(robot, q, qd, qdd))[4:6]
        s = np.sign(qd[4] + qd[5])
        figaroh = np.array([[qdd[5], qd[5], s], [qdd[4], qd[4], s]])
        diagonal = np.array([[qdd[4], qd[4], 0.0], [qdd[5], qd[5], 0.0]])
        np.testing.assert_allclose(Y - diagonal, figaroh, atol=1e-12)
