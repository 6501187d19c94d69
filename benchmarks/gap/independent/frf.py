"""Frequency-side truths: the linearised flexible robot at a posture, its tool FRF estimated by
H1 from a simulated test, and modal tables (Pinocchio for M, dG/dq and the tool Jacobian,
NumPy for the rest).

Coordinates: the link angles of the (possibly augmented) Pinocchio model and one motor angle per
actuated joint. Each actuated joint is a spring between motor and link (a complex stiffness:
viscous ``k + i w c``, hysteretic ``k (1 + i eta)`` or fractional ``k + c (i w)^alpha``); each
motor (inertia ``B``) is held by a stiff position servo (``kp + i w kd``), so the motors are
nearly, not perfectly, held. Virtual joints (bearing tilt, link bending, a rocking base) are
springs to the ground frame of their own coordinate.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .robots import joint_axis


def _perp(a):
    a = np.asarray(a, float) / np.linalg.norm(a)
    e = np.eye(3)[np.argmin(np.abs(a))]
    u = np.cross(a, e)
    u /= np.linalg.norm(u)
    return u, np.cross(a, u)


def augment(model, tool, orth=(), bend=(), rocking=None, bend_at=0.5):
    """A copy of ``model`` with virtual revolute joints: ``orth``: joint indices (0-based) that get
    two tilt axes at their origin; ``bend``: link indices (0-based, not the last) that get two
    bending hinges ``bend_at`` of the way to the child joint, the link's inertia split in that
    proportion; ``rocking``: the inertia (pin.Inertia) of a base that rocks about the x axis
    under the whole robot. Returns ``(model, tool frame id, actuated coordinates (n,), virtual
    coordinates (list))``, coordinates as indices into q."""
    out = pin.Model()
    out.gravity = model.gravity
    attach = {0: (0, pin.SE3.Identity())}
    virt, act = [], []

    def add(parent, axis, placement, name, inertia):
        jid = out.addJoint(parent, pin.JointModelRevoluteUnaligned(np.asarray(axis, float)), placement, name)
        out.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
        return jid

    if rocking is not None:
        attach[0] = (add(0, [1.0, 0.0, 0.0], pin.SE3.Identity(), "base_rock", rocking), pin.SE3.Identity())
        virt.append(attach[0][0])
    for i in range(1, model.njoints):
        parent, off = attach[model.parents[i]]
        P = off * model.jointPlacements[i]
        ax = joint_axis(model, i)
        if (i - 1) in orth:
            u1, u2 = _perp(P.rotation @ ax)
            v1 = add(parent, u1, pin.SE3(np.eye(3), P.translation), f"{model.names[i]}_tilt_a", pin.Inertia.Zero())
            v2 = add(v1, u2, pin.SE3.Identity(), f"{model.names[i]}_tilt_b", pin.Inertia.Zero())
            virt += [v1, v2]
            parent, P = v2, pin.SE3(P.rotation, np.zeros(3))
        I = model.inertias[i]
        if (i - 1) in bend:
            kids = [k for k in range(1, model.njoints) if model.parents[k] == i]
            L = model.jointPlacements[kids[0]].translation
            u1, u2 = _perp(L)
            s = bend_at
            jid = add(parent, ax, P, model.names[i], pin.Inertia(I.mass * s, I.lever, I.inertia * s))
            act.append(jid)
            v1 = add(jid, u1, pin.SE3(np.eye(3), s * L), f"{model.names[i]}_bend_a", pin.Inertia.Zero())
            outer = pin.SE3(np.eye(3), -s * L).act(pin.Inertia(I.mass * (1 - s), I.lever, I.inertia * (1 - s)))
            v2 = add(v1, u2, pin.SE3.Identity(), f"{model.names[i]}_bend_b", outer)
            virt += [v1, v2]
            attach[i] = (v2, pin.SE3(np.eye(3), -s * L))
        else:
            jid = add(parent, ax, P, model.names[i], I)
            act.append(jid)
            attach[i] = (jid, pin.SE3.Identity())
    f = model.frames[model.getFrameId(tool)]
    parent, off = attach[f.parentJoint]
    fid = out.addFrame(pin.Frame(tool, parent, off * f.placement, pin.FrameType.OP_FRAME))
    idx = lambda jid: out.joints[jid].idx_q  # noqa: E731
    return out, fid, [idx(j) for j in act], [idx(j) for j in virt]


class Linear:
    """The linear flexible robot at posture ``q0`` (model joint order, virtual coordinates at 0).

    ``joint``: per actuated joint a dict ``k`` [N m/rad], ``law`` (viscous | hysteretic |
    fractional), ``c`` / ``eta`` / (``c``, ``alpha``), motor ``B`` [kg m^2], servo ``kp``, ``kd``;
    ``virtual``: ``(K (V, V), C (V, V))`` spring and damping matrices of the virtual coordinates."""

    def __init__(self, model, fid, act, virt, q0, joint, virtual=None):
        data = model.createData()
        q = np.zeros(model.nq)
        q[act] = q0
        self.M = pin.crba(model, data, q)
        self.M = np.triu(self.M) + np.triu(self.M, 1).T
        self.Kg = pin.computeGeneralizedGravityDerivatives(model, data, q)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        self.J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:3]
        self.act, self.virt, self.joint = list(act), list(virt), joint
        self.virtual = virtual
        self.nl, self.na = model.nq, len(act)

    def dynamic_stiffness(self, f):
        """D(w) (F, N, N) over link then motor coordinates."""
        w = 2 * np.pi * np.asarray(f, float)
        nl, na = self.nl, self.na
        N = nl + na
        D = np.zeros((w.size, N, N), complex)
        D[:, :nl, :nl] = self.Kg[None] - w[:, None, None] ** 2 * self.M[None]
        for a, (ci, p) in enumerate(zip(self.act, self.joint)):
            law = p.get("law", "viscous")
            if law == "viscous":
                ks = p["k"] + 1j * w * p["c"]
            elif law == "hysteretic":
                ks = p["k"] * (1 + 1j * p["eta"]) * np.ones_like(w)
            elif law == "fractional":
                ks = p["k"] + p["c"] * (1j * w) ** p["alpha"]
            else:
                raise KeyError(law)
            m = nl + a
            D[:, ci, ci] += ks
            D[:, m, m] += ks + p["kp"] + 1j * w * p["kd"] - w**2 * p["B"]
            D[:, ci, m] -= ks
            D[:, m, ci] -= ks
        if self.virt:
            K, C = self.virtual
            v = np.array(self.virt)
            D[:, v[:, None], v[None, :]] += K[None] + 1j * w[:, None, None] * C[None]
        return D

    def frf(self, f):
        """Tool receptance (F, 3, 3) [m/N], output x input, base axes."""
        D = self.dynamic_stiffness(f)
        Jf = np.zeros((3, self.nl + self.na))
        Jf[:, :self.nl] = self.J
        X = np.linalg.solve(D, np.broadcast_to(Jf.T.astype(complex), (D.shape[0],) + Jf.T.shape))
        return Jf[None] @ X

    def modes(self):
        """Natural frequencies [Hz] and damping ratios of the viscous system (laws other than
        viscous are not handled), sorted."""
        nl, na = self.nl, self.na
        N = nl + na
        M = np.zeros((N, N))
        K = np.zeros((N, N))
        C = np.zeros((N, N))
        M[:nl, :nl] = self.M
        K[:nl, :nl] = self.Kg
        for a, (ci, p) in enumerate(zip(self.act, self.joint)):
            m = nl + a
            M[m, m] = p["B"]
            for mat, v in ((K, p["k"]), (C, p["c"])):
                mat[ci, ci] += v
                mat[m, m] += v
                mat[ci, m] -= v
                mat[m, ci] -= v
            K[m, m] += p["kp"]
            C[m, m] += p["kd"]
        if self.virt:
            v = np.array(self.virt)
            K[v[:, None], v[None, :]] += self.virtual[0]
            C[v[:, None], v[None, :]] += self.virtual[1]
        keep = np.abs(np.diag(M)) > 0  # massless virtual bodies have mass through their children
        A = np.block([[np.zeros((N, N)), np.eye(N)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
        lam = np.linalg.eigvals(A)
        lam = lam[lam.imag > 1e-6]
        fn = np.abs(lam) / (2 * np.pi)
        z = -lam.real / np.abs(lam)
        o = np.argsort(fn)
        del keep
        return fn[o], z[o]
