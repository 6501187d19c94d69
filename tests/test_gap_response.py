"""Tip-only response data sets in the gap diagnosis (output error): a planted effect seen only
through the tool position is found and closes the gap, a null case selects nothing, malformed
records get errors naming the file and the field, and the simulated model equals the fitted
torque terms. (Springs simulated in the tip set and failed simulations:
tests/test_gap_response_simulation.py; the two files run on separate workers.)"""

from __future__ import annotations

import json
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

import jflex
from jflex_family import generate as G
from jflex.gap.response import _response as R
from jflex.gap.torque import _set as T
from jflex.gap.torque import _terms as TT
from jflex.gap._effect_term import STRIBECK_VS
from jflex.gap import diagnose, load_case

TIP_NOISE = 1e-4  # [m]


def _truth(folder):
    folder = pathlib.Path(folder)
    return json.loads((folder.parent / f"{folder.name}.truth.json").read_text())


def test_rotor_inertia_seen_at_the_tip_is_found(tmp_path):
    # torque training sets, validation only through the tool position of a short motion from rest
    folder = G.torque_case(tmp_path / "tip", "arm3", ["rotor_inertia"], seed=11, noise=0.01, tip_noise=TIP_NOISE)
    truth = _truth(folder)["effects"][0]
    r = diagnose(folder).result
    assert r["responses_output_error"] == ["tip2"] and r["responses_not_modelled"] == []
    assert r["significant"]
    assert [(s["effect"], s["joint"]) for s in r["selected"]][:1] == [("rotor_inertia", truth["joint"])]
    assert r["gap_before"] > 10 and r["gap_after"] < 0.1 * r["gap_before"]
    assert r["shrink"] > 80
    got = r["parameters"]["torque"][f"rotor_inertia@{truth['joint']}"]["Ia [kg m^2]"]
    assert abs(got - truth["params"]["Ia"]) < 0.05 * truth["params"]["Ia"]
    # where: tip channels in time windows of the response record
    w = r["where"][0]
    assert w["dataset"] == "tip2" and w["channel"] in R.TIP_CHANNELS and "window_s" in w
    assert {s["channel"] for s in r["where"] if s["dataset"] == "tip2"} <= set(R.TIP_CHANNELS)
    assert r["steps"][-1]["per_dataset"]["tip2"] == pytest.approx(r["gap_after"])


def test_null_tip_case_selects_nothing(tmp_path):
    folder = G.torque_case(tmp_path / "null", "arm3", [], seed=12, noise=0.01, tip_noise=TIP_NOISE)
    r = diagnose(folder).result
    assert r["selected"] == [] and not r["significant"]
    # the floor from the residual's second difference matches the planted tip noise
    d = next(d for d in load_case(folder).datasets if d.kind == "response")
    s = R.response_set(load_case(folder).robot, d, "tool")
    expected = np.sqrt(np.mean((TIP_NOISE / s.scale) ** 2)) * 100
    assert 0.7 * expected < r["noise_floor"] < 1.3 * expected


def test_simulation_model_torques_equal_the_fitted_terms(tmp_path):
    # the simulated effect is minus the torque columns it stands for: inverse dynamics of the
    # simulation model along a torque set = the torque fit's prediction
    folder = G.torque_case(tmp_path / "sim", "planar2", [], seed=4, n_train=1, n_val=1)
    c = load_case(folder)
    s = T.torque_set(c.robot, c.datasets[0])
    # a user's effect (an EffectCandidate) enters the simulation as itself, with its fitted values
    from jflex.gap import EffectCandidate
    from jflex.gap._effect_term import EffectTerm
    from jflex.identify import Free

    user = EffectCandidate("my_damper", jflex.effects.JointFriction([c.robot.joint_names[1]], viscous=1.0),
                           free=(Free("v", lambda m: m.effects[0].viscous),), joint=c.robot.joint_names[1]).bind(c.robot)
    terms = (TT.make_term("viscous_friction", 0), TT.make_term("stribeck_friction", 1, STRIBECK_VS[2]), TT.make_term("rotor_inertia", 1),
             TT.make_term("gravity_compensator", 0), TT.make_term("payload", None), TT.make_term("sensor_delay"),
             EffectTerm(user, 1))
    theta = np.array([0.7, 1.1, 0.4, 0.05, 2.0, -1.0, 0.5, 0.3, 1.2, 0.02, 0.01, -0.03, 0.01, 0.0, 0.02, 0.0, 0.0, 0.03, 0.6])
    fit = T.TorqueFit(terms, 0.0, theta, 0.0)
    model = R.simulation_model(c.robot, fit)
    k = 40
    z = jnp.zeros(0)
    # the 40 samples in one compiled call (op-by-op, one sample at a time, took 9 s to dispatch)
    inverse = jax.jit(jax.vmap(lambda q, qd, qdd: jflex.model_inverse_dynamics(model, 0.0, q, qd, qdd, z)))
    tau = np.asarray(inverse(*(jnp.asarray(a[:k]) for a in (s.q, s.qd, s.qdd))))
    assert tau.shape == (k, c.robot.nq)
    np.testing.assert_allclose(tau, T.predict(fit, s)[:k], rtol=1e-9, atol=1e-9)


