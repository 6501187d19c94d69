"""Gap diagnosis (issue 6): planted truths are found, null cases select nothing, a pair lands in
the top three, malformed cases get errors naming file and field, and the candidate terms agree
with the effects of jflex.effects / jflex.linearize."""

from __future__ import annotations

import json
import os
import pathlib
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

import jflex
from jflex_family import generate as G
from jflex.gap.frequency import _model as L
from jflex.gap.torque import _set as T
from jflex.gap.torque import _terms as TT
from jflex.gap._effect_term import SMOOTHING, STRIBECK_VS
from jflex.gap import diagnose, load_case

SLOW = os.environ.get("JFLEX_SLOW") == "1"
RTOL_PARAM = 0.05  # planted parameters entering exactly linearly are recovered within 5 %


def _truth(folder):
    folder = pathlib.Path(folder)
    return json.loads((folder.parent / f"{folder.name}.truth.json").read_text())


@pytest.fixture(scope="module")
def rotor_case(tmp_path_factory):
    return G.torque_case(tmp_path_factory.mktemp("gap") / "rotor", "arm3", ["rotor_inertia"], seed=11, noise=0.01)


@pytest.fixture(scope="module")
def rotor_run(rotor_case, tmp_path_factory):
    """The rotor case diagnosed once, through ``jflex diagnose`` (the same diagnose() call, its
    result written as diagnosis.json): the tests below check different properties of that run."""
    from jflex.cli import main

    out = tmp_path_factory.mktemp("rotor_run") / "run"
    assert main(["diagnose", str(rotor_case), "--out", str(out)]) == 0
    return out


def test_planted_effect_found_and_parameter_recovered(rotor_case, rotor_run):
    truth = _truth(rotor_case)["effects"][0]
    r = json.loads((rotor_run / "diagnosis.json").read_text())
    assert r["significant"]
    assert [(s["effect"], s["joint"]) for s in r["selected"]][:1] == [("rotor_inertia", truth["joint"])]
    got = r["parameters"]["torque"][f"rotor_inertia@{truth['joint']}"]["Ia [kg m^2]"]
    assert abs(got - truth["params"]["Ia"]) < RTOL_PARAM * truth["params"]["Ia"]
    # the nominal identification already takes up the part of Ia that link 1's CAD tolerance
    # allows (Ia of a vertical first joint adds to link 1's Izz): the shrink is of what is left
    assert r["shrink"] > 70 and r["gap_after"] < 1.7 * r["noise_floor"]
    # which candidates are a change of the refitted inertias on these motions (Khalil's regrouping:
    # arm3's joint 1 is vertical and joint 2 perpendicular to it, so their rotors add to their links'
    # Izz; joint 3 is parallel to joint 2, whose motion also turns link 3: its rotor stays apart; a
    # payload is the last link's parameters)
    conf = {(h["effect"], h["joint"]) for h in r["confounded_with_inertia_refit"]}
    assert conf == {("rotor_inertia", "joint1"), ("rotor_inertia", "joint2"), ("payload", None)}
    for key in ("gap_before", "gap_after", "noise_floor", "significant", "where", "ranking", "selected"):
        assert key in r
    assert r["where"][0]["dataset"] == "traj2" and r["where"][0]["nrmse"] >= r["where"][-1]["nrmse"]


def test_null_case_selects_nothing(tmp_path):
    folder = G.torque_case(tmp_path / "null", "arm3", [], seed=12, noise=0.01, nominal_friction=True)
    r = diagnose(folder).result
    assert r["selected"] == []
    assert not r["significant"]
    # the noise floor estimate is close to the planted 1 % (residual second differences)
    assert 0.7 < r["noise_floor"] < 1.3


def test_pair_found_in_top_three(tmp_path):
    folder = G.torque_case(tmp_path / "pair", "arm3", ["coulomb_friction", "payload"], seed=13, noise=0.01)
    truth = _truth(folder)["effects"]
    r = diagnose(folder).result
    top = [(s["effect"], s["joint"]) for s in r["selected"]] + [(s["effect"], s["joint"]) for s in r["ranking"][:3]]
    for t in truth:
        assert (t["effect"], t["joint"]) in top


