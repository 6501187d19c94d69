"""A coupled wrist whose encoders read motor angles (coupling.angles: motor), as the Staubli TX
series logs them: the joint angles the case loads equal K^-1 x the scaled motor angles written
here by NumPy, and the joint torques K^T x the scaled motor torques (made here from known joint
torques); with the default (joint angles) the columns load unchanged."""

import pathlib
import sys

import numpy as np
import pytest
import yaml

import jflex
from jflex.gap import load_case

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import robots as R  # noqa: E402

JOINTS = ["joint1", "joint2", "joint3"]
RATIO = np.array([100.0, 45.0, -32.0])  # motor turns per joint turn
ZERO = np.array([0.0, 50.0, -70.0])  # raw motor reading at each joint's zero [rad]
KT = np.array([2.0, 0.5, 0.4])  # motor current to motor torque on the joint side, per motor [N m/A]
K = np.array([[1.0, 0.0], [1.0, 1.0]])  # joints 2, 3: motor 3 turns with both (joint-side units)


def _case(tmp_path, angles):
    rng = np.random.default_rng(0)
    t = np.arange(400) * 0.01
    q = np.column_stack([0.3 * np.sin(1.1 * t), 0.5 * np.sin(0.7 * t + 1), 0.4 * np.cos(1.3 * t)])
    tau = rng.normal(size=(t.size, 3))
    m = q.copy()
    m[:, 1:] = q[:, 1:] @ K.T  # motor angles, joint-side units
    raw_m = m * RATIO + ZERO
    motor_tau = tau.copy()
    motor_tau[:, 1:] = np.linalg.solve(K.T, tau[:, 1:].T).T  # tau = K^T motor torques
    raw_i = motor_tau / KT
    cols = {"time": t, **{f"m{k + 1}": raw_m[:, k] for k in range(3)}, **{f"i{k + 1}": raw_i[:, k] for k in range(3)}}
    lines = [",".join(cols)] + [",".join(f"{cols[c][r]:.15g}" for c in cols) for r in range(t.size)]
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "robot.urdf").write_text(R.ARM3_URDF)
    entry = {"kind": "torque", "file": "log.csv", "columns": {
        "time": "time", "position": {j: f"m{k + 1}" for k, j in enumerate(JOINTS)},
        "torque": {j: f"i{k + 1}" for k, j in enumerate(JOINTS)}},
        "scale": {**{f"m{k + 1}": float(1 / RATIO[k]) for k in range(3)}, **{f"i{k + 1}": float(KT[k]) for k in range(3)}},
        "offset": {f"m{k + 1}": float(ZERO[k]) for k in range(3)},
        "coupling": {"joints": ["joint2", "joint3"], "matrix": K.tolist(), **({"angles": angles} if angles else {})}}
    cfg = {"robot": "robot.urdf", "datasets": [dict(entry, split="train"), dict(entry, split="validation", name="v")]}
    (tmp_path / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return load_case(tmp_path).datasets[0].arrays, q, tau, m


def test_motor_encoder_angles_become_joint_angles(tmp_path):
    a, q, tau, _ = _case(tmp_path, "motor")
    np.testing.assert_allclose(a["q"], q, atol=1e-12)
    np.testing.assert_allclose(a["tau"], tau, atol=1e-12)
    # the loader's own rates (central differences) are those of the joint angles
    np.testing.assert_allclose(a["qd"], np.gradient(q, a["t"], axis=0), atol=1e-9)


def test_joint_angles_by_default(tmp_path):
    a, q, tau, m = _case(tmp_path, None)
    np.testing.assert_allclose(a["q"], m, atol=1e-12)
    assert np.abs(a["q"][:, 2] - q[:, 2]).max() > 0.1
    np.testing.assert_allclose(a["tau"], tau, atol=1e-12)


def test_unknown_angles_value_is_refused(tmp_path):
    with pytest.raises(jflex.ConfigError, match="coupling.angles"):
        _case(tmp_path, "encoder")
