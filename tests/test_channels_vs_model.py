"""Torque channels judged against the nominal model, on logs made here by NumPy and Pinocchio (no
jflex generator): a channel reading a constant offset plus a little quantised noise where the
model predicts newton-metres is dead and left out of the gap (unless the case keeps it); a channel
clipped for 3 % of its samples has those samples masked out of the fit and the gap, the rest kept;
a light joint logged in motor current (its torque constant forgotten) on a robot whose first joint
carries nearly all the torque is raised as a scale suspect."""

from __future__ import annotations

import pathlib
import sys

import numpy as np
import pinocchio as pin
import yaml

from jflex.gap import load_case
from jflex.gap._problem import Problem
from jflex.gap.torque._scale import torque_scale_suspects

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import robots as R  # noqa: E402
from independent import signals as S  # noqa: E402

FS = 200.0


def _record(urdf, seed, center, amp, T=20.0, noise=0.01):
    """Angles of a Fourier motion and the Pinocchio inverse dynamics along it, plus white noise."""
    traj = S.Fourier(np.random.default_rng(seed), center=center, amp=amp, f0=0.2, harmonics=5)
    t = np.arange(int(T * FS)) / FS
    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    q, qd, qdd = traj(t, 0), traj(t, 1), traj(t, 2)
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    return t, q, tau + noise * np.random.default_rng(seed + 100).standard_normal(tau.shape)


def _case(folder, urdf, records, options=None):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robot.urdf").write_text(urdf)
    entries = []
    for name, split, (t, q, tau) in records:
        np.savez(folder / f"{name}.npz", t=t, q=q, tau=tau)
        entries.append({"kind": "torque", "file": f"{name}.npz", "split": split, "name": name})
    cfg = {"robot": "robot.urdf", "datasets": entries, "options": {"refit_inertia": False, **(options or {})}}
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return load_case(folder)


ARM = dict(center=[0.0, 0.7, -1.3], amp=[0.8, 0.5, 0.6])


def test_a_dead_channel_is_left_out_of_the_gap_unless_kept(tmp_path):
    recs = [("train", "train", _record(R.ARM3_URDF, 1, **ARM)), ("val", "validation", _record(R.ARM3_URDF, 2, **ARM))]
    t, q, tau = recs[1][2]
    rng = np.random.default_rng(3)
    dead = tau.copy()
    # a sensor left unpowered: an offset and 0.002 N m of noise on 16 levels
    dead[:, 2] = 0.31 + np.round(np.clip(rng.normal(0, 0.002, t.size), -0.0059, 0.0059) / 0.0008) * 0.0008
    assert 12 <= np.unique(dead[:, 2]).size <= 16 and np.std(tau[:, 2]) > 500 * np.std(dead[:, 2])
    case = _case(tmp_path / "c", R.ARM3_URDF, [recs[0], ("val", "validation", (t, q, dead))])
    assert case.datasets[1].excluded_channels == ()  # the data layer alone cannot tell it
    pb = Problem(case)
    assert "joint3" in pb.excluded["val"] and "dead against the model" in pb.excluded["val"]["joint3"]
    ev = pb.evaluate(pb.nominal_state())["val"]
    assert "joint3" not in ev["channels"]
    # the other channels are the model's torque plus 0.01 N m noise: a gap of a few per cent at most
    assert ev["nrmse"] < 3.0, ev["channels"]
    kept = Problem(_case(tmp_path / "k", R.ARM3_URDF, [recs[0], ("val", "validation", (t, q, dead))],
                         options={"keep_channels": ["joint3"]}))
    assert "joint3" not in kept.excluded.get("val", {})
    assert kept.evaluate(kept.nominal_state())["val"]["channels"]["joint3"] > 1000.0