def test_sensor_delay_recovered(tmp_path):
    folder = G.torque_case(tmp_path / "delay", "planar2", ["sensor_delay"], seed=14, noise=0.005)
    d_true = _truth(folder)["effects"][0]["params"]["d"]
    r = diagnose(folder).result
    assert r["selected"][0]["effect"] == "sensor_delay"
    # the truth adds a 2 ms anti-alias lag behind the pure delay; the grid step is 1 ms
    assert abs(r["parameters"]["torque"]["sensor_delay"]["delay [s]"] - (d_true + 0.002)) <= 0.0021


# --- malformed cases ------------------------------------------------------------------------------
def _good_case(tmp_path):
    return G.torque_case(tmp_path / "ok", "planar2", [], seed=1, n_train=1, n_val=1)


def _edit(folder, fn):
    p = folder / "case.yaml"
    cfg = yaml.safe_load(p.read_text())
    fn(cfg)
    p.write_text(yaml.safe_dump(cfg))


@pytest.mark.parametrize(
    "edit, err, words",
    [
        (lambda c: c.pop("robot"), jflex.ConfigError, ["case.yaml", "robot"]),
        (lambda c: c["datasets"][0].update(kind="torques"), jflex.ConfigError, ["datasets[0].kind", "torques"]),
        (lambda c: c["datasets"][1].update(split="test"), jflex.ConfigError, ["datasets[1].split"]),
        (lambda c: c["datasets"][0].update(file="nope.npz"), jflex.ConfigError, ["datasets[0].file", "nope.npz"]),
        (lambda c: c.update(nominal_effects=[{"effect": "magic"}]), jflex.ConfigError, ["nominal_effects[0].effect", "magic"]),
        (lambda c: c.update(nominal_effects=[{"effect": "coulomb_friction", "joint": "wrist"}]), jflex.ConfigError,
         ["nominal_effects[0].joint", "wrist"]),
        (lambda c: c["datasets"].pop(1), jflex.ConfigError, ["validation"]),
        (lambda c: c.update(tool_frame="flange"), jflex.ConfigError, ["tool_frame", "flange"]),
    ],
)
def test_malformed_case_errors(tmp_path, edit, err, words):
    folder = _good_case(tmp_path)
    _edit(folder, edit)
    with pytest.raises(err) as e:
        load_case(folder)
    for w in words:
        assert w in str(e.value)


def test_malformed_npz_errors(tmp_path):
    folder = _good_case(tmp_path)
    z = dict(np.load(folder / "traj0.npz"))
    good = dict(z)
    np.savez(folder / "traj0.npz", **{k: v for k, v in z.items() if k != "tau"})
    with pytest.raises(jflex.DataError, match=r"traj0\.npz: field 'tau'"):
        load_case(folder)
    z["q"] = z["q"][:, :1]
    np.savez(folder / "traj0.npz", **z)
    with pytest.raises(jflex.DataError, match=r"traj0\.npz: field 'q'"):
        load_case(folder)
    np.savez(folder / "traj0.npz", **good)
    z = dict(np.load(folder / "traj1.npz"))
    z["tau"][3, 1] = np.nan
    np.savez(folder / "traj1.npz", **z)
    with pytest.raises(jflex.DataError, match=r"traj1\.npz: field 'tau': contains NaN"):
        load_case(folder)


def test_extra_joint_columns_are_kept(tmp_path):
    folder = _good_case(tmp_path)
    z = dict(np.load(folder / "traj0.npz"))
    N = z["q"].shape[0]
    z["q"] = np.column_stack([z["q"][:, 0], np.linspace(0, 1, N), z["q"][:, 1]])
    z["joints"] = np.array(["shoulder", "wrist", "elbow"])
    for k in ("qd", "qdd"):
        z[k] = np.column_stack([z[k][:, 0], np.zeros(N), z[k][:, 1]])
    z["tau"] = np.column_stack([z["tau"][:, 0], np.zeros(N), z["tau"][:, 1]])
    np.savez(folder / "traj0.npz", **z)
    c = load_case(folder)
    d = c.datasets[0]
    assert d.extra_joints == ("wrist",) and d.arrays["q"].shape == (N, 2) and d.arrays["tau"].shape == (N, 2)


