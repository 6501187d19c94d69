"""Real robots' effects as gap candidates: an effect class that registers itself
(jflex.effects.register_candidate) is tried by the diagnosis with no line in jflex.gap; a sensor
delay of either sign; plausible ranges. The diagnosis cases are made by independent code
(Pinocchio + NumPy, tests/_real_effects_cases.py): the planted effect is found and named, and one
planted outside its plausible range is reported implausible and not named."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex import effects as E
from jflex.effects import _linear as EL
from jflex.gap.torque import _set as T
from jflex.gap.torque import _terms as TT

pytest.importorskip("pinocchio")
import _real_effects_cases as G  # noqa: E402


def test_builtin_real_effects_are_registered_candidates():
    for name, cls in (("torque_offset", E.TorqueOffset), ("asymmetric_coulomb", E.AsymmetricCoulomb),
                      ("coupled_drive", E.CoupledDrive)):
        assert E.registered_candidates()[name] is cls and name in TT.KINDS
    # a coupled drive is tried at the adjacent pairs of the wrist (the last three joints) only
    assert list(TT.KINDS["coupled_drive"].joints(6)) == [3, 4]
    assert list(TT.KINDS["torque_offset"].joints(6)) == list(range(6))


def _two_joint_robot():
    return jflex.make_robot(joint_names=["a", "b"], link_names=["l1", "l2"], parents=[-1, 0],
                            joint_types=["revolute", "revolute"], placement_R=np.stack([np.eye(3)] * 2),
                            placement_p=np.zeros((2, 3)), axis=[[0, 0, 1], [0, 0, 1]],
                            inertia=np.stack([np.r_[1.0, np.zeros(9)]] * 2))


class _Cogging(E.AbstractLinearEffect):
    """A user's law: ``tau = A sin(3 q)`` (a toy cogging torque), linear in A."""

    amplitude: jnp.ndarray
    joints: tuple = eqx.field(static=True)
    linear_leaves = ("amplitude",)
    units = ("N m",)
    candidate = E.CandidateInfo(name="toy_cogging", build=lambda joints, hyper: _Cogging(joints, 1.0),
                                placements=lambda n: tuple((j,) for j in range(n)))

    def __init__(self, joints, amplitude):
        self.joints = tuple(joints)
        self.amplitude = jnp.broadcast_to(jnp.asarray(amplitude, float), (len(self.joints),))

    def potential_energy(self, robot, slots, x):
        from jflex.effects._base import joint_indices

        q = x[jnp.array(joint_indices(robot, self.joints, "toy"))]
        return -jnp.sum(self.amplitude * jnp.cos(3 * q)) / 3  # dV/dq = A sin(3 q)

    def plausible_ranges(self, robot, scale):
        return [(-1.0, 1.0)] * len(self.joints)


def test_a_users_registered_effect_becomes_a_candidate_without_gap_code():
    robot = _two_joint_robot()
    E.register_candidate(_Cogging)
    try:
        assert "toy_cogging" in TT.KINDS
        term = TT.make_term("toy_cogging", 1)
        t = np.linspace(0, 1, 50)
        q = np.stack([np.sin(t), np.cos(2 * t)], axis=1)
        s = T.TorqueSet(name="s", t=t, q=q, qd=q * 0, qdd=q * 0, tau=q, F0=q, scale=np.ones(2), Y=np.zeros((50, 2, 20)),
                        q_extra=np.zeros((50, 0)), extra_joints=(), robot=robot)
        cols = term.columns(s)
        assert cols.shape == (50, 2, 1)
        np.testing.assert_allclose(cols[:, 1, 0], np.sin(3 * q[:, 1]), atol=1e-12)
        np.testing.assert_allclose(cols[:, 0, 0], 0.0, atol=1e-15)
        assert "amplitude = 1.5" in term.implausible(np.array([1.5]), [s])
    finally:
        EL._REGISTRY.pop("toy_cogging", None)
        TT.KINDS.pop("toy_cogging", None)


