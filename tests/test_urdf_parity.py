"""URDF loading against Pinocchio: every URDF shipped in example-robot-data, reduced models
(``pin.buildReducedModel``), mimic joints, floating bases, inertia checks.

The reference for each file is ``pin.buildModelFromUrdf(path)`` (fixed base, mimic joints as
independent joints). Pinocchio stores a continuous joint as ``(cos, sin)``; jflex as the angle.
Evaluation is eager (one call per kernel and state): jitting each robot would cost more compile
time than it saves.
"""

import pathlib
import sys
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import jflex
from _references import pin
from conftest import SLOW

pytestmark = pytest.mark.skipif(pin is None, reason="needs the test extra 'pin'")

RTOL = 1e-9


def _erd_root():
    for p in map(pathlib.Path, sys.path):
        c = p / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if c.is_dir():
            return c
    return None


ERD = _erd_root()
URDFS = sorted(str(p.relative_to(ERD)) for p in ERD.rglob("*.urdf")) if ERD is not None else []
# tiago_dual has 101 joints: its eager crba (a stack of 101^2 scalars) compiles for ~30 s
HEAVY_CRBA = {"tiago_description/robots/tiago_dual.urdf"}


def close(a, b, rtol=RTOL, what=""):
    a, b = np.asarray(a), np.asarray(b).reshape(np.shape(a))
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * max(1.0, np.abs(b).max()), err_msg=what)


def pin_q(model, theta):
    """Pinocchio's configuration for joint angles/positions ``theta`` (one per jflex joint)."""
    q = np.zeros(model.nq)
    for i, th in enumerate(theta):
        jm = model.joints[i + 1]
        if jm.nq == 2:  # continuous (unbounded revolute): (cos, sin)
            q[jm.idx_q : jm.idx_q + 2] = np.cos(th), np.sin(th)
        else:
            q[jm.idx_q] = th
    return q


def _sym(M):
    return np.triu(M) + np.triu(M, 1).T


def compare(robot, model, rng, crba=True, states=2):
    """rnea, crba and forward dynamics (ABA) against Pinocchio at random states."""
    assert robot.joint_names == tuple(model.names[1:])
    data = model.createData()
    n = robot.nq
    for _ in range(states):
        th = rng.uniform(-1.0, 1.0, n)
        v, a = rng.normal(size=n), rng.normal(size=n)
        q = pin_q(model, th)
        tau = pin.rnea(model, data, q, v, a)
        close(jflex.rnea(robot, th, v, a), tau, what="rnea")
        M = _sym(pin.crba(model, data, q))
        if crba:
            close(jflex.crba(robot, th), M, what="crba")
        if np.linalg.eigvalsh(M)[0] <= 1e-12 * np.abs(M).max():
            # a moving joint carrying no inertia (romeo's fingers, romeo_laas_small's grippers): M is singular
            continue
        qdd = np.asarray(jflex.forward_dynamics(robot, th, v, tau))
        qdd_pin = pin.aba(model, data, q, v, tau)
        # Accelerations are as exact as M is well conditioned (iCub: cond 4e7, Pinocchio's own aba
        # misses a by 2e-9); compared in torque space, M (qdd - qdd_pin), the check is uniform.
        close(M @ qdd, M @ qdd_pin, what="aba (torque space)")
        close(qdd, qdd_pin, rtol=RTOL * max(1.0, 1e-7 * np.linalg.cond(M)), what="aba")


def _load_pin(rel):
    try:
        return pin.buildModelFromUrdf(str(ERD / rel))
    except (RuntimeError, ValueError) as exc:  # ur3.urdf: "No name given for the robot"
        pytest.skip(f"Pinocchio does not load {rel}: {str(exc).splitlines()[0][:80]}")