# --- response data sets (joint channels enter as equation error) ------------------------------------
def test_response_validation_set_finds_planted_effect(tmp_path):
    # validation record: applied torques exact, joint angles with 1 mrad white noise
    folder = G.torque_case(tmp_path / "resp", "arm3", ["rotor_inertia"], seed=11, noise=0.01, angle_noise=1e-3)
    truth = _truth(folder)["effects"][0]
    r = diagnose(folder).result
    assert r["responses_not_modelled"] == []
    assert r["where"][0]["dataset"] == "resp2"
    assert [(s["effect"], s["joint"]) for s in r["selected"]][:1] == [("rotor_inertia", truth["joint"])]
    got = r["parameters"]["torque"][f"rotor_inertia@{truth['joint']}"]["Ia [kg m^2]"]
    assert abs(got - truth["params"]["Ia"]) < RTOL_PARAM * truth["params"]["Ia"]
    # the nominal identification already takes up the part of Ia that link 1's CAD tolerance
    # allows (Ia of a vertical first joint adds to link 1's Izz): the shrink is of what is left
    assert r["shrink"] > 70 and r["gap_after"] < 1.7 * r["noise_floor"]


def test_response_null_case_is_within_its_propagated_noise_floor(tmp_path):
    # differentiated angle noise is coloured: the floor propagated from the angles' noise must
    # hold the nominal residual (an underestimated floor would raise a false alarm here)
    folder = G.torque_case(tmp_path / "rnull", "arm3", [], seed=11, noise=0.01, angle_noise=1e-3, nominal_friction=True)
    r = diagnose(folder).result
    assert not r["significant"] and r["selected"] == []
    d = next(d for d in load_case(folder).datasets if d.kind == "response")
    assert np.allclose(d.arrays["angle_noise_rad"], 1e-3, rtol=0.15)
    # the trajectory holds harmonics up to 0.5 Hz: the derivative filter keeps them
    assert 1.0 < d.arrays["cutoff_hz"] < 20.0


def test_response_without_every_joint_channel_is_output_error(tmp_path):
    # a channel set lacking some joint is compared as output error: it needs the rest posture q0
    # (the diagnosis itself is in tests/test_gap_response.py)
    folder = G.torque_case(tmp_path / "rtip", "planar2", [], seed=3, n_train=1, angle_noise=1e-4)
    z = dict(np.load(folder / "resp1.npz"))
    z["y"], z["channels"] = z["y"][:, :1], np.array(["tip_x"])
    np.savez(folder / "resp1.npz", **z)
    with pytest.raises(jflex.DataError, match=r"resp1\.npz: field 'q0': missing"):
        load_case(folder)
    z["q0"] = np.array([0.1, -0.2])
    np.savez(folder / "resp1.npz", **z)
    d = next(d for d in load_case(folder).datasets if d.kind == "response")
    assert "q" not in d.arrays and np.allclose(d.arrays["q0"], [0.1, -0.2])
    z["t"] = z["t"] * (1 + 0.05 * np.linspace(0, 1, len(z["t"])) ** 2)  # non-uniform sampling
    z["y"], z["channels"] = np.zeros((len(z["t"]), 2)), np.array(["shoulder", "elbow"])
    np.savez(folder / "resp1.npz", **z)
    # non-uniform stamps are refused, or made uniform by the data conditioning (never used as they are)
    try:
        d = next(d for d in load_case(folder).datasets if d.kind == "response")
    except jflex.DataError as e:
        assert re.search(r"resp1\.npz: field 't': .*uniform sampling", str(e))
    else:
        dt = np.diff(d.arrays["t"])
        assert np.allclose(dt, dt.mean(), rtol=1e-6)


