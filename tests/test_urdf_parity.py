"""URDF loading against Pinocchio: every URDF shipped in example-robot-data, reduced models
(``pin.buildReducedModel``), mimic joints, floating bases, inertia checks.

The reference for each file is ``pin.buildModelFromUrdf(path, mimic=True)`` (fixed base, mimic
joints as coupled coordinates, jflex's default); a robot with mimic joints is also compared, loaded
with ``mimic="independent"``, against ``mimic=False``. Pinocchio stores a continuous joint as
``(cos, sin)``; jflex as the angle. Evaluation is eager (one call per kernel, one state): jitting
each robot would cost more compile time than it saves. By default a representative subset runs
(every robot with mimic joints, a continuous joint, a reduced tree); JFLEX_SLOW=1 runs them all.
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
_FREE = ("floating", "planar")


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


def _has_mimic(rel):
    return any(j.find("mimic") is not None and j.get("type") in ("revolute", "continuous", "prismatic")
               for j in ET.parse(ERD / rel).getroot().findall("joint"))


MIMIC_URDFS = [rel for rel in URDFS if _has_mimic(rel)]


def _broken_mimic(path):
    """The first moving joint whose <mimic> names no moving joint of the file, or None."""
    joints = {j.get("name"): j for j in ET.parse(path).getroot().findall("joint")}
    moving = ("revolute", "continuous", "prismatic")
    for name, j in joints.items():
        m = j.find("mimic")
        if m is not None and j.get("type") in moving and joints.get(m.get("joint"), j).get("type") not in moving:
            return name
        if m is not None and j.get("type") in moving and m.get("joint") not in joints:
            return name
    return None
# besides those: continuous joints (double pendulum, TIAGo's wheels), fixed joints carrying <mimic>
# (talos_reduced), a plain arm, a lone body
# (panda_collision and talos_full_v2_box repeat their siblings' trees: with JFLEX_SLOW=1 only)
SUBSET = set(MIMIC_URDFS) - {"panda_description/urdf/panda_collision.urdf", "talos_data/robots/talos_full_v2_box.urdf"} | {
    "double_pendulum_description/urdf/double_pendulum_continuous.urdf",
    "talos_data/robots/talos_reduced.urdf",
    "ur_description/urdf/ur5_robot.urdf",
    "hector_description/robots/quadrotor_base.urdf",
}


def close(a, b, rtol=RTOL, what=""):
    a, b = np.asarray(a), np.asarray(b).reshape(np.shape(a))
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * max(1.0, np.abs(b).max()), err_msg=what)


def pin_q(model, theta, names=None):
    """Pinocchio's configuration for joint angles/positions ``theta``, one per jflex coordinate
    (``names``: the jflex coordinates, by default Pinocchio's joints in order)."""
    names = list(model.names[1:]) if names is None else names
    q = np.zeros(model.nq)
    for name, th in zip(names, theta, strict=True):
        jm = model.joints[model.getJointId(name)]
        if jm.nq == 2:  # continuous (unbounded revolute): (cos, sin)
            q[jm.idx_q : jm.idx_q + 2] = np.cos(th), np.sin(th)
        else:
            q[jm.idx_q] = th
    return q


def _coordinates_match(robot, model):
    """jflex's coordinates are Pinocchio's velocity coordinates, in the same order."""
    assert robot.joint_names == tuple(model.names[1:])
    assert robot.nq == model.nv
    idx_v = [model.joints[model.getJointId(k)].idx_v for k in robot.coordinate_names]
    assert idx_v == list(range(model.nv))


def _sym(M):
    return np.triu(M) + np.triu(M, 1).T


def coupling(path, names):
    return coupling_from_text(pathlib.Path(path).read_text(), names)


def coupling_from_text(text, names):
    """``(G, b)`` with Pinocchio's joint values ``G q + b`` for jflex's coordinates ``q``, read from
    the URDF's <mimic> tags (chains composed), for ``names`` the joints of the tree: the reference
    for the files whose mimic joints Pinocchio cannot couple (a leader met after its follower)."""
    spec = {}
    for j in ET.fromstring(text).findall("joint"):
        m = j.find("mimic")
        if m is not None and j.get("name") in names:
            spec[j.get("name")] = (m.get("joint"), float(m.get("multiplier", 1)), float(m.get("offset", 0)))
    coords = [k for k in names if k not in spec]
    G, b = np.zeros((len(names), len(coords))), np.zeros(len(names))
    for i, k in enumerate(names):
        a, off = 1.0, 0.0
        while k in spec:
            k, ak, bk = spec[k]
            a, off = a * ak, a * bk + off
        G[i, coords.index(k)], b[i] = a, off
    return G, b, coords


def compare(robot, model, rng, crba=True, states=1, kinematics=True, G=None, b=None):
    """rnea, crba, forward dynamics, forward kinematics and a Jacobian against Pinocchio at random
    states. With mimic joints Pinocchio has no ABA: forward dynamics is checked to return the
    accelerations that Pinocchio's rnea turned into torques. ``G, b`` (see :func:`coupling`): the
    model's joints are independent and jflex's coordinates map onto them as ``G q + b``."""
    n = robot.nq
    if G is None:
        _coordinates_match(robot, model)
        G, b, names = np.eye(n), np.zeros(n), robot.coordinate_names
    else:
        assert robot.joint_names == tuple(model.names[1:]) and model.nv == robot.n_joints
        names = robot.joint_names
    data = model.createData()
    mimic = robot.nq < robot.n_joints
    for _ in range(states):
        th = rng.uniform(-1.0, 1.0, n)
        v, a = rng.normal(size=n), rng.normal(size=n)
        q = pin_q(model, G @ th + b, names)
        tau = G.T @ pin.rnea(model, data, q, G @ v, G @ a)
        close(jflex.rnea(robot, th, v, a), tau, what="rnea")
        M = G.T @ _sym(pin.crba(model, data, q)) @ G
        if crba:
            close(jflex.crba(robot, th), M, what="crba")
        if kinematics:
            pin.forwardKinematics(model, data, q)
            T = np.asarray(jflex.forward_kinematics(robot, th))
            close(T, np.stack([data.oMi[i].homogeneous for i in range(1, model.njoints)]), what="forward kinematics")
            # the deepest joint's Jacobian, or a coupled one's: the most columns, or the coupling
            depth = [len(model.supports[i]) for i in range(1, model.njoints)]
            k = int(np.argmax(depth)) + 1
            if mimic:
                k = 1 + next(i for i, m in enumerate(robot.mimic) if m >= 0)
            pin.computeJointJacobians(model, data, q)
            J = pin.getJointJacobian(model, data, k, pin.LOCAL_WORLD_ALIGNED)
            # by index: a name may be a link's and another joint's (so_arm's 'gripper')
            close(jflex.jacobian(robot, th, k - 1), J @ G if J.shape[1] == G.shape[0] else J,
                  what=f"jacobian of {model.names[k]}")
        if np.linalg.eigvalsh(M)[0] <= 1e-12 * np.abs(M).max():
            # a moving joint carrying no inertia (romeo's fingers, romeo_laas_small's grippers): M is singular
            continue
        qdd = np.asarray(jflex.forward_dynamics(robot, th, v, tau))
        qdd_pin = a if mimic else pin.aba(model, data, q, v, tau)
        # Accelerations are as exact as M is well conditioned (iCub: cond 4e7, Pinocchio's own aba
        # misses a by 2e-9); compared in torque space, M (qdd - qdd_pin), the check is uniform.
        close(M @ qdd, M @ qdd_pin, what="forward dynamics (torque space)")
        close(qdd, qdd_pin, rtol=RTOL * max(1.0, 1e-7 * np.linalg.cond(M)), what="forward dynamics")


def _load_pin(rel, mimic=False):
    try:
        return pin.buildModelFromUrdf(str(ERD / rel), mimic=mimic)
    except (RuntimeError, ValueError) as exc:  # ur3.urdf: "No name given for the robot"
        pytest.skip(f"Pinocchio does not load {rel}: {str(exc).splitlines()[0][:80]}")


@pytest.mark.slow
@pytest.mark.parametrize("rel", URDFS if SLOW else sorted(SUBSET & set(URDFS)))
def test_example_robot_data_urdf_matches_pinocchio(rel):
    path = ERD / rel
    mimic = rel in MIMIC_URDFS
    model = _load_pin(rel)
    if model.nv == 0:  # a lone body (quadrotor, iris_simple): no joint to model
        with pytest.raises(jflex.URDFError, match="no moving joints"):
            jflex.load_urdf(path)
        return
    broken = _broken_mimic(path)
    if broken:  # a <mimic> naming a joint the file lacks (alex_psyonic_hands): named, not coupled
        with pytest.raises(jflex.URDFError, match=f"joint '{broken}'.*<mimic joint=.*mimic='independent'"):
            jflex.load_urdf(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        robot = jflex.load_urdf(path, mimic="independent" if broken else "coupled")
    nonphysical = [str(w.message) for w in caught if "non-physical inertia" in str(w.message)]
    if nonphysical:
        with pytest.raises(jflex.URDFError, match="non-physical inertia"):
            jflex.load_urdf(path, mimic=robot.mimic and "coupled" or "independent", strict=True)
    big = rel in HEAVY_CRBA and not SLOW
    rng = np.random.default_rng(0)
    if not mimic or broken:
        compare(robot, model, rng, crba=not big, kinematics=not big)
        return
    assert robot.nq < robot.n_joints
    with pytest.raises(jflex.URDFError, match="mimic"):
        jflex.load_urdf(path, mimic="refuse")
    try:
        coupled = pin.buildModelFromUrdf(str(path), mimic=True)
    except (RuntimeError, ValueError):
        coupled = None  # "The parent joint of the mimic joint is not in the kinematic tree" (Pinocchio 3.x, 4.x)
    if coupled is not None:
        compare(robot, coupled, rng)
    else:
        G, b, coords = coupling(path, robot.joint_names)
        assert robot.coordinate_names == tuple(coords)
        compare(robot, model, rng, G=G, b=b)
    if SLOW or rel == "panda_description/urdf/panda.urdf":
        # as independent joints, against Pinocchio's default (mimic=False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            independent = jflex.load_urdf(path, mimic="independent")
        assert independent.joint_names == robot.joint_names and independent.nq == robot.n_joints
        compare(independent, model, np.random.default_rng(1), kinematics=False)


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


def test_panda_loads_as_it_ships_with_coupled_fingers():
    if ERD is None:
        pytest.skip("example-robot-data not installed")
    path = ERD / "panda_description/urdf/panda.urdf"
    robot = jflex.load_urdf(path)
    arm = tuple(f"panda_joint{i}" for i in range(1, 8))
    assert robot.coordinate_names == arm + ("panda_finger_joint1",)
    assert robot.joint_names == robot.coordinate_names + ("panda_finger_joint2",) and robot.nq == 8
    with pytest.raises(jflex.URDFError, match=r"panda.urdf: joint 'panda_finger_joint2' mimics joint 'panda_finger_joint1'.*lock="):
        jflex.load_urdf(path, mimic="refuse")
    with pytest.raises(jflex.URDFError, match=r"mimic must be one of \['coupled', 'independent', 'refuse'\]"):
        jflex.load_urdf(path, mimic="yes")
    # locking the leader locks the follower at multiplier * value + offset (1 and 0 here)
    locked = jflex.load_urdf(path, lock={"panda_finger_joint1": 0.03})
    model = _reduced_pin(pin.buildModelFromUrdf(str(path)), {"panda_finger_joint1": 0.03, "panda_finger_joint2": 0.03})
    compare(locked, model, np.random.default_rng(3))
    # a follower locked while its leader moves breaks the coupling: refused
    with pytest.raises(jflex.URDFError, match="panda_finger_joint2' mimics.*locked while its leader moves"):
        jflex.load_urdf(path, lock={"panda_finger_joint2": 0.01})
    # joints= names coordinates: a kept leader keeps its follower coupled to it
    hand = jflex.load_urdf(path, joints=["panda_joint7", "panda_finger_joint1"])
    assert hand.coordinate_names == ("panda_joint7", "panda_finger_joint1") and hand.n_joints == 3
    full = pin.buildModelFromUrdf(str(path), mimic=True)
    reduced = pin.buildReducedModel(full, [full.getJointId(f"panda_joint{i}") for i in range(1, 7)], pin.neutral(full))
    compare(hand, reduced, np.random.default_rng(4))
    with pytest.raises(jflex.URDFError, match="joints names 'panda_finger_joint2', which mimics joint 'panda_finger_joint1'"):
        jflex.load_urdf(path, joints=["panda_joint7", "panda_finger_joint2"])
    # load_robot("panda") is the 7-joint arm, fingers closed
    assert jflex.load_robot("panda").joint_names == arm


def test_duplicate_names_in_joints_are_refused():
    if ERD is None:
        pytest.skip("example-robot-data not installed")
    path = ERD / "ur_description/urdf/ur5_robot.urdf"
    with pytest.raises(jflex.URDFError, match="joints names 'elbow_joint' twice"):
        jflex.load_urdf(path, joints=["elbow_joint", "shoulder_lift_joint", "elbow_joint"])


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
    with pytest.raises(jflex.URDFError, match="joint 'j2'.*<mimic joint='j9'>.*mimic='independent'"):
        jflex.from_urdf_string(MIMIC.format(leader="j9"))
    r = jflex.from_urdf_string(MIMIC.format(leader="j9"), mimic="independent")
    assert r.joint_names == ("j0", "j1", "j2")
    r = jflex.from_urdf_string(MIMIC.format(leader="j1"), lock={"j1": 0.2})
    # j2 follows at 2 * 0.2 + 0.1 = 0.5 about the same z axis: frame 'b' turned by 0.2 + 0.5
    assert r.joint_names == ("j0",)
    c, s = np.cos(0.7), np.sin(0.7)
    close(np.asarray(jflex.frame_placement(r, np.zeros(1), "b"))[:3, :3], [[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _link(name, m, xyz):
    return (f'<link name="{name}"><inertial><origin xyz="{xyz}" rpy="0.1 0.2 0.3"/><mass value="{m}"/>'
            '<inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.03" iyz="0.002" izz="0.025"/></inertial></link>')


def _joint(name, typ, parent, child, axis, xyz, mimic=""):
    return (f'<joint name="{name}" type="{typ}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}" rpy="0.3 -0.2 0.1"/><axis xyz="{axis}"/>'
            f'<limit lower="-2" upper="2" effort="10" velocity="2"/>{mimic}</joint>')


def _coupled_urdf(j4_mimic=""):
    """j2 (revolute) and j3 (prismatic) follow j1 with multipliers and offsets; j4 is independent or
    (``j4_mimic``) follows j2 in turn."""
    return ('<robot name="coupled"><link name="base"/>' + _link("l1", 1.0, "0.1 0 0") + _link("l2", 0.7, "0 0.1 0")
            + _link("l3", 0.5, "0 0 0.1") + _link("l4", 0.3, "0.05 0.05 0")
            + _joint("j1", "revolute", "base", "l1", "0 0 1", "0 0 0.2")
            + _joint("j2", "revolute", "l1", "l2", "0 1 0", "0.3 0 0", '<mimic joint="j1" multiplier="2" offset="0.1"/>')
            + _joint("j3", "prismatic", "l2", "l3", "1 0 0", "0.2 0.1 0", '<mimic joint="j1" multiplier="-0.05" offset="0.02"/>')
            + _joint("j4", "revolute", "l3", "l4", "0 0.6 0.8", "0 0 0.2", j4_mimic)
            + "</robot>")


def test_mimic_multiplier_offset_and_chain_match_pinocchio():
    import jax

    text = _coupled_urdf()
    robot = jflex.from_urdf_string(text)
    assert robot.coordinate_names == ("j1", "j4") and robot.joint_names == ("j1", "j2", "j3", "j4")
    compare(robot, pin.buildModelFromXML(text, mimic=True), np.random.default_rng(6))
    # a chain (j4 follows j2, which follows j1): composed, against the independent model at G q + b
    chain = _coupled_urdf('<mimic joint="j2" multiplier="-1.5" offset="0.3"/>')
    robot2 = jflex.from_urdf_string(chain)
    assert robot2.coordinate_names == ("j1",)
    G, b, _ = coupling_from_text(chain, robot2.joint_names)
    np.testing.assert_allclose(G[:, 0], [1.0, 2.0, -0.05, -3.0])
    np.testing.assert_allclose(b, [0.0, 0.1, 0.02, -1.5 * 0.1 + 0.3])
    compare(robot2, pin.buildModelFromXML(chain), np.random.default_rng(7), G=G, b=b)
    # compiled with the robot traced (multipliers and offsets are leaves), batched, differentiated
    rng = np.random.default_rng(8)
    q, v, a = rng.normal(size=(3, 4, 2))
    eager = np.stack([np.asarray(jflex.rnea(robot, *x)) for x in zip(q, v, a)])
    close(jax.jit(jax.vmap(jflex.rnea, (None, 0, 0, 0)))(robot, q, v, a), eager)
    f = lambda k: jflex.rnea(robot.replace(mimic_multiplier=robot.mimic_multiplier.at[1].set(k)), q[0], v[0], a[0])
    h = 1e-6
    close(jax.jacfwd(f)(2.0), (np.asarray(f(2.0 + h)) - np.asarray(f(2.0 - h))) / (2 * h), rtol=1e-6)
    cycle = _coupled_urdf('<mimic joint="j2" multiplier="1" offset="0"/>').replace('<mimic joint="j1" multiplier="2"', '<mimic joint="j4" multiplier="2"')
    with pytest.raises(jflex.URDFError, match="mimic each other in a cycle"):
        jflex.from_urdf_string(cycle)
    with pytest.raises(jflex.URDFError, match="joint 'j2' <mimic>: multiplier and offset must be finite"):
        jflex.from_urdf_string(text.replace('multiplier="2"', 'multiplier="inf"'))


def test_long_chain_loads_without_recursion():
    # 990 joints once exhausted Python's recursion limit in the tree walk (RecursionError).
    # Pinocchio's own URDF parser is no reference here (it ran out of memory on this file): the tip's
    # placement is checked against the product of the URDF's transforms.
    from scipy.spatial.transform import Rotation

    n = 990
    axes = ["0 0 1", "0 1 0", "1 0 0"]
    parts = ['<robot name="chain"><link name="l0"/>']
    for i in range(1, n + 1):
        parts.append(f'<link name="l{i}">' + _inertial(0.1, 1e-4, 1e-4, 1e-4, "0.05 0 0") + "</link>")
        parts.append(f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/><child link="l{i}"/>'
                     f'<origin xyz="0.1 0 0" rpy="0 0 0.01"/><axis xyz="{axes[i % 3]}"/>'
                     '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>')
    robot = jflex.from_urdf_string("".join(parts) + "</robot>")
    assert robot.nq == n and robot.parents == tuple(range(-1, n - 1))
    q = np.random.default_rng(9).uniform(-0.1, 0.1, n)
    ref = np.eye(4)
    step = np.eye(4)
    step[:3, :3], step[:3, 3] = Rotation.from_euler("xyz", [0, 0, 0.01]).as_matrix(), [0.1, 0, 0]
    for i in range(1, n + 1):
        turn = np.eye(4)
        turn[:3, :3] = Rotation.from_rotvec(np.array(axes[i % 3].split(), float) * q[i - 1]).as_matrix()
        ref = ref @ step @ turn
    close(jflex.frame_placement(robot, q, f"l{n}"), ref)


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
  <link name="world"/><link name="pelvis"/>
  <link name="leg"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
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