def test_builtin_candidates_carry_plausible_ranges():
    # a hose spring fitted as 0.144 rad of gear play, a 80 ms delay, a Coulomb level of 5 x the
    # joint's torque: each reported with its name, value and range
    robot = _two_joint_robot()
    t = np.linspace(0, 1, 101)
    q = np.stack([np.sin(2 * np.pi * t), np.cos(2 * np.pi * t)], axis=1)
    tau = 2.0 * q  # rms sqrt(2), std sqrt(2)
    s = T.TorqueSet(name="s", t=t, q=q, qd=q, qdd=q, tau=tau, F0=tau, scale=np.ones(2), Y=np.zeros((101, 2, 20)),
                    q_extra=np.zeros((101, 0)), extra_joints=(), robot=robot)
    msg = TT.LoadedPlay(1, (TT.LOADED, 0.01)).implausible(np.array([0.0, 0.144]), [s])
    assert "play half-width b = 0.144 rad" in msg and "[0, 0.02] rad" in msg
    assert TT.LoadedPlay(1, (TT.LOADED, 0.01)).implausible(np.array([0.0, 0.004]), [s]) is None
    assert "delay = -0.08 s" in TT.SensorDelay(None, -0.08).implausible(np.zeros(0), [s])
    assert TT.SensorDelay(None, -0.012).implausible(np.zeros(0), [s]) is None
    lim = 2 * np.sqrt(2)
    assert TT.make_term("coulomb_friction", 0).implausible(np.array([0.9 * lim]), [s]) is None
    assert "Fc [N m] = 5" in TT.make_term("coulomb_friction", 0).implausible(np.array([5.0]), [s])
    assert "negative" in TT.make_term("asymmetric_coulomb", 1).implausible(np.array([0.1, 5.0]), [s])
    # a torque read 1.8 x (a gain no drive has; the data's scale check starts at 3 x)
    assert "drive gain - 1 = 0.8 lies outside the plausible range [-0.3, 0.3]" in TT.make_term("drive_gain", 1).implausible(
        np.array([0.8]), [s])
    assert TT.make_term("drive_gain", 1).implausible(np.array([-0.07]), [s]) is None


def test_shift_of_either_sign_against_the_closed_form():
    t = np.arange(0, 2, 0.001)
    X = np.stack([np.sin(3 * t), np.cos(5 * t)], axis=1)
    for d in (0.0123, -0.0123):
        Y = T.shift(X, t, d)
        inner = (t > 0.05) & (t < 1.95)
        np.testing.assert_allclose(Y[inner], np.stack([np.sin(3 * (t - d)), np.cos(5 * (t - d))], axis=1)[inner], atol=2e-5)
    assert min(TT.DELAYS) < 0 < max(TT.DELAYS)


def _diagnose(tmp_path, **kw):
    folder, truth = G.make(tmp_path / "case", **kw)
    return jflex.gap.diagnose(folder, prune=3, max_effects=1).result, truth


def _named(res):
    return [(e["effect"], e["joint"]) for e in res["selected"]]


def test_negative_sensor_delay_is_found(tmp_path):
    # the encoders lag the torque by 12 ms (the torque channel leads)
    res, truth = _diagnose(tmp_path, robot="arm3", delay=-0.012)
    assert _named(res) == [("sensor_delay", None)]
    assert res["parameters"]["torque"]["sensor_delay"]["delay [s]"] == pytest.approx(-0.012, abs=0.0015)
    assert not res["selected"][0].get("implausible")
    assert res["torque_scale_suspects"] == []  # torques on their own scale raise no scale alarm


def test_a_delay_outside_the_plausible_range_is_reported_not_named(tmp_path):
    res, truth = _diagnose(tmp_path, robot="arm3", delay=-0.058)
    assert "sensor_delay" not in [e for e, _ in _named(res)]
    entry = next(e for e in res["ranking"] if e["effect"] == "sensor_delay")
    assert "delay" in entry["implausible"] and "-0.05" in entry["implausible"]


def test_a_forgotten_current_scale_is_named_and_no_effect_is(tmp_path):
    # the log holds motor currents (torque / 8 N m per A, a constant times a gear) read as torques,
    # with a torque offset planted too: nothing may be named on data off scale
    res, truth = _diagnose(tmp_path, robot="arm3", effect="torque_offset", logged_gain=0.125)
    assert res["selected"] == [] and res["verdict"] != "explained"
    suspects = res["torque_scale_suspects"]
    assert suspects and {d["dataset"] for d in suspects} == {"traj0", "traj1"}
    for d in suspects:
        # the gain maps the nominal fit (whose friction coefficients already shrank to the logged
        # scale) onto the log: near the true 0.125, not equal to it
        assert 0.125 / 1.6 < d["gain"] < 0.125 * 1.6
        assert d["joint"] in res["stop_reason"]
    assert "off scale" in res["stop_reason"]


