"""The noise floor and the verdict on cases with real-log traits made by independent code
(benchmarks/gap/independent/reallog.py: Pinocchio, SciPy, NumPy): a periodic log's floor is its
added noise (through the same low-pass as the data) within 20 %; a drifting friction is not
hidden as noise; a null case with 10 % CAD error and coloured noise raises no alarm."""

import pathlib
import sys

import numpy as np
import pytest

import jflex
from jflex.gap.judge._noise import noise_floor
from jflex.gap._problem import Problem
from jflex.data._signal import zero_phase_lowpass

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
reallog = pytest.importorskip("independent.reallog")


def test_periodic_log_floor_within_20_percent_of_the_true_noise(tmp_path):
    folder, truth = reallog.make_reallog_case(tmp_path / "periodic", "periodic", seed=0, small=True)
    case = jflex.gap.load_case(folder)
    pb = Problem(case)
    s = pb.tval[0]
    ev = {s.name: dict(kind="torque", nrmse=1.0, channels={}, neff=1.0, resid=np.zeros_like(s.tau))}
    det = noise_floor(pb, ev, case).details
    d = det[s.name]
    assert "scatter between periods" in d["method"] and not d["failed"]
    # the white noise the generator added, through the data's own low-pass (parallel filtering):
    # its power gain measured on a long white record
    h = float(np.mean(np.diff(case.split("validation")[0].arrays["t"])))
    w = np.random.default_rng(0).standard_normal((200_000, 1))
    gain = float(zero_phase_lowpass(w, h, s.cutoff)[5000:-5000].std())
    true = np.array([truth["noise_std_nm"][n] for n in pb.names]) * gain / s.scale * 100
    got = np.array([d["channels"][n] for n in pb.names])
    np.testing.assert_allclose(got, true, rtol=0.2)
    assert d["low"] < d["floor"] < d["high"]


@pytest.mark.heavy
def test_drifting_friction_is_not_within_noise(tmp_path):
    folder, truth = reallog.make_reallog_case(tmp_path / "drift", "drifting_friction", seed=0, small=True)
    r = jflex.gap.diagnose(folder).result
    assert r["verdict"] != "within_noise" and r["significant"]


@pytest.mark.slow
def test_null_case_with_cad_error_and_coloured_noise_raises_no_alarm(tmp_path):
    folder, truth = reallog.make_reallog_case(tmp_path / "null", "null_cad_ar1", seed=0, small=True)
    r = jflex.gap.diagnose(folder).result
    assert r["verdict"] not in ("explained", "partly_explained") and not r["selected"]
