"""Rayleigh damping against its closed-form modal damping ratios; joint friction laws."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg as sl

import jflex
from jflex.effects import JointFriction, rayleigh_damping
from jflex.effects import AbstractEffect


class _Springs(AbstractEffect):
    k: jnp.ndarray

    def potential_energy(self, robot, slots, x):
        return 0.5 * jnp.sum(self.k * x[:2] ** 2)


def _chain():
    """Two prismatic joints in series along x: masses 1 and 0.5 kg, springs 400 and 150 N/m."""
    robot = jflex.make_robot(
        joint_names=["a", "b"], link_names=["A", "B"], parents=[-1, 0], joint_types=["prismatic", "prismatic"],
        placement_R=np.stack([np.eye(3)] * 2), placement_p=np.zeros((2, 3)), axis=[[1.0, 0, 0], [1.0, 0, 0]],
        inertia=np.array([[1.0] + [0] * 9, [0.5] + [0] * 9]), gravity=(0, 0, 0),
    )
    return jflex.Model(robot, [_Springs(jnp.array([400.0, 150.0]))])


def test_rayleigh_modal_damping_ratios():
    model = _chain()
    x0 = jnp.zeros(2)
    lin = jflex.linearize(model, x0)
    w = np.sqrt(sl.eigh(np.asarray(lin.K), np.asarray(lin.M), eigvals_only=True))
    a, b = 0.8, 2e-3
    damped = model.with_effects(rayleigh_damping(model, x0, a, b))
    L = jflex.linearize(damped, x0)
    M, C, K = (np.asarray(v) for v in (L.M, L.C, L.K))
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-Minv @ K, -Minv @ C]])
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    zeta = -lam.real / np.abs(lam)
    np.testing.assert_allclose(zeta, a / (2 * w) + b * w / 2, rtol=1e-10)


def test_friction_torque_laws():
    fr = JointFriction(["a"], viscous=0.3, coulomb=1.0, stribeck=1.5, stribeck_velocity=0.05, smoothing=1e-4)
    for v in (-2.0, -0.01, 0.02, 0.5):
        ref = -(0.3 * v + (1.0 + 0.5 * np.exp(-((v / 0.05) ** 2))) * np.tanh(v / 1e-4))
        np.testing.assert_allclose(fr.torque(jnp.array([v])), [ref], rtol=1e-12)
    # far above the Stribeck velocity: Coulomb + viscous; just above zero: the breakaway level
    np.testing.assert_allclose(fr.torque(jnp.array([1.0])), [-1.3], rtol=1e-9)
    np.testing.assert_allclose(fr.torque(jnp.array([1e-3])), [-1.5], rtol=2e-3)


def test_friction_dissipates_exactly_its_work():
    model = _chain().with_effects(JointFriction(["a", "b"], viscous=0.2, coulomb=0.5, smoothing=1e-2))
    ts = np.linspace(0, 1.5, 151)
    r = jflex.simulate(model, ts, x0=[0.05, -0.02], rtol=1e-10, atol=1e-12, outputs=("energy", "work"))
    E, W = np.asarray(r["energy"]), np.asarray(r["work"])
    np.testing.assert_allclose(E - E[0], W, atol=1e-9)
    assert np.all(np.diff(W) <= 1e-12)


def test_bad_friction_and_damping_parameters():
    with pytest.raises(jflex.ParameterError, match="coulomb"):
        JointFriction(["a"], coulomb=-1.0)
    with pytest.raises(jflex.ShapeError, match="viscous"):
        JointFriction(["a", "b"], viscous=[1.0, 2.0, 3.0])
    with pytest.raises(jflex.ParameterError, match="positive semi-definite"):
        jflex.effects.ViscousDamping((0, 1), [[1.0, 0.0], [0.0, -1.0]])
