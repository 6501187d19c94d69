"""A case whose robot couples joints by <mimic> (example-robot-data's Panda: panda_finger_joint2
follows panda_finger_joint1) is refused by name when it is read, with the way out; locking the
leader (which locks its follower) gives a case the diagnosis reads."""

import importlib.metadata as md
import shutil
import subprocess
import sys

import numpy as np
import pytest
import yaml

import jflex
from jflex.gap import load_case

ARM = [f"panda_joint{i}" for i in range(1, 8)]
FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]


@pytest.fixture
def panda_case(tmp_path):
    try:
        urdf = next(f.locate() for f in md.files("example-robot-data") if f.name == "panda.urdf")
    except (md.PackageNotFoundError, StopIteration):
        pytest.skip("example-robot-data is not installed")
    shutil.copy(urdf, tmp_path / "robot.urdf")
    joints = ARM + FINGERS
    rng = np.random.default_rng(0)
    t = 0.004 * np.arange(600)
    for name in ("a", "b"):
        q = 0.3 * np.sin(np.outer(t, rng.uniform(0.5, 2.0, 9)) + rng.uniform(0, 6, 9))
        q[:, 7:] = 0.02
        cols = ["t"] + [f"{j}_q" for j in joints] + [f"{j}_tau" for j in joints]
        np.savetxt(tmp_path / f"{name}.csv", np.column_stack([t, q, rng.normal(size=q.shape)]), delimiter=",",
                   header=",".join(cols), comments="")

    def write(robot, with_fingers):
        js = joints if with_fingers else ARM
        ds = [dict(kind="torque", file=f"{n}.csv", split=s,
                   columns=dict(time="t", position={j: f"{j}_q" for j in js}, torque={j: f"{j}_tau" for j in js}))
              for n, s in (("a", "train"), ("b", "validation"))]
        (tmp_path / "case.yaml").write_text(yaml.safe_dump(dict(robot=robot, tool_frame="panda_hand", datasets=ds),
                                                           sort_keys=False))
        return tmp_path
    return write


def test_a_robot_with_mimic_joints_is_refused_by_name(panda_case):
    folder = panda_case("robot.urdf", True)
    with pytest.raises(jflex.ConfigError, match=r"field 'robot'.*<mimic>.*panda_finger_joint2 follows "
                                                r"panda_finger_joint1.*lock: \{panda_finger_joint1"):
        load_case(folder)
    r = subprocess.run([sys.executable, "-m", "jflex.cli", "diagnose", str(folder), "--out", str(folder / "run")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "panda_finger_joint2 follows panda_finger_joint1" in r.stderr
    assert "Traceback" not in r.stderr


def test_locking_the_leader_gives_a_case(panda_case):
    case = load_case(panda_case({"file": "robot.urdf", "lock": {"panda_finger_joint1": 0.02}}, False))
    assert tuple(case.robot.joint_names) == tuple(ARM)