# --- the candidate terms are the effects' forces ---------------------------------------------------
def test_torque_terms_equal_joint_friction_effect(rotor_case):
    c = load_case(rotor_case)
    s = T.torque_set(c.robot, c.datasets[0])
    fv, fc, fs, vs = 1.3, 0.7, 1.1, STRIBECK_VS[2]
    eff = jflex.effects.JointFriction(["joint2"], viscous=fv, coulomb=fc, stribeck=fs, stribeck_velocity=vs, smoothing=SMOOTHING)
    model = jflex.Model(c.robot, [eff])
    k = 200
    # the 200 samples in one compiled call (op-by-op, one sample at a time, is slow to dispatch)
    force = jax.jit(jax.vmap(lambda q, qd: jflex.effects.JointFriction.generalized_force(eff, model.rigid, model.layout.slots[0], 0.0,
                                                                                        q, qd, jnp.zeros(0))))
    f = np.asarray(force(jnp.asarray(s.q[:k]), jnp.asarray(s.qd[:k])))
    assert f.shape == (k, c.robot.nq)
    cols = np.concatenate([TT.make_term("viscous_friction", 1).columns(s), TT.make_term("stribeck_friction", 1, vs).columns(s)], axis=2)[:k]
    tau = cols @ np.array([fv, fc, fs - fc])
    np.testing.assert_allclose(tau, -f, atol=1e-10)


def test_compensator_term_equals_fourier_compensator(rotor_case):
    c = load_case(rotor_case)
    s = T.torque_set(c.robot, c.datasets[0])
    B = np.array([3.0, -1.0])
    model = jflex.Model(c.robot, [jflex.effects.FourierGravityCompensator(B, joint=1)])
    k = 50
    z = jnp.zeros(0)
    inverse = jax.jit(jax.vmap(lambda q, qd, qdd: jflex.model_inverse_dynamics(model, 0.0, q, qd, qdd, z)))
    tau_model = np.asarray(inverse(*(jnp.asarray(a[:k]) for a in (s.q, s.qd, s.qdd))))  # one compiled call
    assert tau_model.shape == (k, c.robot.nq)
    cols = TT.make_term("gravity_compensator", 1).columns(s)[:k]
    np.testing.assert_allclose(s.F0[:k] + cols @ np.array([B[0], 0.0, B[1], 0.0]), tau_model, atol=1e-8)


