"""Loop closure of the press linkage and its finite-element models."""

import copy
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex import fem

CFG = jflex.load_yaml(pathlib.Path(__file__).parent.parent / "configs" / "press.yaml")
GEO = fem.press_from_config(CFG)
PHIS = jnp.pi / 2 + 2 * jnp.pi * jnp.arange(72) / 72


@pytest.fixture(scope="module")
def motion():
    return fem.press_motion(GEO, PHIS)


@pytest.fixture(scope="module")
def poses():
    return {v: (fem.press_fe(GEO, v), fem.press_poses(GEO, fem.press_fe(GEO, v), 8)) for v in ("perfect", "joints")}


def test_loop_closure_holds_over_a_revolution(motion):
    res = np.asarray(jax.vmap(fem.press_residual, in_axes=(0, 0, None))(motion.q, motion.phi, GEO))
    assert np.abs(res).max() < 1e-10
    # both slider pins at one height (the two sides close the same loop)
    np.testing.assert_allclose(motion.q[:, 5], motion.q[:, 9], atol=1e-10)


def test_velocities_and_accelerations_match_finite_differences(motion):
    h = 1e-4
    qp = fem.press_motion(GEO, PHIS + h).q
    qm = fem.press_motion(GEO, PHIS - h).q
    q = motion.q
    np.testing.assert_allclose(motion.dq, (qp - qm) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(motion.ddq, (qp - 2 * q + qm) / h**2, atol=1e-5)
    # points: positions from the same coordinates, derivatives from the motion
    P, dP, ddP = fem.point_motion(fem.press_points, motion, GEO)
    pts = jax.vmap(fem.press_points, in_axes=(0, 0, None))
    Pp, Pm = np.asarray(pts(qp, PHIS + h, GEO)), np.asarray(pts(qm, PHIS - h, GEO))
    np.testing.assert_allclose(dP, (Pp - Pm) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(ddP, (Pp - 2 * np.asarray(P) + Pm) / h**2, atol=1e-5)


def test_bdc_is_the_lowest_slider_position(motion):
    y = np.asarray(motion.q[:, 5])
    assert np.argmin(y) == 0
    assert abs(motion.dq[0, 5]) < 1e-10  # slider at rest at BDC


def test_slider_crank_against_closed_form():
    # A plain slider-crank: q = [rod angle, slider x]; x = r cos(phi) + sqrt(l^2 - r^2 sin^2 phi).
    r, l = 0.1, 0.4

    def res(q, phi, args):
        return jnp.stack([r * jnp.cos(phi) + l * jnp.cos(q[0]) - q[1], r * jnp.sin(phi) + l * jnp.sin(q[0])])

    phis = jnp.linspace(0.0, 2 * jnp.pi, 37)
    m = fem.linkage_motion(res, jnp.array([0.0, r + l]), phis)
    s, c = np.sin(phis), np.cos(phis)
    root = np.sqrt(l**2 - r**2 * s**2)
    np.testing.assert_allclose(m.q[:, 1], r * c + root, atol=1e-12)
    np.testing.assert_allclose(m.dq[:, 1], -r * s - r**2 * s * c / root, atol=1e-10)
    d2 = -r * c - r**2 * (c**2 - s**2) / root - r**4 * s**2 * c**2 / root**3
    np.testing.assert_allclose(m.ddq[:, 1], d2, atol=1e-10)


@pytest.mark.parametrize("variant", ["perfect", "joints"])
def test_press_fe_is_a_stable_structure(variant, poses):
    pfe, pp = poses[variant]
    for M, K in zip(pp.M, pp.K):
        np.testing.assert_allclose(M, M.T, atol=1e-9)
        np.testing.assert_allclose(K, K.T, rtol=1e-12, atol=1e-12 * np.abs(K).max())
        assert np.linalg.eigvalsh(np.asarray(K)).min() > 0  # input and guides held: no mechanism left
        assert np.linalg.eigvalsh(np.asarray(M)).min() > 0


def test_rigid_translation_load_exceeds_slider_masses(poses):
    pfe, pp = poses["joints"]
    model = pfe.model
    acc = np.zeros((model.n_nodes, 3))
    acc[:, 1] = 1.0
    ones = np.asarray(model.gather(acc))
    # a uniform unit vertical acceleration of the free DOFs moves at least both sliders
    mass_free = float(ones @ np.asarray(pp.M[0]) @ ones)
    assert mass_free > float(GEO.m1 + GEO.m2)


def test_joints_lower_the_natural_frequencies(poses):
    f = {}
    for v, (_, pp) in poses.items():
        f[v] = np.asarray(fem.modes(pp.M[0], pp.K[0], 3).omega)
    assert np.all(f["joints"] < f["perfect"])


def test_config_errors_name_the_field():
    bad = copy.deepcopy(CFG)
    bad["press"]["rod_length"] = -0.1
    with pytest.raises(jflex.ConfigError, match="press.rod_length"):
        fem.press_from_config(bad)
    bad = copy.deepcopy(CFG)
    del bad["joints"]["E_tension"]
    with pytest.raises(jflex.ConfigError, match="joints.E_tension"):
        fem.press_from_config(bad)
    bad = copy.deepcopy(CFG)
    bad["press"]["sections"]["lower"]["depth"] = 0
    with pytest.raises(jflex.ConfigError, match="sections.lower"):
        fem.press_from_config(bad)
    with pytest.raises(jflex.ConfigError, match="variant"):
        fem.press_fe(GEO, "rigid")
