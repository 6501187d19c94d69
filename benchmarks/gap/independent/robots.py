"""Robots of the independent bench as Pinocchio models, and URDF files written from them.

Nothing here imports jflex: the true robot is a Pinocchio model (a 3-joint arm written below,
UR5 and Panda from example-robot-data's URDF files), the case's nominal robot is the same model
with CAD-like inertia errors, written back to URDF for the case folder.
"""

from __future__ import annotations

import pathlib
import sys

import numpy as np
import pinocchio as pin

ARM3_URDF = """<?xml version="1.0"?>
<robot name="arm3">
  <link name="base_link"/>
  <joint name="joint1" type="revolute">
    <parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 0.40" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3.0" upper="3.0" effort="300" velocity="3"/>
  </joint>
  <link name="link1">
    <inertial><origin xyz="0 0.01 -0.12" rpy="0 0 0"/><mass value="11.0"/>
      <inertia ixx="0.25" ixy="0" ixz="0" iyy="0.24" iyz="0" izz="0.12"/></inertial>
  </link>
  <joint name="joint2" type="revolute">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="0 0.12 0.05" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.5" upper="2.5" effort="300" velocity="3"/>
  </joint>
  <link name="link2">
    <inertial><origin xyz="0.26 0 0.015" rpy="0 0 0"/><mass value="7.5"/>
      <inertia ixx="0.03" ixy="0" ixz="0.004" iyy="0.21" iyz="0" izz="0.20"/></inertial>
  </link>
  <joint name="joint3" type="revolute">
    <parent link="link2"/><child link="link3"/>
    <origin xyz="0.55 -0.10 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2.8" upper="2.8" effort="150" velocity="3"/>
  </joint>
  <link name="link3">
    <inertial><origin xyz="0.21 0.005 0" rpy="0 0 0"/><mass value="3.8"/>
      <inertia ixx="0.012" ixy="0" ixz="0" iyy="0.075" iyz="0" izz="0.072"/></inertial>
  </link>
  <joint name="tool_joint" type="fixed">
    <parent link="link3"/><child link="tool"/><origin xyz="0.45 0 0" rpy="0 0 0"/>
  </joint>
  <link name="tool"/>
</robot>
"""

# name -> (URDF path inside example-robot-data's robots folder, tool frame, home posture [rad], joints to lock)
ERD = {
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0", [0.0, -1.2, 1.4, -1.6, -1.5, 0.0], ()),
    "panda": ("panda_description/urdf/panda.urdf", "panda_hand_tcp", [0.0, -0.6, 0.0, -2.2, 0.0, 1.7, 0.8],
              ("panda_finger_joint1", "panda_finger_joint2")),
}
HOME = {"arm3": [0.0, 0.7, -1.3]}
TOOL = {"arm3": "tool"}


def erd_root() -> pathlib.Path:
    """example-robot-data's ``robots`` folder (shipped as data next to Pinocchio by cmeel)."""
    for p in map(pathlib.Path, sys.path):
        c = p / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if c.is_dir():
            return c
    c = pathlib.Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"
    if c.is_dir():
        return c
    raise FileNotFoundError("example-robot-data's robots folder not found (pip install example-robot-data)")


def true_model(name: str) -> tuple[pin.Model, str, np.ndarray]:
    """The true robot ``name`` (arm3, ur5, panda): Pinocchio model, tool frame name, home posture."""
    if name == "arm3":
        return pin.buildModelFromXML(ARM3_URDF), TOOL["arm3"], np.array(HOME["arm3"])
    rel, tool, home, lock = ERD[name]
    model = pin.buildModelFromUrdf(str(erd_root() / rel))
    if lock:
        # the fingers are locked (closed), their mass merged into the hand
        ids = [model.getJointId(j) for j in lock]
        model = pin.buildReducedModel(model, ids, pin.neutral(model))
    return model, tool, np.array(home)


_AXES = {"RX": (1.0, 0.0, 0.0), "RY": (0.0, 1.0, 0.0), "RZ": (0.0, 0.0, 1.0)}


def joint_axis(model: pin.Model, i: int) -> np.ndarray:
    sn = model.joints[i].shortname()
    for k, a in _AXES.items():
        if sn.endswith(k):
            return np.array(a)
    if "RevoluteUnaligned" in sn:
        return np.asarray(model.joints[i].extract().axis, float)
    raise ValueError(f"joint {model.names[i]}: type {sn} is not a revolute joint this bench writes")


