"""ROS 2 bags and MCAP logs as case data sets (issue 16 item 3, the ``ros`` extra): a bag of
``sensor_msgs/msg/JointState`` written with rosbags' own writer (motor currents in ``effort``,
joints in a scrambled order plus one the model lacks) loads to the arrays of the NPZ it was
written from; jittered stamps are resampled; each mistake names its field; the MCAP case runs
through the diagnosis."""

from __future__ import annotations

import pathlib
import sys

import numpy as np
import pytest
import yaml

pytest.importorskip("rosbags")

from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

import jflex  # noqa: E402
from jflex_family import generate as G  # noqa: E402
from jflex.gap import diagnose, load_case  # noqa: E402

KT, GEAR = 0.35, 80.0  # motor torque constant [N m/A] and gear ratio: tau = KT * GEAR * current
T0 = 1_732_000_000 * 10**9  # an epoch stamp [ns]: the loader must not lose the nanoseconds
TS = get_typestore(Stores.ROS2_HUMBLE)
JS = TS.types["sensor_msgs/msg/JointState"]
STRING = TS.types["std_msgs/msg/String"]
HEADER, TIME = TS.types["std_msgs/msg/Header"], TS.types["builtin_interfaces/msg/Time"]


def _stamp(ns):
    return TIME(sec=int(ns // 10**9), nanosec=int(ns % 10**9))


def write_bag(path, t, q, tau, names, qd=None, storage="mcap", topic="/joint_states", stamped=True, extra=True,
              effort=True, unstamped=()):
    """A bag of JointState messages at times ``t`` [s]: efforts are motor currents [A]; the joints
    in reverse order, plus a gripper joint the model lacks. Returns the bag's path (the ``.mcap``
    file for MCAP, the bag folder for sqlite3)."""
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    order = list(range(q.shape[1]))[::-1]  # the joints of q (all of the model, or fewer)
    with Writer(path, version=9, storage_plugin=plugin) as w:
        con = w.add_connection(topic, JS.__msgtype__, typestore=TS)
        other = w.add_connection("/rosout_text", STRING.__msgtype__, typestore=TS)
        w.write(other, T0, TS.serialize_cdr(STRING(data="hello"), STRING.__msgtype__))
        for k in range(t.size):
            ns = T0 + int(round(t[k] * 1e9))
            pos = [q[k, j] for j in order] + ([0.02] if extra else [])
            vel = [qd[k, j] for j in order] + ([0.0] if extra else []) if qd is not None else []
            eff = [tau[k, j] / (KT * GEAR) for j in order] + ([0.1] if extra else []) if effort else []
            msg = JS(header=HEADER(stamp=_stamp(ns if stamped and k not in unstamped else 0), frame_id=""),
                     name=[names[j] for j in order] + (["gripper"] if extra else []),
                     position=np.asarray(pos, float), velocity=np.asarray(vel, float), effort=np.asarray(eff, float))
            w.write(con, ns + 2_000_000, TS.serialize_cdr(msg, JS.__msgtype__))  # received 2 ms later
    return next(pathlib.Path(path).glob("*.mcap")) if storage == "mcap" else pathlib.Path(path)


def _entry(folder, bag, split, names):
    return {"kind": "torque", "file": str(bag.relative_to(folder)), "split": split,
            "scale": {n: KT * GEAR for n in names}}


@pytest.fixture(scope="module")
def bag_case(tmp_path_factory):
    """The planted viscous-friction case of the generator: the train log as an MCAP bag with
    velocities, the validation log as a sqlite3 bag without."""
    folder = G.torque_case(tmp_path_factory.mktemp("bag") / "visc", "planar2", ["viscous_friction"], seed=3,
                           noise=0.01, n_train=1, n_val=1)
    npz = load_case(folder)
    names = list(npz.robot.joint_names)
    cfg = yaml.safe_load((folder / "case.yaml").read_text())
    entries = []
    for i, d in enumerate(cfg["datasets"]):
        z = np.load(folder / d["file"])
        name = pathlib.Path(d["file"]).stem
        bag = write_bag(folder / name, z["t"], z["q"], z["tau"], names, z["qd"] if i == 0 else None,
                        storage="mcap" if i == 0 else "sqlite3")
        entries.append(_entry(folder, bag, d["split"], names))
    cfg["datasets"] = entries
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return folder, npz, names


def test_bag_loads_to_the_npz_arrays(bag_case):
    folder, npz, _ = bag_case
    case = load_case(folder)
    assert case.datasets[0].file.suffix == ".mcap" and case.datasets[1].file.is_dir()
    for a, b in zip(case.datasets, npz.datasets):
        for k in ("t", "q", "tau"):
            np.testing.assert_allclose(a.arrays[k], b.arrays[k], rtol=1e-9, atol=1e-9 * np.abs(b.arrays[k]).max())
        # the gripper the model lacks: a posture variable
        assert a.extra_joints == ("gripper",)
        np.testing.assert_allclose(a.arrays["q_extra"], 0.02)
    # the MCAP bag has velocities; the sqlite3 one none: central differences of q
    np.testing.assert_allclose(case.datasets[0].arrays["qd"], npz.datasets[0].arrays["qd"], rtol=1e-9, atol=1e-9)
    a = case.datasets[1].arrays
    np.testing.assert_allclose(a["qd"], np.gradient(a["q"], a["t"], axis=0), rtol=1e-12)


def _one_bag_case(folder, bag_case, **kw):
    """A copy of the bag case whose train set is a new bag written with ``kw`` (from the train NPZ)."""
    src, npz, names = bag_case
    folder.mkdir(parents=True, exist_ok=True)
    for f in ("robot.yaml",):
        (folder / f).write_text((src / f).read_text())
    a = npz.datasets[0].arrays
    t = kw.pop("t", a["t"])
    q, tau = kw.pop("q", a["q"]), kw.pop("tau", a["tau"])
    bag = write_bag(folder / "log", t, q, tau, names, **kw)
    cfg = yaml.safe_load((src / "case.yaml").read_text())
    cfg["datasets"][0] = _entry(folder, bag, "train", names)
    val = cfg["datasets"][1]["file"]
    (folder / val).mkdir()
    for f in (src / val).iterdir():
        (folder / val / f.name).write_bytes(f.read_bytes())
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return folder, cfg, names


def test_jittered_stamps_are_resampled(tmp_path, bag_case):
    a = bag_case[1].datasets[0].arrays
    rng = np.random.default_rng(0)
    h = a["t"][1] - a["t"][0]
    s = a["t"] + rng.uniform(-0.1, 0.1, a["t"].size) * h  # jitter of 10 % of a step
    # the messages sample the NPZ motion at the jittered stamps
    qs = np.column_stack([np.interp(s, a["t"], a["q"][:, j]) for j in range(a["q"].shape[1])])
    taus = np.column_stack([np.interp(s, a["t"], a["tau"][:, j]) for j in range(a["tau"].shape[1])])
    folder, _, _ = _one_bag_case(tmp_path / "c", bag_case, t=s - s[0], q=qs, tau=taus, stamped=False)
    d = load_case(folder).datasets[0].arrays
    sr = np.round((s - s[0]) * 1e9) * 1e-9  # the stamps as the bag holds them (ns)
    # no message dropped: the grid spans the log in as many samples
    assert d["t"].size == s.size and d["t"][0] == 0
    np.testing.assert_allclose(d["t"], np.linspace(0, sr[-1], s.size), rtol=1e-12, atol=1e-12)
    for k, raw in (("q", qs), ("tau", taus)):
        ref = np.column_stack([np.interp(d["t"], sr, raw[:, j]) for j in range(raw.shape[1])])
        np.testing.assert_allclose(d[k], ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    # a jitter below 1 % of a step is kept as it is, the receive time (every stamp zero) read
    s2 = a["t"] + rng.uniform(-0.004, 0.004, a["t"].size) * h
    folder, _, _ = _one_bag_case(tmp_path / "d", bag_case, t=s2, stamped=False)
    np.testing.assert_allclose(load_case(folder).datasets[0].arrays["t"], s2 - s2[0], atol=1e-9)


def test_a_bag_folder_outside_the_case_is_refused(tmp_path, bag_case):
    folder, cfg, _ = _one_bag_case(tmp_path / "c", bag_case)
    outside = write_bag(tmp_path / "elsewhere", *(bag_case[1].datasets[0].arrays[k] for k in ("t", "q", "tau")),
                        bag_case[2], storage="sqlite3")
    cfg["datasets"][0]["file"] = "../elsewhere"
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    with pytest.raises(jflex.ConfigError, match=r"datasets\[0\]\.file.*outside the case folder"):
        load_case(folder)
    assert load_case(folder, allow_outside=True).datasets[0].file.resolve() == outside.resolve()


def _case_with(tmp_path, bag_case, edit=None, **kw):
    folder, cfg, names = _one_bag_case(tmp_path / "c", bag_case, **kw)
    if edit is not None:
        edit(cfg["datasets"][0])
        (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    return folder


@pytest.mark.parametrize("kw, edit, err, words", [
    ({"topic": "/arm/joint_states"}, None, jflex.DataError,
     ["log.mcap", "datasets[0].topic", "'/joint_states'", "'/arm/joint_states'", "'/rosout_text'"]),
    ({}, lambda d: d.update(topic="/rosout_text"), jflex.DataError,
     ["datasets[0].topic", "std_msgs/msg/String", "sensor_msgs/msg/JointState"]),
    ({"effort": False}, None, jflex.DataError, ["log.mcap", "message 0", "field 'effort'", "empty"]),
    ({}, lambda d: d["scale"].update(wrist=2.0), jflex.ConfigError, ["datasets[0].scale.wrist", "shoulder"]),
    ({}, lambda d: d["scale"].update(elbow=0), jflex.ConfigError, ["datasets[0].scale.elbow"]),
    ({}, lambda d: d.update(units={"time": "ms"}), jflex.ConfigError, ["datasets[0].units", "only for CSV"]),
    ({}, lambda d: d.update(file="nobag"), jflex.ConfigError, ["datasets[0].file", "metadata.yaml"]),
])
def test_bag_errors_name_the_field(tmp_path, bag_case, kw, edit, err, words):
    folder = _case_with(tmp_path, bag_case, edit, **kw)
    with pytest.raises(err) as e:
        load_case(folder)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_a_model_joint_missing_from_name(tmp_path, bag_case):
    _, npz, names = bag_case
    a = npz.datasets[0].arrays
    folder = _case_with(tmp_path, bag_case, None, q=a["q"][:, :1], tau=a["tau"][:, :1])
    # write_bag names joints by their index in q: one column, the model's first joint only
    with pytest.raises(jflex.DataError) as e:
        load_case(folder)
    msg = str(e.value)
    assert "field 'name'" in msg and repr(names[1]) in msg and "message 0" in msg and "log.mcap" in msg


def test_topic_on_a_npz_set_and_missing_rosbags(tmp_path, bag_case, monkeypatch):
    folder, cfg, _ = _one_bag_case(tmp_path / "c", bag_case)
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)  # as if rosbags were not installed
    with pytest.raises(jflex.DataError, match=r"datasets\[0\]\.file.*pip install \"jflex\[ros\]\""):
        load_case(folder)
    monkeypatch.undo()
    np.savez(folder / "x.npz", **bag_case[1].datasets[0].arrays)
    cfg["datasets"][0] = {"kind": "torque", "file": "x.npz", "split": "train", "topic": "/joint_states"}
    (folder / "case.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    with pytest.raises(jflex.ConfigError, match=r"datasets\[0\]\.topic.*only for ROS 2 bags"):
        load_case(folder)


def test_bag_case_diagnosis_finds_the_planted_friction(bag_case):
    folder, _, _ = bag_case
    truth = yaml.safe_load((folder.parent / "visc.truth.json").read_text())["effects"][0]
    r = diagnose(folder).result
    assert r["significant"]
    assert (r["selected"][0]["effect"], r["selected"][0]["joint"]) == ("viscous_friction", truth["joint"])
    assert r["gap_after"] < 0.5 * r["gap_before"]


def test_stamp_problems_are_refused(tmp_path, bag_case):
    a = bag_case[1].datasets[0].arrays
    folder = _case_with(tmp_path / "mixed", bag_case, unstamped=(7,))
    with pytest.raises(jflex.DataError, match=r"log\.mcap: topic '/joint_states', message 7: field 'header\.stamp'"):
        load_case(folder)
    # messages dropped, the rest jittered. A torque log's stamps are conditioned as a CSV log's:
    # ten dropped messages (0.055 s, short against the motion) are bridged, forty (0.2 s) cut the
    # log into two data sets, each gap reported; a response log (simulated from rest) is refused
    h = a["t"][1] - a["t"][0]

    def dropped(n, name, edit=None):
        keep = np.r_[0:100, 100 + n:a["t"].size]
        s = a["t"][keep] + np.random.default_rng(1).uniform(-0.05, 0.05, keep.size) * h
        return _case_with(tmp_path / name, bag_case, edit, t=s, q=a["q"][keep], tau=a["tau"][keep]), s

    folder, s = dropped(10, "bridged")
    d = load_case(folder).datasets[0]
    gap, = d.conditioning["sampling"]["gaps"]
    assert gap["action"] == "bridged by linear interpolation" and abs(gap["t_s"] - (s[99] - s[0])) < 1e-9
    assert d.arrays["t"].size == a["t"].size - 1  # one uniform grid over the gap
    folder, s = dropped(40, "split")
    with pytest.warns(UserWarning, match=r"is split at 1 gap\(s\) too long to bridge"):
        sets = [d for d in load_case(folder).datasets if d.file.suffix == ".mcap"]
    assert [d.name.rsplit("#", 1)[-1] for d in sets] == ["1", "2"]
    gap, = sets[0].conditioning["sampling"]["split_from"]["gaps"]
    assert gap["action"] == "split" and abs(gap["t_s"] - (s[99] - s[0])) < 1e-9
    assert sets[0].arrays["t"][-1] <= gap["t_s"] + 1e-9 and sets[1].arrays["t"][0] >= gap["t_s"] + 40 * h
    folder, _ = dropped(40, "response", lambda d: d.update(kind="response"))
    with pytest.raises(jflex.DataError, match=r"field 'header\.stamp': a gap of 0\.2\d* s"):
        load_case(folder)
    folder = _case_with(tmp_path / "junk", bag_case)
    (folder / "log" / "log.mcap").write_bytes(b"not an mcap file")
    with pytest.raises(jflex.DataError, match=r"log\.mcap: field 'datasets\[0\]\.file': not a readable ROS 2 bag"):
        load_case(folder)


def test_a_response_bag_gives_torques_and_joint_outputs(tmp_path, bag_case):
    _, npz, names = bag_case
    folder = _case_with(tmp_path, bag_case, lambda d: d.update(kind="response"))
    d = load_case(folder).datasets[0]
    a = npz.datasets[0].arrays
    assert d.kind == "response" and d.arrays["channels"] == tuple(names)
    np.testing.assert_allclose(d.arrays["y"], a["q"], rtol=1e-9, atol=1e-9)  # the gripper is no output
    np.testing.assert_allclose(d.arrays["tau"], a["tau"], rtol=1e-9, atol=1e-9 * np.abs(a["tau"]).max())