def test_linear_model_equals_linearize_of_flexible_joint_model(rotor_case):
    c = load_case(rotor_case)
    k = np.array([3e4, 5e4, 2e4])
    cc = 1e-3 * k
    lm = L.FrequencyModel(c.robot, L.Structure(tuple(L.Site("joint", j) for j in range(3))), "tool")
    q0 = np.array([0.3, 0.8, -1.1])
    P = lm.mats(q0)
    model = jflex.Model(c.robot, [jflex.effects.FlexibleJoints(k, cc, rotor_inertia=[1e-4] * 3, gear_ratio=[50.0] * 3, coupling=False)])
    _, lin = jflex.linear.linearization(model, q0, "theta_*")
    np.testing.assert_allclose(P.M, lin.M, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(P.Kg + np.diag(k), lin.K, rtol=1e-9, atol=1e-6)
    H = lm.frf(np.log(np.r_[k, cc]), q0, np.array([5.0, 20.0]))
    Hj = jflex.frf(model, q0, 2 * np.pi * jnp.array([5.0, 20.0]), hold="theta_*", frame="tool")
    np.testing.assert_allclose(H, np.asarray(Hj), rtol=1e-8, atol=1e-14)


def test_frequency_model_is_jflex_linear_of_its_model(rotor_case):
    """The diagnosis's fast evaluator gives what jflex.linear.frf gives for the jflex.Model it stands
    for (the effects' own Spring, damping laws and Payload, rigid joints held), for every law of
    jflex.effects, a coupled bearing pair, a link hinge and a payload (a rigid body off the tool
    frame's origin: mass, centre of mass, rotational inertia)."""
    c = load_case(rotor_case)
    E = jflex.effects
    sites = (L.Site("joint", 0), L.Site("joint", 1, law=E.Hysteretic(eta=1.0)), L.Site("joint", 2, law=E.Fractional(1.0, 0.4)),
             L.Site("orth", 0, 0), L.Site("orth", 0, 1, coupled=True), L.Site("link", 1, 0, frac=0.4), L.Site("link", 1, 1, frac=0.4))
    lm = L.FrequencyModel(c.robot, L.Structure(sites, payload=10), "tool")
    k = np.array([3e4, 5e4, 2e4, 4e5, 2e5, 8e4, 9e4])
    cc = np.array([30.0, 0.05 * 5e4, 40.0, 400.0, 200.0, 80.0, 90.0])
    pay = np.r_[np.log(1.5), 0.02, -0.03, 0.05, np.log([0.02, 0.03, 0.01]), 0.01, -0.02, 0.005]
    x = np.r_[np.log(k), np.log(cc), pay, np.arctanh(0.3)]
    q0 = np.array([0.3, 0.8, -1.1])
    freq = np.array([5.0, 20.0, 40.0, 90.0])
    H = lm.frf(x, q0, freq)
    model = lm.model(x)
    Hj = jflex.frf(model, lm.posture(q0), 2 * np.pi * jnp.asarray(freq), hold=lm.held, frame="tool")
    np.testing.assert_allclose(H, np.asarray(Hj), rtol=1e-7, atol=1e-14 * np.abs(H).max())
    # and its analytic derivatives in the log parameters match central differences of it
    _, dH = lm.frf_jacobian(x, q0, freq)
    for p in (1, 8, 9, 14, 15, 17, 19, 22, 24):
        h = 1e-6
        e = np.zeros_like(x)
        e[p] = h
        fd = (lm.frf(x + e, q0, freq) - lm.frf(x - e, q0, freq)) / (2 * h)
        np.testing.assert_allclose(dH[p], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_payload_candidate_recovers_mass_and_centre_of_mass(tmp_path):
    """The frequency-side payload candidate is a rigid body, not a point mass: planted off the tool
    frame's origin (2 kg, centre of mass (30, -20, 50) mm, a 6 cm sphere's inertia the candidate
    does not fit; the jflex-family generator's FRFs, 1 % noise, two training postures), it is
    recovered within 3 % in mass and 1 cm in centre of mass (seen: 0.6 %, 1.3 mm; on the full
    frequency grid 1.4 %, 6 mm: the noise on two postures pins the lever arm along the link least),
    and it predicts the held-out posture far better than a point mass at the origin does (seen: a
    residual 37x smaller)."""
    import types

    from jflex.gap.case._case import Dataset
    from jflex.gap.frequency._kinds import ToolPayload

    robot = G.load_robot(G.write_robot(tmp_path, "arm3"))
    sites = [L.Site("joint", j) for j in range(3)]
    k = np.array([4e4, 6e4, 2e4])
    c = 6e-4 * k
    m, com = 2.0, np.array([0.03, -0.02, 0.05])  # (the arm's tool axes are its last link's)
    rng = np.random.default_rng(0)
    sets = []
    freq = G.FRF_FREQ[::2]  # (180 lines: the peaks stay resolved, the fits take half the time)
    for i, q0 in enumerate([np.array([0.0, 0.5, -1.2]), np.array([0.0, 1.0, -0.7]), np.array([0.0, 0.3, -1.6])]):
        H = G.frf_truth(robot, "tool", sites, np.diag(k), [["viscous", float(v), 0.5] for v in c], q0, freq, (m, list(com)))
        H = H * (1 + 0.01 * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape)) / np.sqrt(2))
        sets.append(Dataset(kind="frf", file=None, name=f"p{i}", split="train", arrays=dict(q0=q0, freq=freq, H=H)))
    # what ToolPayload.add asks of the problem
    pb = types.SimpleNamespace(ftrain=sets[:2], _frequency_model=lambda rob, st: L.FrequencyModel(rob, st, "tool"))
    lm0 = L.FrequencyModel(robot, L.Structure(tuple(sites)), "tool")
    x0, _ = L.fit_linear(lm0, np.log(np.r_[k * [1.1, 0.9, 1.1], c]), pb.ftrain)  # the nominal springs
    kind = ToolPayload()
    assert kind.n_params == 4
    lm, x = kind.add(pb, lm0, x0, None)
    pp = lm.payload_parameters(x)
    assert pp["mass [kg]"] == pytest.approx(m, rel=0.03), pp
    assert np.linalg.norm(np.asarray(pp["com (tool frame) [m]"]) - com) < 0.01, pp
    # and the report says so (not "a point mass at the tool frame's origin")
    from jflex.gap.report._html import payload_summary

    ps = payload_summary({"linear": {"payload": pp}}, robot, "tool")
    assert ps["com_m"] == pp["com (tool frame) [m]"] and "centre of mass" in ps["side"]
    point = ToolPayload()
    point.n_params = 1  # the former candidate: a point mass at the tool frame's origin
    lp, xp = point.add(pb, lm0, x0, None)
    held_out = lambda lm_, x_: float(np.sum(L.residual(lm_, x_, sets[2:], peaks=False) ** 2))
    assert held_out(lm, x) < 0.2 * held_out(lp, xp)


