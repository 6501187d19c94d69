"""The elastic sites of a frequency model (:class:`Site`): where a spring sits in the kinematic tree,
and the robot with the virtual joints of the sites inserted (:func:`augment`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..._robot import make_robot
from ._laws import VISCOUS


@dataclasses.dataclass(frozen=True, eq=False)
class Site:
    """One elastic coordinate: ``kind`` joint | orth | link, at joint/link index ``where``,
    ``axis`` 0/1 for virtual pairs, its damping ``law`` (a unit-loss prototype of a
    :mod:`jflex.effects` law), ``frac`` the position of a link hinge along the link (0 root, 1
    tip), ``coupled`` on the axis-1 site of a pair whose stiffness couples with its axis-0 partner."""

    kind: str
    where: int
    axis: int = 0
    law: object = VISCOUS
    frac: float = 0.5
    coupled: bool = False


def _perp(a):
    a = np.asarray(a, float) / np.linalg.norm(a)
    e = np.eye(3)[np.argmin(np.abs(a))]
    u1 = np.cross(a, e)
    u1 /= np.linalg.norm(u1)
    return u1, np.cross(a, u1)


def augment(robot, springs):
    """The robot with the virtual joints of ``springs`` inserted (zero-inertia links), and the
    index of each spring's coordinate in it. Returns ``(robot_aug, coord_index (S,), model_index (n,))``."""
    n = robot.nq
    R = np.asarray(robot.placement_R)
    P = np.asarray(robot.placement_p)
    ax = np.asarray(robot.axis)
    inert = np.asarray(robot.inertia)
    joints = []  # dicts in build order
    for i in range(n):
        joints.append(dict(name=robot.joint_names[i], link=robot.link_names[i],
                           parent=None if robot.parents[i] < 0 else robot.link_names[robot.parents[i]],
                           R=R[i].copy(), p=P[i].copy(), axis=ax[i].copy(), type=robot.joint_types[i],
                           inertia=inert[i].copy(), lower=float(robot.lower[i]), upper=float(robot.upper[i])))
    frames = [dict(name=robot.frame_names[k], parent=None if robot.frame_parents[k] < 0 else robot.link_names[robot.frame_parents[k]],
                   R=np.asarray(robot.frame_R[k]).copy(), p=np.asarray(robot.frame_p[k]).copy()) for k in range(len(robot.frame_names))]

    def find(name):
        return next(k for k, j in enumerate(joints) if j["link"] == name)

    virtual = {}
    for s in springs:
        if s.kind == "orth" and (("orth", s.where) not in virtual):
            j = find(robot.link_names[s.where])
            J = joints[j]
            u1, u2 = _perp(J["axis"])
            v1 = dict(name=f"{J['name']}_orth_a", link=f"{J['link']}_orth_a", parent=J["parent"], R=J["R"], p=J["p"],
                      axis=u1, type="revolute", inertia=np.zeros(10),
                      lower=-np.inf, upper=np.inf)
            v2 = dict(name=f"{J['name']}_orth_b", link=f"{J['link']}_orth_b", parent=v1["link"], R=np.eye(3), p=np.zeros(3),
                      axis=u2, type="revolute", inertia=np.zeros(10), lower=-np.inf, upper=np.inf)
            J["parent"], J["R"], J["p"] = v2["link"], np.eye(3), np.zeros(3)
            joints[j:j] = [v1, v2]
            virtual[("orth", s.where)] = (v1["name"], v2["name"])
        if s.kind == "link" and (("link", s.where) not in virtual):
            link = robot.link_names[s.where]
            j = find(link)
            kids = [k for k, jj in enumerate(joints) if jj["parent"] == link]
            kf = [f for f in frames if f["parent"] == link]
            ends = [joints[k]["p"] for k in kids] + [f["p"] for f in kf]
            L = max(ends, key=np.linalg.norm) if ends else np.array([0.0, 0.0, 0.1])
            if np.linalg.norm(L) < 1e-9:
                L = np.array([0.0, 0.0, 0.1])
            u1, u2 = _perp(L)
            mid = s.frac * L
            v1 = dict(name=f"{link}_bend_a", link=f"{link}_bend_a", parent=link, R=np.eye(3), p=mid, axis=u1,
                      type="revolute", inertia=np.zeros(10), lower=-np.inf, upper=np.inf)
            v2 = dict(name=f"{link}_bend_b", link=f"{link}_bend_b", parent=v1["link"], R=np.eye(3), p=np.zeros(3),
                      axis=u2, type="revolute", inertia=np.zeros(10), lower=-np.inf, upper=np.inf)
            for k in kids:
                joints[k]["parent"], joints[k]["p"] = v2["link"], joints[k]["p"] - mid
            for f in kf:
                f["parent"], f["p"] = v2["link"], f["p"] - mid
            joints[j + 1:j + 1] = [v1, v2]
            virtual[("link", s.where)] = (v1["name"], v2["name"])
    names = [j["link"] for j in joints]
    aug = make_robot(
        joint_names=[j["name"] for j in joints], link_names=names,
        parents=[-1 if j["parent"] is None else names.index(j["parent"]) for j in joints],
        joint_types=[j["type"] for j in joints], placement_R=np.stack([j["R"] for j in joints]),
        placement_p=np.stack([j["p"] for j in joints]), axis=np.stack([j["axis"] for j in joints]),
        gravity=np.asarray(robot.gravity),
        # limits are left out: the linear analysis does not use them (and make_robot rejects the
        # infinite limits of virtual joints when passed explicitly)
        frame_names=[f["name"] for f in frames],
        frame_parents=[-1 if f["parent"] is None else names.index(f["parent"]) for f in frames],
        frame_R=np.stack([f["R"] for f in frames]) if frames else None,
        frame_p=np.stack([f["p"] for f in frames]) if frames else None, base_name=robot.base_name,
    )
    # inertias set after the build: a base-parameter realisation need not pass make_robot's
    # per-link physical checks, and the linear analysis does not need it to
    aug = aug.replace(inertia=np.stack([j["inertia"] for j in joints]))
    jn = list(aug.joint_names)
    coord = []
    for s in springs:
        if s.kind == "joint":
            coord.append(jn.index(robot.joint_names[s.where]))
        else:
            coord.append(jn.index(virtual[(s.kind, s.where)][s.axis]))
    model_index = [jn.index(nm) for nm in robot.joint_names]
    return aug, np.array(coord, dtype=int), np.array(model_index, dtype=int)
