"""What case.yaml and its data must not slip past load_case: unknown kept channels, a nominal
delay longer than the record, training data too short to identify the nominal model, magnitudes
whose squares overflow, an empty modal table, a validation set that holds the training samples,
a massless or absurdly heavy link, a robot without joints. Errors name the field; warnings are
Python warnings that also reach the report's data notes."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import yaml

import jflex
from jflex.gap import load_case
from jflex.gap.report._html import data_notes
from test_case_schema import write_case


def _edit(folder, fn):
    cfg = yaml.safe_load((folder / "case.yaml").read_text())
    fn(cfg)
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return folder


def _traj(folder, name, n, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    np.savez(folder / name, t=t, q=np.column_stack([np.sin(t), np.cos(3 * t)]), tau=rng.normal(size=(n, 2)))


def _load_quiet(folder):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        case = load_case(folder)
    return case, [str(w.message) for w in caught]


def _long_case(tmp_path, n=400):
    folder = write_case(tmp_path / "c")
    for i in range(2):
        _traj(folder, f"traj{i}.npz", n, seed=i)
    return folder


def test_keep_channels_unknown_joint_lists_the_valid_ones(tmp_path):
    folder = _edit(_long_case(tmp_path), lambda c: c.update(options={"keep_channels": ["nojoint"]}))
    with pytest.raises(jflex.ConfigError, match=r"options.keep_channels': unknown joints \['nojoint'\]; expected "
                       r"joint names of the model \['shoulder', 'elbow'\]"):
        load_case(folder)
    _edit(folder, lambda c: c.update(options={"keep_channels": ["elbow"]}))
    _load_quiet(folder)


@pytest.mark.parametrize("delay,ok", [(1e6, False), (1.0, False), (0.005, True)])
def test_nominal_delay_well_below_the_record(tmp_path, delay, ok):
    # records of 400 samples at 100 Hz: 3.99 s
    folder = _edit(_long_case(tmp_path), lambda c: c.update(
        nominal_effects=[{"effect": "sensor_delay", "joint": "all", "value": delay}]))
    if ok:
        _load_quiet(folder)
        return
    with pytest.raises(jflex.ConfigError, match=r"nominal_effects\[0\]\.value': a delay of .* s against the record "
                       r"'traj\d' of 3.99 s: expected a delay well below the record length"):
        load_case(folder)


def test_short_training_set_warned_and_noted(tmp_path):
    folder = _long_case(tmp_path)
    _traj(folder, "traj0.npz", 25)
    with pytest.warns(UserWarning, match=r"too short to identify the nominal model: 25 samples x 2 joints = 50 "
                      r"equations for 20 parameters"):
        case = load_case(folder)
    assert any("too short" in w for w in case.warnings)
    notes = data_notes({"conditioning": {d.name: d.conditioning for d in case.datasets}})
    assert any(n.startswith("Warning ('traj0')") and "too short" in n for n in notes)
    # 10 equations per parameter: 100 samples of 2 joints for the 20 inertial parameters is enough
    _traj(folder, "traj0.npz", 100)
    assert not any("too short" in w for w in _load_quiet(folder)[1])


def test_frf_magnitudes_whose_squares_overflow(tmp_path):
    folder = _long_case(tmp_path)
    f = np.linspace(1, 50, 30)
    H = (1e-6 / (1 + 1j * f))[:, None, None] * np.ones((30, 3, 3))
    np.savez(folder / "frf.npz", q0=np.zeros(2), freq=f, H=H * 1e300)
    _edit(folder, lambda c: (c["datasets"].append({"kind": "frf", "file": "frf.npz", "split": "validation"}),
                             c.update(tool_frame="tool")))
    top = f"{np.abs(H * 1e300).max():.3g}".replace("+", r"\+")
    with pytest.raises(jflex.DataError, match=rf"frf.npz: field 'H': magnitudes up to {top} overflow the squared sums"):
        load_case(folder)
    np.savez(folder / "frf.npz", q0=np.zeros(2), freq=f, H=H)
    _load_quiet(folder)


def test_torques_whose_squares_overflow(tmp_path):
    folder = _long_case(tmp_path)
    z = dict(np.load(folder / "traj1.npz"))
    np.savez(folder / "traj1.npz", **dict(z, tau=z["tau"] * 1e160))
    with pytest.raises(jflex.DataError, match="traj1.npz: field 'tau': magnitudes up to .* overflow"):
        load_case(folder)


def test_empty_modal_table_refused(tmp_path):
    folder = _long_case(tmp_path)
    np.savez(folder / "modes.npz", q0=np.zeros(2), freq=np.zeros(0), zeta=np.zeros(0))
    _edit(folder, lambda c: c["datasets"].append({"kind": "modal", "file": "modes.npz", "split": "validation"}))
    with pytest.raises(jflex.DataError, match="modes.npz: field 'freq': the modal table is empty"):
        load_case(folder)
    (folder / "modes.csv").write_text("f_hz,zeta\n")
    _edit(folder, lambda c: c["datasets"].__setitem__(-1, {
        "kind": "modal", "file": "modes.csv", "split": "validation", "q0": [0, 0],
        "columns": {"frequency": "f_hz", "damping_ratio": "zeta"}}))
    with pytest.raises(jflex.DataError, match="modes.csv: a header but no data lines"):
        load_case(folder)


def test_validation_holding_the_training_samples_is_warned(tmp_path):
    folder = _long_case(tmp_path)
    _edit(folder, lambda c: c["datasets"].__setitem__(1, dict(c["datasets"][0], split="validation", name="val")))
    with pytest.warns(UserWarning, match="validation set 'val' and training set 'traj0' hold the same samples: "
                      "nothing is held out"):
        case = load_case(folder)
    notes = data_notes({"conditioning": {d.name: d.conditioning for d in case.datasets}})
    assert any(n.startswith("Warning ('val')") and "nothing is held out" in n for n in notes)
    # windows of one file that overlap
    _edit(folder, lambda c: (c["datasets"][0].update(window=[0.0, 3.0]), c["datasets"][1].update(window=[2.0, None])))
    with pytest.warns(UserWarning, match="hold overlapping windows of traj0.npz"):
        load_case(folder)
    # disjoint windows (what case init --hold-out writes), and two different files: no warning
    _edit(folder, lambda c: c["datasets"][1].update(window=[3.0, None]))
    assert not any("held out" in w for w in _load_quiet(folder)[1])
    assert not any("held out" in w for w in _load_quiet(_long_case(tmp_path / "b"))[1])


ARM = """<robot name="r">
  <link name="base"/>
  <link name="l1"><inertial><mass value="{m1}"/><inertia ixx="{i1}" ixy="0" ixz="0" iyy="{i1}" iyz="0" izz="{i1}"/></inertial></link>
  <link name="l2"><inertial><mass value="{m2}"/><inertia ixx="{i2}" ixy="0" ixz="0" iyy="{i2}" iyz="0" izz="{i2}"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