def test_a_damping_law_defined_outside_gap_is_a_frequency_candidate():
    """A law written once (here, in a test file) with a loss leaf and a candidate name is tried by
    the diagnosis at every flexible joint, its small-motion law read off its own equations."""
    from jflex.gap._problem import law_candidates

    class Ring(jflex.effects.AbstractDampingLaw):  # loss ~ sqrt(|w|) i: neither viscous nor hysteretic
        k_e: jnp.ndarray
        loss = "k_e"
        candidate = "ring_damping"

        def __init__(self, k_e=1.0):
            self.k_e = jnp.asarray(float(k_e))

        def force(self, K, e, ed, z, P):
            return jnp.zeros_like(e)

        def frequency_term(self, K, omega, P):
            return 1j * self.k_e * jnp.sqrt(jnp.abs(omega)) * K

        @classmethod
        def prototypes(cls):
            return (cls(1.0),)

    assert law_candidates()["ring_damping"] is Ring
    # its kind: tried at the nominally flexible joints only, one parameter (no exponent), and a
    # case may name it
    from jflex.gap.frequency._kinds import frequency_kinds
    from jflex.gap._problem import Candidate
    from jflex.gap.judge._signatures import n_params

    kind = frequency_kinds()["ring_damping"]
    assert kind.law is Ring and kind.per_joint
    assert n_params(Candidate("ring_damping", 0), torque=False) == 1
    assert n_params(Candidate("fractional_damping", 0), torque=False) == 2  # its order is freed too

    class _Pb:  # what the kind asks of the problem
        nominal = {("ring_damping", 2)}

    assert [kind.tried_at(_Pb, j, {1, 2}) for j in range(3)] == [False, True, False]
    w = np.array([4.0, 100.0])
    np.testing.assert_allclose(L.unit_loss(Ring(), w), 1j * np.sqrt(w), rtol=1e-12)
    # the modal iteration's table: exact on power laws, within its stated 1e-5 on others
    wm = np.array([0.37, 12.3, 4567.0])
    np.testing.assert_allclose(L.unit_loss(Ring(), wm, tabulated=True), 1j * np.sqrt(wm), rtol=1e-5)
    for law in (jflex.effects.KelvinVoigt(1.0), jflex.effects.Hysteretic(eta=1.0), jflex.effects.Fractional(1.0, 0.37)):
        np.testing.assert_allclose(L.unit_loss(law, wm, tabulated=True), L.unit_loss(law, wm), rtol=1e-9)
    # a law is a candidate while its class says so (compiled programs keep the class alive): the
    # later tests must not try it
    Ring.candidate = None
    assert "ring_damping" not in law_candidates()


def test_coupled_virtual_pair_equals_full_spd_stiffness(rotor_case):
    """A coupled orthogonal pair is the full 2x2 stiffness [[ka, r sqrt(ka kb)], [., kb]] (r = tanh x_r)."""
    c = load_case(rotor_case)
    joint = [L.Site("joint", j) for j in range(3)]
    pair = [L.Site("orth", 0, 0), L.Site("orth", 0, 1, coupled=True)]
    st = L.Structure(tuple(joint + pair))
    assert st.pairs() == [(3, 4)] and st.n_params() == 11
    lm = L.FrequencyModel(c.robot, st, "tool")
    k = np.array([3e4, 5e4, 2e4, 4e5, 2e4])
    cc = 1e-3 * k
    r = 0.3
    q0 = np.array([0.3, 0.8, -1.1])
    freq = np.array([5.0, 20.0, 40.0])
    H = lm.frf(np.r_[np.log(k), np.log(cc), np.arctanh(r)], q0, freq)
    K = np.diag(k)
    K[3, 4] = K[4, 3] = r * np.sqrt(k[3] * k[4])
    Ht = G.frf_truth(c.robot, "tool", joint + pair, K, [["viscous", v, 0.5] for v in cc], q0, freq)
    np.testing.assert_allclose(H, Ht, rtol=1e-8, atol=1e-14)
    # with r = 0 it is the uncoupled pair
    H0 = lm.frf(np.r_[np.log(k), np.log(cc), 0.0], q0, freq)
    H1 = L.FrequencyModel(c.robot, L.Structure(tuple(joint + pair[:1] + [L.Site("orth", 0, 1)])), "tool").frf(
        np.r_[np.log(k), np.log(cc)], q0, freq)
    np.testing.assert_allclose(H0, H1, rtol=1e-12)