def test_a_clipped_channel_has_its_clipped_samples_masked_and_the_rest_kept(tmp_path):
    clean = [("train", "train", _record(R.ARM3_URDF, 4, **ARM)), ("val", "validation", _record(R.ARM3_URDF, 5, **ARM))]
    clipped, levels = [], []
    for name, split, (t, q, tau) in clean:
        level = np.quantile(tau[:, 1], 0.97)  # the sensor's range ends below the motion's peaks
        c = tau.copy()
        c[:, 1] = np.minimum(c[:, 1], level)
        clipped.append((name, split, (t, q, c)))
        levels.append(level)
    case = _case(tmp_path / "c", R.ARM3_URDF, clipped)
    twin = Problem(_case(tmp_path / "t", R.ARM3_URDF, clean))
    for d, (_, _, (t, q, tau)), level in zip(case.datasets, clean, levels):
        assert d.excluded_channels == ()
        np.testing.assert_array_equal(~d.arrays["tau_valid"][:, 1], tau[:, 1] >= level)
        assert d.arrays["tau_valid"][:, [0, 2]].all()
    pb = Problem(case)
    s = pb.tval[0]
    clipped_rows = np.interp(s.t, clean[1][2][0], (clean[1][2][2][:, 1] >= levels[1]).astype(float)) > 0
    assert np.all(s.weight[clipped_rows, 1] == 0) and s.weight[:, [0, 2]].all()
    assert 0.03 <= 1 - s.weight[:, 1].mean() < 0.2  # the clipped 3 %, widened by the filter's reach
    ev, ev_twin = pb.evaluate(pb.nominal_state())["val"], twin.evaluate(twin.nominal_state())["val"]
    # the clipped samples off the gap: joint2 is judged as its clean twin is, not by the clipped peaks
    miss = clean[1][2][2][:, 1] - clipped[1][2][2][:, 1]
    clip_nrmse = 100 * np.sqrt(np.mean(miss**2)) / np.std(clean[1][2][2][:, 1])
    assert abs(ev["channels"]["joint2"] - ev_twin["channels"]["joint2"]) < 0.2 * clip_nrmse, (ev["channels"],
                                                                                          ev_twin["channels"], clip_nrmse)
    assert ev["nrmse"] < ev_twin["nrmse"] + 0.5


TORSO_URDF = """<?xml version="1.0"?>
<robot name="torso_arm">
  <link name="base_link"/>
  <joint name="torso" type="revolute">
    <parent link="base_link"/><child link="torso_link"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="900" velocity="2"/>
  </joint>
  <link name="torso_link">
    <inertial><origin xyz="0.35 0 0"/><mass value="40.0"/>
      <inertia ixx="0.5" ixy="0" ixz="0" iyy="1.6" iyz="0" izz="1.6"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="torso_link"/><child link="upper"/>
    <origin xyz="0.7 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="90" velocity="2"/>
  </joint>
  <link name="upper">
    <inertial><origin xyz="0.15 0 0"/><mass value="1.5"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.012"/></inertial>
  </link>
  <joint name="wrist" type="revolute">
    <parent link="upper"/><child link="hand"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="20" velocity="2"/>
  </joint>
  <link name="hand">
    <inertial><origin xyz="0.06 0 0"/><mass value="0.4"/>
      <inertia ixx="0.0003" ixy="0" ixz="0" iyy="0.0008" iyz="0" izz="0.0008"/></inertial>
  </link>
</robot>
"""


def test_a_light_joint_logged_in_current_is_a_scale_suspect_though_the_torso_dominates(tmp_path):
    kw = dict(center=[0.2, -0.3, 0.4], amp=[0.4, 0.6, 0.8], noise=0.002)
    for gain in (0.1, 8.0):
        recs = []
        for name, split, seed in (("train", "train", 6), ("val", "validation", 7)):
            t, q, tau = _record(TORSO_URDF, seed, **kw)
            share = np.sum(tau**2, axis=0) / np.sum(tau**2)
            assert share[0] > 0.95 and share[2] < 0.05  # the wrist carries under 5 % of the torque energy
            tau[:, 2] *= gain  # the wrist's current, its torque constant left out of the case
            recs.append((name, split, (t, q, tau)))
        pb = Problem(_case(tmp_path / f"g{gain}", TORSO_URDF, recs))
        found = torque_scale_suspects(pb, pb.nominal_state())
        assert [d["joint"] for d in found] == ["wrist"], found
        assert abs(found[0]["gain"] / gain - 1) < 0.1, found