def link_names(model: pin.Model) -> list[str]:
    """One link name per joint (index 0: the base)."""
    out = ["base_link"]
    for i in range(1, model.njoints):
        bodies = [f.name for f in model.frames if f.parentJoint == i and f.type == pin.FrameType.BODY]
        out.append(bodies[0] if bodies else f"{model.names[i]}_link")
    return out


def _xyz_rpy(M: pin.SE3) -> str:
    xyz = " ".join(f"{v:.12g}" for v in M.translation)
    rpy = " ".join(f"{v:.12g}" for v in pin.rpy.matrixToRpy(M.rotation))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def urdf_text(model: pin.Model, tool: str, name: str = "robot") -> str:
    """A URDF of the fixed-base revolute chain ``model`` (inertias as they are in the model) with
    the frame ``tool`` as a fixed child link."""
    links = link_names(model)
    L = ['<?xml version="1.0"?>', f'<robot name="{name}">', f'  <link name="{links[0]}"/>']
    for i in range(1, model.njoints):
        I = model.inertias[i]
        c, Ic = I.lever, I.inertia
        ax = " ".join(f"{v:.12g}" for v in joint_axis(model, i))
        lo, hi = model.lowerPositionLimit[i - 1], model.upperPositionLimit[i - 1]
        eff, vel = model.effortLimit[i - 1], model.velocityLimit[i - 1]
        L += [f'  <joint name="{model.names[i]}" type="revolute">',
              f'    <parent link="{links[model.parents[i]]}"/><child link="{links[i]}"/>',
              f"    {_xyz_rpy(model.jointPlacements[i])}<axis xyz=\"{ax}\"/>",
              f'    <limit lower="{lo:.12g}" upper="{hi:.12g}" effort="{eff:.12g}" velocity="{vel:.12g}"/>',
              "  </joint>",
              f'  <link name="{links[i]}"><inertial>',
              f'    <origin xyz="{c[0]:.12g} {c[1]:.12g} {c[2]:.12g}" rpy="0 0 0"/><mass value="{I.mass:.12g}"/>',
              f'    <inertia ixx="{Ic[0, 0]:.12g}" ixy="{Ic[0, 1]:.12g}" ixz="{Ic[0, 2]:.12g}" '
              f'iyy="{Ic[1, 1]:.12g}" iyz="{Ic[1, 2]:.12g}" izz="{Ic[2, 2]:.12g}"/>',
              "  </inertial></link>"]
    f = model.frames[model.getFrameId(tool)]
    L += [f'  <joint name="{tool}_joint" type="fixed">',
          f'    <parent link="{links[f.parentJoint]}"/><child link="{tool}"/>{_xyz_rpy(f.placement)}',
          "  </joint>", f'  <link name="{tool}"/>', "</robot>"]
    return "\n".join(L) + "\n"


def tool_placement(model: pin.Model, tool: str) -> tuple[int, pin.SE3]:
    f = model.frames[model.getFrameId(tool)]
    return f.parentJoint, f.placement


def cad_error(model: pin.Model, rng, mass_pct=(2.0, 10.0), com_m=(0.005, 0.02)) -> tuple[pin.Model, list]:
    """The CAD (nominal) robot: every link's mass off by 2-10 % (random sign; its rotational
    inertia scaled alike) and its COM shifted by 0.5-2 cm in a random direction. Returns the
    nominal model and, per link, what was changed."""
    nom = model.copy()
    info = []
    for i in range(1, model.njoints):
        I = model.inertias[i]
        s = 1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(*mass_pct) / 100.0
        d = rng.normal(size=3)
        d *= rng.uniform(*com_m) / np.linalg.norm(d)
        nom.inertias[i] = pin.Inertia(I.mass * s, I.lever + d, I.inertia * s)
        info.append(dict(joint=model.names[i], mass_true=float(I.mass), mass_cad=float(I.mass * s),
                         com_true=[float(v) for v in I.lever], com_cad=[float(v) for v in I.lever + d]))
    return nom, info


def add_payload(model: pin.Model, tool: str, mass: float, offset, radius: float = 0.05) -> pin.Model:
    """``model`` carrying a solid sphere of ``mass`` [kg] whose centre is ``offset`` [m] from the
    tool frame's origin (tool axes)."""
    out = model.copy()
    j, P = tool_placement(model, tool)
    sphere = pin.Inertia(mass, np.asarray(offset, float), np.eye(3) * 0.4 * mass * radius**2)
    out.inertias[j] = out.inertias[j] + P.act(sphere)
    return out