@pytest.mark.parametrize("rel", URDFS)
def test_example_robot_data_urdf_matches_pinocchio(rel):
    model = _load_pin(rel)
    path = ERD / rel
    if model.nv == 0:  # a lone body (quadrotor, iris_simple): no joint to model
        with pytest.raises(jflex.URDFError, match="no moving joints"):
            jflex.load_urdf(path)
        return
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        robot = jflex.load_urdf(path, mimic="independent")
    nonphysical = [str(w.message) for w in caught if "non-physical inertia" in str(w.message)]
    if nonphysical:
        with pytest.raises(jflex.URDFError, match="non-physical inertia"):
            jflex.load_urdf(path, mimic="independent", strict=True)
    if any(j.find("mimic") is not None and j.get("type") != "fixed" for j in ET.parse(path).getroot().iter("joint")):
        with pytest.raises(jflex.URDFError, match="mimic"):
            jflex.load_urdf(path)
    compare(robot, model, np.random.default_rng(0), crba=SLOW or rel not in HEAVY_CRBA)


# ---- reduced models ---------------------------------------------------------------------------


def _reduced_pin(model, lock):
    q0 = pin.neutral(model)
    ids = []
    for name, val in lock.items():
        jm = model.joints[model.getJointId(name)]
        if jm.nq == 2:
            q0[jm.idx_q : jm.idx_q + 2] = np.cos(val), np.sin(val)
        else:
            q0[jm.idx_q] = val
        ids.append(model.getJointId(name))
    return pin.buildReducedModel(model, ids, q0)


@pytest.mark.parametrize(
    "rel,keep,values",
    [
        # TALOS' left arm on its torso and legs held at a posture (neck, grippers, right arm at 0)
        ("talos_data/robots/talos_full_v2.urdf",
         ["arm_left_1_joint", "arm_left_2_joint", "arm_left_3_joint", "arm_left_4_joint",
          "arm_left_5_joint", "arm_left_6_joint", "arm_left_7_joint"],
         {"torso_1_joint": 0.3, "torso_2_joint": -0.2, "leg_left_4_joint": 0.5}),
        # TIAGo's arm on a raised torso, wheels (continuous) locked at an angle
        ("tiago_description/robots/tiago.urdf",
         ["arm_1_joint", "arm_2_joint", "arm_3_joint", "arm_4_joint", "arm_5_joint", "arm_6_joint", "arm_7_joint"],
         {"torso_lift_joint": 0.2, "wheel_left_joint": 0.7}),
    ],
)
def test_reduced_model_matches_pinocchio(rel, keep, values):
    if ERD is None:
        pytest.skip("example-robot-data not installed")
    path = ERD / rel
    full = pin.buildModelFromUrdf(str(path))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the vendors' antenna/camera inertias
        robot = jflex.load_urdf(path, joints=keep, lock=values)
    lock = {name: values.get(name, 0.0) for name in full.names[1:] if name not in keep}
    model = _reduced_pin(full, lock)
    assert robot.joint_names == tuple(keep) == tuple(model.names[1:])
    compare(robot, model, np.random.default_rng(1))
    # the locked links stay reachable as frames (the hand's placement through the reduced tree)
    pin_data = model.createData()
    th = np.random.default_rng(2).uniform(-1, 1, robot.nq)
    pin.framesForwardKinematics(model, pin_data, pin_q(model, th))
    for frame in ("arm_left_7_link", "arm_7_link", "torso_2_link", "torso_lift_link"):
        if model.existFrame(frame):
            close(jflex.frame_placement(robot, th, frame), pin_data.oMf[model.getFrameId(frame)].homogeneous)