# --- malformed tip responses ------------------------------------------------------------------------
@pytest.fixture
def tip_folder(tmp_path):
    return G.torque_case(tmp_path / "ok", "planar2", [], seed=1, n_train=1, n_val=1, tip_noise=TIP_NOISE)


def _rewrite(folder, fn):
    z = dict(np.load(folder / "tip1.npz"))
    fn(z)
    np.savez(folder / "tip1.npz", **z)


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda z: z.pop("q0"), ["tip1.npz", "field 'q0'", "missing", "rest"]),
        (lambda z: z.update(q0=np.zeros(3)), ["tip1.npz", "field 'q0'", "(2,)", "(3,)"]),
        (lambda z: z.update(q0=np.zeros((1, 2))), ["tip1.npz", "field 'q0'", "(2,)"]),
        (lambda z: z.update(channels=np.array(["tip_x", "tip_y", "tip_w"])), ["tip1.npz", "field 'channels'", "tip_w"]),
        (lambda z: z.update(y=z["y"][:, :2]), ["tip1.npz", "field 'channels'", "3 names for 2 columns"]),
        (lambda z: z.update(y_repeats=np.zeros((2, 5, 3))), ["tip1.npz", "field 'y_repeats'"]),
        (lambda z: z.update(t=z["t"][::-1].copy()), ["tip1.npz", "field 't'", "increasing"]),
    ],
)
def test_malformed_tip_response_errors(tip_folder, edit, words):
    _rewrite(tip_folder, edit)
    with pytest.raises(jflex.DataError) as e:
        load_case(tip_folder)
    for w in words:
        assert w in str(e.value), str(e.value)


def test_tip_response_needs_tool_frame_and_train_split_needs_a_validation_record(tip_folder):
    p = tip_folder / "case.yaml"
    cfg = yaml.safe_load(p.read_text())
    cfg.pop("tool_frame")
    p.write_text(yaml.safe_dump(cfg))
    with pytest.raises(jflex.ConfigError, match=r"case\.yaml: field 'tool_frame': .*datasets\[1\].*tip1\.npz"):
        load_case(tip_folder)
    # a tip record in the train split fits the simulated candidates when a tip validation record
    # judges them (tests/test_gap_simulated.py); it is listed as not used only without one
    from jflex.gap._problem import Problem

    cfg["tool_frame"] = "tool"
    cfg["datasets"][1]["split"] = "train"
    cfg["datasets"].append(dict(kind="response", file="tip1.npz", split="validation", name="tip1v"))
    p.write_text(yaml.safe_dump(cfg))
    pb = Problem(load_case(tip_folder))
    assert pb.responses == [] and [s.name for s in pb.rtrain] == ["tip1"] and [s.name for s in pb.rval] == ["tip1v"]


def test_play_candidate_changes_nothing_until_a_spring_is_held_there():
    """Backlash on tip records alone is play inside a simulated spring: without a spring at its
    joint it adds nothing, so the diagnosis neither refits nor ranks it (``Problem.changes``);
    with torque training data it is the torque side's own term, always a candidate."""
    import types

    from jflex.gap._problem import Candidate, Problem, State

    def problem(ttrain=(), springs=()):
        return types.SimpleNamespace(ttrain=list(ttrain), rtrain=["tr"], rval=["va"], ftrain=[],
                                     sim_springs=lambda st: dict(springs))

    st = State(None, None, None)
    back, flex = Candidate("backlash", 1), Candidate("joint_flexibility", 1)
    assert not Problem.changes(problem(), st, back)
    assert Problem.changes(problem(springs={1: (1e3, 1.0, 0.01)}), st, back)
    assert not Problem.changes(problem(springs={0: (1e3, 1.0, 0.01)}), st, back)
    assert Problem.changes(problem(ttrain=["t"]), st, back)
    assert Problem.changes(problem(), st, flex)