def test_backlash_columns_split_posture_and_engagement_impulse(rotor_case):
    """The backlash term: a posture/velocity column plus one engagement-impulse column per pulse
    width; its fit searches (half-width, engagement time) and keeps every coefficient non-negative."""
    c = load_case(rotor_case)
    s = T.torque_set(c.robot, c.split("train")[0])
    cols = TT.make_term("backlash", 1, (0.01, 0.008)).columns(s)
    assert cols.shape == s.q.shape + (1 + len(TT.BACKLASH_PULSES),)
    assert np.all(np.isfinite(cols)) and np.abs(cols[:, :, 0]).max() > 0
    fit = TT.fit_play_backlash((), 0.0, 1, [s])
    b, te = TT.backlash_hyper(fit.terms[-1].hyper)
    assert te in TT.BACKLASH_ENGAGE and 0 < b <= max(TT.BACKLASH_B) + 0.002 and np.all(fit.theta >= 0)
    assert "engagement [s]" in T.term_parameters(fit, c.robot.joint_names)[f"backlash@{c.robot.joint_names[1]}"]
    # the candidate's refit keeps the better of the two backlash variants by the information criterion
    loaded = TT.fit_loaded_backlash((), 0.0, 1, [s])
    rows = s.tau.size
    bic = lambda f: rows * np.log(f.cost) + f.terms[-1].n_params * np.log(rows)
    chosen = T.fit_with((), 0.0, TT.make_term("backlash", 1), [s])
    assert chosen.cost == min((fit, loaded), key=bic).cost


def test_loaded_backlash_columns_are_the_link_lag_to_first_order(rotor_case):
    """The loaded-gear backlash: the link lags the motor-side angle by tau_j/k + b sgn(tau_j); its
    two columns are the rigid torques' change per unit 1/k and per unit b (finite differences of
    RNEA along that lag, with the same smoothed sign and its rates)."""
    import jax

    c = load_case(rotor_case)
    s = T.torque_set(c.robot, c.split("train")[0])
    j, w = 1, 0.02
    cols = TT.make_term("backlash", j, (TT.LOADED, w)).columns(s)
    assert cols.shape == s.q.shape + (2,)
    np.testing.assert_allclose(cols[:, :, 0], TT.compliance_column(s, j), rtol=0, atol=0)
    tj = TT.smooth_torque(s)[:, j]
    sg = np.tanh(tj / (w * tj.std()))
    sd = np.gradient(sg, s.t)
    lag = [sg, sd, np.gradient(sd, s.t)]
    rnea = jax.vmap(jflex.rnea, in_axes=(None, 0, 0, 0))
    eps = 1e-6
    moved = [a.copy() for a in (s.q, s.qd, s.qdd)]
    for a, d in zip(moved, lag):
        a[:, j] -= eps * d
    fd = (np.asarray(rnea(c.robot, *moved)) - np.asarray(rnea(c.robot, s.q, s.qd, s.qdd))) / eps
    scale = np.abs(cols[:, :, 1]).max()
    assert scale > 0
    np.testing.assert_allclose(cols[:, :, 1], fd, rtol=0, atol=1e-4 * scale)
    fit = TT.fit_loaded_backlash((), 0.0, j, [s])
    assert fit.terms[-1].hyper[1] in TT.BACKLASH_SIGN_WIDTHS and np.all(fit.theta >= 0)
    names = T.term_parameters(fit, c.robot.joint_names)[f"backlash@{c.robot.joint_names[j]}"]
    assert set(names) == {"compliance 1/k [rad/(N m)]", "b [rad]", "sign width [x std(tau)]"}


def test_cli_diagnose_writes_run_folder(rotor_run):
    r = json.loads((rotor_run / "diagnosis.json").read_text())
    assert r["selected"] and (rotor_run / "report.md").is_file() and (rotor_run / "waterfall.png").is_file()