def test_reduction_errors_name_the_joint():
    if ERD is None:
        pytest.skip("example-robot-data not installed")
    path = ERD / "ur_description/urdf/ur5_robot.urdf"
    with pytest.raises(jflex.URDFError, match="ur5_robot.urdf.*lock names 'elbow'.*is not a joint"):
        jflex.load_urdf(path, lock={"elbow": 0.1})
    with pytest.raises(jflex.URDFError, match="joints names 'wrist_9'"):
        jflex.load_urdf(path, joints=["shoulder_pan_joint", "wrist_9"])
    with pytest.raises(jflex.URDFError, match="'ee_fixed_joint', which is not a moving joint"):
        jflex.load_urdf(path, lock={"ee_fixed_joint": 0.0})
    with pytest.raises(jflex.URDFError, match="'elbow_joint' is both kept"):
        jflex.load_urdf(path, joints=["elbow_joint"], lock={"elbow_joint": 0.1})
    with pytest.raises(jflex.URDFError, match=r"lock\['elbow_joint'\] = 9.0 lies outside"):
        jflex.load_urdf(path, lock={"elbow_joint": 9.0})
    with pytest.raises(jflex.URDFError, match="no moving joints.*left after lock"):
        jflex.load_urdf(path, joints=[])
    # joints= locks the others at lock's values or 0; a YAML robot config reduces the same way
    keep = ["shoulder_lift_joint", "elbow_joint"]
    a = jflex.load_urdf(path, joints=keep, lock={"wrist_1_joint": 0.4})
    b = jflex.load_urdf(path, lock={"shoulder_pan_joint": 0.0, "wrist_1_joint": 0.4, "wrist_2_joint": 0.0, "wrist_3_joint": 0.0})
    c = jflex.robot_from_config({"urdf": str(path), "joints": keep, "lock": {"wrist_1_joint": 0.4}})
    assert a.joint_names == b.joint_names == c.joint_names == tuple(keep)
    close(a.inertia, b.inertia)
    close(c.inertia, b.inertia)


# ---- mimic joints -----------------------------------------------------------------------------


def test_mimic_joint_refused_or_locked_with_its_leader():
    if ERD is None:
        pytest.skip("example-robot-data not installed")
    path = ERD / "panda_description/urdf/panda.urdf"
    with pytest.raises(jflex.URDFError, match=r"panda.urdf: joint 'panda_finger_joint2' mimics joint 'panda_finger_joint1'.*lock="):
        jflex.load_urdf(path)
    # locking the leader locks the follower at multiplier * value + offset (1 and 0 here)
    robot = jflex.load_urdf(path, lock={"panda_finger_joint1": 0.03})
    model = _reduced_pin(pin.buildModelFromUrdf(str(path)), {"panda_finger_joint1": 0.03, "panda_finger_joint2": 0.03})
    compare(robot, model, np.random.default_rng(3))
    # a follower locked while its leader moves breaks the coupling: refused
    with pytest.raises(jflex.URDFError, match="panda_finger_joint2' mimics"):
        jflex.load_urdf(path, lock={"panda_finger_joint2": 0.01})
    # load_robot("panda") is the 7-joint arm, fingers closed
    assert jflex.load_robot("panda").joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))


MIMIC = """<robot name="m">
  <link name="base"/><link name="a0"/><link name="a"/><link name="b"/>
  <joint name="j0" type="revolute"><parent link="base"/><child link="a0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j1" type="revolute"><parent link="a0"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="{leader}" multiplier="2" offset="0.1"/></joint>
</robot>"""


def test_mimic_of_a_missing_joint_is_named():
    with pytest.raises(jflex.URDFError, match="joint 'j2'.*<mimic joint='j9'>"):
        jflex.from_urdf_string(MIMIC.format(leader="j9"))
    r = jflex.from_urdf_string(MIMIC.format(leader="j9"), mimic="independent")
    assert r.joint_names == ("j0", "j1", "j2")
    r = jflex.from_urdf_string(MIMIC.format(leader="j1"), lock={"j1": 0.2})
    # j2 follows at 2 * 0.2 + 0.1 = 0.5 about the same z axis: frame 'b' turned by 0.2 + 0.5
    assert r.joint_names == ("j0",)
    c, s = np.cos(0.7), np.sin(0.7)
    close(np.asarray(jflex.frame_placement(r, np.zeros(1), "b"))[:3, :3], [[c, -s, 0], [s, c, 0], [0, 0, 1]])


# ---- inertias, floating bases, duplicates -----------------------------------------------------


