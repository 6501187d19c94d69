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
              effort=True):
    """A bag of JointState messages at times ``t`` [s]: efforts are motor currents [A]; the joints
    in reverse order, plus a gripper joint the model lacks. Returns the bag's path (the ``.mcap``
    file for MCAP, the bag folder for sqlite3)."""
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    order = list(range(len(names)))[::-1]
    with Writer(path, version=9, storage_plugin=plugin) as w:
        con = w.add_connection(topic, JS.__msgtype__, typestore=TS)
        other = w.add_connection("/rosout_text", STRING.__msgtype__, typestore=TS)
        w.write(other, T0, TS.serialize_cdr(STRING(data="hello"), STRING.__msgtype__))
        for k in range(t.size):
            ns = T0 + int(round(t[k] * 1e9))
            pos = [q[k, j] for j in order] + ([0.02] if extra else [])
            vel = [qd[k, j] for j in order] + ([0.0] if extra else []) if qd is not None else []
            eff = [tau[k, j] / (KT * GEAR) for j in order] + ([0.1] if extra else []) if effort else []
            msg = JS(header=HEADER(stamp=_stamp(ns if stamped else 0), frame_id=""),
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