@pytest.mark.slow
def test_frf_joint_flexibility_found(tmp_path):
    folder = G.frf_case(tmp_path / "jf", "arm3", ["joint_flexibility"], seed=7)
    truth = _truth(folder)["effects"][0]
    r = diagnose(folder).result
    assert (r["ranking"][0]["effect"], r["ranking"][0]["joint"]) == ("joint_flexibility", truth["joint"])


def test_frf_noise_floor_of_averaged_repeats(tmp_path):
    # H is the mean of 3 repeats with ~1 % noise each: its floor is ~1 % / sqrt(3), not the
    # spread of one repeat (the old estimate, which hid small effects under the floor)
    from jflex.gap._problem import Problem
    from jflex.gap import noise_floor

    folder = G.frf_case(tmp_path / "null", "arm3", [], seed=21)
    case = load_case(folder)
    pb = Problem(case)
    ev = pb.evaluate(pb.nominal_state())
    fl = noise_floor(pb, ev, case).per_dataset
    assert all(0.4 < v < 0.8 for v in fl.values()), fl


def _candidate_shrinks(folder, cands) -> dict:
    """Percentage of the nominal excess gap each candidate closes, refitted alone on the nominal."""
    from jflex.gap._problem import Problem
    from jflex.gap import gap_summary, noise_floor

    case = load_case(folder)
    pb = Problem(case)
    nom = pb.nominal_state()
    ev0 = pb.evaluate(nom)
    floor = noise_floor(pb, ev0, case).per_dataset
    exc0 = gap_summary(ev0, floor)[2]
    return {c: 100 * (1 - gap_summary(pb.evaluate(pb.add(nom, c)), floor)[2] / exc0) for c in cands}


def test_frf_fractional_damping_beats_its_rivals(tmp_path):
    # a fractional law planted at one joint: refitted at that joint it closes most of the excess
    # gap, more than the same law elsewhere or a hysteretic law there (the three closest rivals
    # of the bench case; the full diagnosis is the slow test below)
    from jflex.gap._problem import Candidate

    folder = G.frf_case(tmp_path / "fd", "arm3", ["fractional_damping"], seed=504)
    truth = _truth(folder)["effects"][0]
    names = load_case(folder).robot.joint_names
    j = names.index(truth["joint"])
    other = (j + 2) % 3
    shrink = _candidate_shrinks(folder, [Candidate("fractional_damping", j), Candidate("fractional_damping", other),
                                         Candidate("hysteretic_damping", j)])
    best = max(shrink, key=shrink.get)
    assert best == Candidate("fractional_damping", j), shrink
    assert shrink[best] > 50, shrink


@pytest.mark.slow
def test_frf_link_flexibility_found(tmp_path):
    # bending hinges off mid-span with coupled stiffness, modes above the measured band: only a
    # posture-dependent softening shows; the candidate must still be found and close the gap.
    # Seeds that bend link2 (link1 of arm3 is 0.15 m long: its bending is the tilt of joint2,
    # a known confounded pair)
    # (small version: the truth and its closest rivals refitted, not the whole diagnosis)
    from jflex.gap._problem import Candidate

    folder = G.frf_case(tmp_path / "lf", "arm3", ["link_flexibility"], seed=502 if SLOW else 22)
    truth = _truth(folder)["effects"][0]
    if SLOW:
        r = diagnose(folder).result
        assert (r["selected"][0]["effect"], r["selected"][0]["link"]) == ("link_flexibility", truth["link"])
        assert r["shrink"] > 60
        return
    i = list(load_case(folder).robot.link_names).index(truth["link"])
    shrink = _candidate_shrinks(folder, [Candidate("link_flexibility", i), Candidate("orthogonal_compliance", i),
                                         Candidate("orthogonal_compliance", i + 1), Candidate("payload")])
    best = max(shrink, key=shrink.get)
    assert best == Candidate("link_flexibility", i), shrink
    assert shrink[best] > 60, shrink


@pytest.mark.slow
def test_gap_bench_small(tmp_path):
    from jflex_family.bench import run_bench

    s = run_bench(tmp_path, size="small", limit=None if SLOW else 3, progress=lambda m: None)
    assert s["cases"] >= 3
    assert s["top1"] >= (0.9 if SLOW else 0.5)