def _one_link(inertial, extra=""):
    return f"""<robot name="t">
  <link name="base"/>
  <link name="arm">{inertial}</link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>{extra}
</robot>"""


def _inertial(m, ixx, iyy, izz, xyz="0 0 0"):
    return (f'<inertial><origin xyz="{xyz}"/><mass value="{m}"/>'
            f'<inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial>')


def test_point_masses_and_roundoff_load_silently():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = jflex.from_urdf_string(_one_link(_inertial(2.0, 0, 0, 0, "0.5 0 0")))  # point mass
        close(jflex.crba(r, np.zeros(1)), [[2.0 * 0.25]])  # m r^2
        r = jflex.from_urdf_string(_one_link(_inertial(1.0, 0.1, 0.1, -2.5e-22)))  # a rod, round-off
        close(jflex.crba(r, np.zeros(1)), [[0.0]])


def test_massless_link_keeps_its_rotational_inertia_through_a_fixed_joint():
    # bolt's feet: mass 0, rotational inertia given; Pinocchio keeps it (this was bolt's 2e-4)
    foot = '<link name="foot">' + _inertial(0.0, 0.3, 0.3, 0.5) + "</link>"
    text = _one_link(_inertial(1.0, 0.1, 0.1, 0.1, "0.2 0 0"),
                     foot + '<joint name="ankle" type="fixed"><parent link="arm"/><child link="foot"/>'
                     '<origin xyz="1 0 0" rpy="1.5707963267948966 0 0"/></joint>')
    r = jflex.from_urdf_string(text)
    # about z: arm 0.1 + 1 * 0.2^2; foot rotated about x by 90 deg: its y moment (0.3) lies on z
    close(jflex.crba(r, np.zeros(1)), [[0.1 + 0.04 + 0.3]])


def test_nonphysical_inertia_warns_naming_the_link_or_strict_refuses():
    text = _one_link(_inertial(1.0, 0.1, 0.1, 0.5))  # 0.1 + 0.1 < 0.5: triangle inequality broken
    with pytest.warns(UserWarning, match="link 'arm': non-physical inertia.*triangle inequality"):
        r = jflex.from_urdf_string(text)
    close(jflex.crba(r, np.zeros(1)), [[0.5]])  # loaded as given
    with pytest.raises(jflex.URDFError, match="link 'arm': non-physical inertia.*strict"):
        jflex.from_urdf_string(text, strict=True)
    with pytest.raises(jflex.URDFError, match="link 'arm': mass must be >= 0"):
        jflex.from_urdf_string(_one_link(_inertial(-1.0, 0.1, 0.1, 0.1)))


FLOATING = """<robot name="f">
  <link name="world"/><link name="pelvis"/><link name="leg"/>
  <joint name="root" type="floating"><parent link="world"/><child link="pelvis"/><origin xyz="0 0 1"/></joint>
  <joint name="hip" type="revolute"><parent link="pelvis"/><child link="leg"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def test_floating_base_welded_with_a_warning_or_refused():
    with pytest.warns(UserWarning, match="joint 'root': floating joint from the root link welded"):
        r = jflex.from_urdf_string(FLOATING)
    assert r.joint_names == ("hip",) and np.allclose(r.placement_p[0], [0, 0, 1])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jflex.from_urdf_string(FLOATING, floating="fixed")
    with pytest.raises(jflex.URDFError, match="joint 'root'.*floating='refuse'"):
        jflex.from_urdf_string(FLOATING, floating="refuse")


def test_duplicate_joint_name_names_the_file(tmp_path):
    text = _one_link(_inertial(1.0, 0.1, 0.1, 0.1), '<link name="x"/><joint name="j" type="fixed"><parent link="arm"/>'
                     '<child link="x"/></joint>')
    f = tmp_path / "dup.urdf"
    f.write_text(text)
    with pytest.raises(jflex.URDFError, match=r"dup.urdf: joint 'j' is defined twice"):
        jflex.load_urdf(f)
