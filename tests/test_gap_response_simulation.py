"""Simulations on tip-only response data sets in the gap diagnosis (output error): a spring at one
joint, fitted on FRF training data and simulated in the tip set, is found and closes the gap; a
simulated spring with play rests where it holds gravity. (Torque-side effects seen at the tip, the
null case and malformed tip records: tests/test_gap_response.py, the two files run on separate
workers; a simulation that runs away: tests/test_gap_result.py.)"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex_family import generate as G
from jflex.gap.response import _response as R
from jflex.gap import diagnose
from test_gap_response import TIP_NOISE, _truth


@pytest.mark.long
def test_joint_flexibility_seen_at_the_tip_is_found(tmp_path):
    # springs fitted on FRF training data (motors held) are simulated in the tip set: the applied
    # torque drives the motor side (the stated rotor inertia), the spring the link. The nominal
    # model lacks the spring at one joint; the tip record is the only validation set.
    from jflex.gap.report._report import write_report

    folder = G.frf_case(tmp_path / "flex", "arm3", ["joint_flexibility"], seed=3, n_post=2, tip_noise=TIP_NOISE,
                        frf_validation=False)
    truth = _truth(folder)["effects"][0]
    d = diagnose(folder)
    r = d.result
    assert r["responses_output_error"] == ["tip"] and r["significant"]
    assert [(s["effect"], s["joint"]) for s in r["selected"]][:1] == [("joint_flexibility", truth["joint"])]
    g0, g1 = (r["steps"][k]["per_dataset"]["tip"] for k in (0, -1))
    assert g1 < 0.2 * g0 and r["shrink"] > 80
    k = r["parameters"]["linear"][truth["joint"]]["stiffness [N m/rad]"]
    assert abs(k - truth["params"]["k"]) < 0.1 * truth["params"]["k"]
    assert r["failed_solves"] == []
    # the report plots measured vs nominal vs final tip traces and links them
    md = write_report(d, tmp_path / "out").read_text()
    assert (tmp_path / "out" / "response_tip.png").is_file() and "(response_tip.png)" in md


def test_simulated_spring_with_play_rests_where_it_holds_gravity():
    """A simulated spring ``(k, c, I_m, b)`` carries play (:class:`jflex.effects.FlexibleJoints`
    ``play``, the other springs without); its rest deflection (:func:`._response.rest_deflection`,
    used by :func:`._response.rest_coords`) is ``b`` past the play plus ``tau / k``, where the
    transmission passes the link's gravity torque. Without play every spring holds play 0 (one
    structure for springs with and without play), and its motion is the plain spring's."""
    inert = [{"mass": 3.0, "com": [0.25, 0.02, 0.0], "inertia": [0.1, 0.0, 0.2, 0.0, 0.0, 0.25]}] * 2
    robot = jflex.from_dh([[0.0, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0]], tool=[0.0, 0.5, 0.0, 0.0], inertias=inert,
                          gravity=(0.0, -9.81, 0.0))
    k, b = np.array([3e3, 2e3]), np.array([0.0, 0.004])
    m0 = R.simulation_model(robot, None, {0: (k[0], 1.0, 0.02), 1: (k[1], 1.0, 0.01)}, None)
    f0 = m0.effects[-1]
    assert np.array_equal(f0.play, [0.0, 0.0])
    plain = jflex.Model(m0.robot, [jflex.effects.FlexibleJoints(f0.stiffness, f0.damping, f0.rotor_inertia, joints=f0.joints,
                                                                coupling=False)])
    rng = np.random.default_rng(1)
    x, xd, u = (jnp.asarray(rng.standard_normal(n)) * s for n, s in ((4, 0.01), (4, 1.0), (2, 10.0)))
    a0, _ = jflex.model_forward_dynamics(m0, 0.0, x, xd, jnp.zeros(0), u)
    a1, _ = jflex.model_forward_dynamics(plain, 0.0, x, xd, jnp.zeros(0), u)
    assert np.allclose(a0, a1, rtol=1e-12, atol=1e-9)
    model = R.simulation_model(robot, None, {0: (k[0], 1.0, 0.02), 1: (k[1], 1.0, 0.01, b[1])}, None)
    fj = model.effects[-1]
    assert np.allclose(fj.play, b) and float(fj.play_smoothing) == R.PLAY_SMOOTHING
    q0 = np.array([0.4, -0.3])
    g = np.asarray(jflex.gravity(robot, q0))
    d = R.rest_deflection(g, k, b, R.PLAY_SMOOTHING)
    assert d[0] == g[0] / k[0]  # no play there: exactly tau / k
    assert d[1] == pytest.approx(g[1] / k[1] + np.sign(g[1]) * b[1], rel=1e-3)
    x = jnp.asarray(np.concatenate([q0, q0 + d]))
    held = np.asarray(fj.spring_torque(model.rigid, model.layout.slots[-1], x, jnp.zeros(4)))
    assert np.allclose(held, g, rtol=1e-9, atol=0)