def test_a_torque_constant_a_few_per_cent_off_is_named_as_a_drive_gain(tmp_path):
    # joint 2's torque is logged 7 % high (a data-sheet torque constant off): nothing else is planted
    res, truth = _diagnose(tmp_path, robot="arm3", logged_gain=[1.0, 1.07, 1.0])
    assert _named(res) == [("drive_gain", truth["joint_names"][1])]
    assert res["verdict"] == "explained"
    # only the gain relative to the other joints shows (the inertias are refitted): still about 7 %
    assert res["parameters"]["torque"][f"drive_gain@{truth['joint_names'][1]}"]["gain - 1"] == pytest.approx(0.07, abs=0.02)


def test_a_torque_the_log_leaves_out_is_told_from_a_scale_only_where_the_data_can():
    # joint b's model torque is 150 N m of gravity with a 2 N m ripple; its log reads the ripple
    # alone (a torso whose drive reads only what its counterbalance leaves): a gain near 0 and an
    # offset of -150 N m both match, and the reason names both. Joint a's log is the model's x 10
    # (a gear ratio forgotten): a gain, and no offset matches.
    from jflex.gap.torque._scale import scale_reason, torque_scale_suspects
    import types

    t = np.linspace(0, 10, 2001)
    ripple = 2.0 * np.sin(2 * np.pi * 0.3 * t)
    F0 = np.stack([100.0 * np.sin(2 * np.pi * 0.2 * t), 150.0 + ripple], axis=1)
    tau = np.stack([10.0 * F0[:, 0], ripple + 0.01 * np.cos(7 * t)], axis=1)
    q = np.zeros((t.size, 2))
    s = T.TorqueSet(name="s", t=t, q=q, qd=q, qdd=q, tau=tau, F0=F0, scale=tau.std(axis=0), Y=np.zeros((t.size, 2, 20)),
                    q_extra=np.zeros((t.size, 0)), extra_joints=(), robot=_two_joint_robot())
    pb = types.SimpleNamespace(ttrain=[s], n=2, names=("a", "b"))
    state = types.SimpleNamespace(tfit=T.TorqueFit(terms=(), delay=0.0, theta=np.zeros(0), cost=0.0))
    sus = {d["joint"]: d for d in torque_scale_suspects(pb, state)}
    assert sus["a"]["gain"] == pytest.approx(10.0, rel=1e-6)
    assert sus["b"]["gain"] < 1 / 3 and sus["b"]["offset"] == pytest.approx(-150.0, abs=0.5)
    why = scale_reason(list(sus.values()))
    assert "a in s (10 x the model)" in why and "b in s (" in why and "150 N m below it" in why
    assert "torque_offset" in why
    assert "torque_offset" not in scale_reason([sus["a"]])


@pytest.mark.heavy  # a diagnosis each: 25-60 s idle
@pytest.mark.parametrize("effect", ["torque_offset", "asymmetric_coulomb"])
def test_planted_joint_effect_is_found_and_named(tmp_path, effect):
    res, truth = _diagnose(tmp_path, robot="arm3", effect=effect)
    j = truth["joint_names"][truth["params"]["joint"]]
    assert _named(res) == [(effect, j)]
    assert res["verdict"] == "explained"


@pytest.mark.heavy  # a diagnosis each: 25-60 s idle
def test_coupled_wrist_drive_of_a_six_joint_arm_is_found_and_named(tmp_path):
    res, truth = _diagnose(tmp_path, robot="ur5", effect="coupled_drive")
    a, b = (truth["joint_names"][k] for k in truth["params"]["joints"])
    assert _named(res) == [("coupled_drive", a)]
    fitted = res["parameters"]["torque"][f"coupled_drive@{a}+{b}"]
    assert fitted["coupling ratio"] == 1.0
    assert fitted["motor1.inertia [kg m^2]"] == pytest.approx(truth["params"]["Ia"], rel=0.25)
