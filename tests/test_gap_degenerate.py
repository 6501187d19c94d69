"""Degenerate validation data never get a confident verdict: torques of zeros, torques scaled
past the float range, a dead channel, an FRF of zeros, a noise floor that failed. The case is one
of the independent bench's (Pinocchio + NumPy), then broken on purpose."""

import copy
import pathlib
import sys

import numpy as np
import pytest

import jflex
from jflex import DataError
from jflex.gap import verdict
from jflex.gap.judge._degenerate import frf_set, torque_channels
from jflex.gap.judge._noise import noise_floor
from jflex.gap._problem import Problem
from jflex.gap.judge._where import where

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import make_case  # noqa: E402


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    folder, _ = make_case(tmp_path_factory.mktemp("deg") / "null", kind="torque", robot="arm3", effects=(), seed=3,
                          small=True)
    return jflex.gap.load_case(folder)


def _broken(case, fn, split="validation"):
    c = copy.copy(case)
    c.datasets = [copy.copy(d) for d in case.datasets]
    for d in c.datasets:
        d.arrays = dict(d.arrays)
        if d.split == split:
            d.arrays["tau"] = fn(np.array(d.arrays["tau"], float))
    return c


@pytest.mark.parametrize("fn, words", [
    (lambda tau: np.zeros_like(tau), "no channel carries a torque signal"),
    (lambda tau: tau * 1e300, "1e+300 times the nominal model's"),
    (lambda tau: tau * 1e6, "times the nominal model's"),
])
def test_validation_torques_without_signal_are_refused_by_name(case, fn, words):
    name = case.split("validation")[0].name
    with pytest.raises(DataError) as e:
        Problem(_broken(case, fn))
    msg = str(e.value)
    assert f"data set '{name}'" in msg and words.replace("1e+300", "") in msg


def test_a_dead_channel_is_left_out_and_named(case):
    names = case.robot.joint_names

    def dead(tau):
        tau[:, 2] = 0.013  # a channel stuck at one reading
        return tau

    pb = Problem(_broken(case, dead))
    v = case.split("validation")[0].name
    assert set(pb.excluded) == {v} and names[2] in pb.excluded[v] and "constant" in pb.excluded[v][names[2]]
    # the gap and the "where" table ignore it
    from jflex.gap._problem import State
    import jflex.gap.torque._set as T

    st = State(T.fit_terms((), 0.0, pb.ttrain), None, None)
    ev = pb.evaluate(st)
    assert names[2] not in ev[v]["channels"] and set(ev[v]["weights"]) == set(names[:2])
    floor = noise_floor(pb, ev, pb.case).per_dataset
    assert all(w["channel"] != names[2] for w in where(pb, ev, floor, pb.case))


def test_a_dead_training_channel_weighs_nothing_in_the_fit(case):
    def dead(tau):
        tau[:, 1] = 0.0
        return tau

    pb = Problem(_broken(case, dead, split="train"))
    assert all(np.isinf(s.scale[1]) and np.all(s.tau[:, 1] == 0) for s in pb.ttrain)
    assert all(np.isfinite(s.scale[1]) for s in pb.tval)


def test_channels_the_data_layer_excluded_are_left_out(case):
    c = copy.copy(case)
    c.datasets = [copy.copy(d) for d in case.datasets]
    v = next(d for d in c.datasets if d.split == "validation")
    v.excluded_channels = (case.robot.joint_names[0],)
    pb = Problem(c)
    assert list(pb.excluded[v.name]) == [case.robot.joint_names[0]]
    assert "data conditioning" in pb.excluded[v.name][case.robot.joint_names[0]]


def test_an_frf_of_zeros_or_nan_is_refused():
    H = np.zeros((50, 3, 3), complex)
    assert "zero throughout" in frf_set(H)
    H[3, 0, 0] = np.nan
    assert "non-finite" in frf_set(H)
    H = np.ones((50, 3, 3), complex) * 1e-6
    assert frf_set(H) is None


def test_torque_channel_checks():
    rng = np.random.default_rng(0)
    F0 = rng.normal(size=(200, 2))
    tau = F0 + 0.01 * rng.normal(size=(200, 2))
    assert torque_channels("x", tau, F0, ("a", "b")) == ({}, None)
    tau[5, 1] = np.inf
    bad, why = torque_channels("x", tau, F0, ("a", "b"))
    assert "non-finite" in bad["b"] and why is None


def test_a_failed_floor_gives_no_confident_verdict(case):
    # a residual of exact zeros: the floor saw no noise at all; it is reported failed, never 0 %
    pb = Problem(case)
    s = pb.tval[0]
    ev = {s.name: dict(kind="torque", nrmse=3.0, channels={n: 3.0 for n in pb.names}, neff=100.0,
                       resid=np.zeros_like(s.tau))}
    nf = noise_floor(pb, ev, case)
    fl, det = nf.per_dataset, nf.details
    assert det[s.name]["failed"] and "zero" in det[s.name]["reason"] and fl[s.name] == 0.0
    assert verdict(True, False, True, 100.0, floor_known=False) == "floor_unknown"