</robot>"""


def test_massless_link_warned_at_load_naming_it():
    with pytest.warns(UserWarning, match=r"link 'l2' \(moved by joint 'j2'\) has zero mass and inertia; nothing below "
                      r"joint 'j2' has mass"):
        jflex.from_urdf_string(ARM.format(m1=1, i1=0.1, m2=0, i2=0))
    # a massless link carrying a massive one: a frame on a joint, warned without the stronger words
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        jflex.from_urdf_string(ARM.format(m1=0, i1=0, m2=1, i2=0.1))
    msgs = [str(w.message) for w in caught]
    assert any("link 'l1' (moved by joint 'j1') has zero mass and inertia (a frame" in m for m in msgs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jflex.from_urdf_string(ARM.format(m1=1, i1=0.1, m2=1, i2=0.1))


def test_massless_link_reaches_the_case_warnings(tmp_path):
    folder = _long_case(tmp_path)
    (folder / "r.urdf").write_text(ARM.format(m1=1, i1=0.1, m2=0, i2=0))
    _edit(folder, lambda c: c.update(robot="r.urdf"))
    with pytest.warns(UserWarning, match="link 'l2'"):
        case = load_case(folder)
    assert any("link 'l2'" in w for w in case.warnings)
    assert any("link 'l2'" in w for w in case.datasets[0].conditioning["warnings"])


def test_absurd_mass_refused_by_name():
    with pytest.raises(jflex.URDFError, match=r"link 'l2': mass 1e\+300 kg.*expected a machine's"):
        jflex.from_urdf_string(ARM.format(m1=1, i1=0.1, m2=1e300, i2=0.1))
    with pytest.raises(jflex.URDFError, match=r"link 'l1': mass 1 kg, rotational inertia up to 1e\+20"):
        jflex.from_urdf_string(ARM.format(m1=1, i1=1e20, m2=1, i2=0.1))


def test_robot_without_joints_refused():
    with pytest.raises(jflex.ParameterError, match="no joints"):
        jflex.make_robot(joint_names=[], link_names=[], parents=[], joint_types=[], placement_R=np.zeros((0, 3, 3)),
                         placement_p=np.zeros((0, 3)), axis=np.zeros((0, 3)))
