"""The identification regressor: rigid inertial parameters plus the joint-level terms that
torque data also see (viscous and Coulomb friction, rotor armature, gravity-compensator Fourier
terms, the thesis "Posture Dependent Dynamics in Robotic Machining" Eqs. 2.11/3.1 and Appendix B).

Parameters are ordered ``[pi_1 (10), ..., pi_n (10), Fv (n), Fc (n), Ia (n), B_1..B_K]``, each
group present only when switched on; ``pi_i`` in Pinocchio's order.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import checked_arrays, guard
from .._robot import PRISMATIC, Robot
from .._tree import support
from ..data._validate import check_finite, check_shape

_PI_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")


class Regressor(eqx.Module):
    """Which terms the torque model has; ``__call__`` gives the (n, p) regressor of one sample.

    **Fields (static):**

    - ``viscous``, ``coulomb``: per-joint ``Fv qd`` and ``Fc sign(qd)`` friction.
    - ``armature``: per-joint rotor inertia reflected to the joint, ``Ia qdd``.
    - ``compensator``: ``(joint, K)``: a gravity compensator on ``joint`` (0-based) modelled by
      ``tau_GC = sum_k B_k cos(k q_joint)`` acting as an external torque (Eq. 2.11), so its
      columns are ``-cos(k q)``; ``None`` for none.
    - ``coulomb_width`` [rad/s]: when > 0, ``sign`` is replaced by ``tanh(qd / width)``.

    **Field (a pytree):** ``effects``: :class:`jflex.effects.AbstractLinearEffect` effects (a torque
    offset, direction-dependent Coulomb friction, a coupled drive, ...) whose coefficients are
    identified too: their columns (the effect's own regressor) follow the groups above, in order,
    named ``owner.leaf`` (e.g. ``joint3.offset``); the values they hold are irrelevant to the columns.
    """

    viscous: bool = eqx.field(static=True, default=True)
    coulomb: bool = eqx.field(static=True, default=True)
    armature: bool = eqx.field(static=True, default=False)
    compensator: tuple[int, int] | None = eqx.field(static=True, default=None)
    coulomb_width: float = eqx.field(static=True, default=0.0)
    effects: tuple = ()

    def n_params(self, n: int) -> int:
        """Number of standard parameters for an ``n``-joint robot."""
        k = self.compensator[1] if self.compensator else 0
        k += sum(int(np.size(e.parameters())) for e in self.effects)
        return 10 * n + n * (int(self.viscous) + int(self.coulomb) + int(self.armature)) + k

    def names(self, robot: Robot) -> tuple[str, ...]:
        """Parameter names, e.g. ``link2.mcx``, ``joint1.Fv``, ``joint2.B3``."""
        out = [f"{l}.{p}" for l in robot.link_names for p in _PI_NAMES]
        for flag, tag in ((self.viscous, "Fv"), (self.coulomb, "Fc"), (self.armature, "Ia")):
            if flag:
                out += [f"{j}.{tag}" for j in robot.joint_names]
        if self.compensator:
            j, k = self.compensator
            out += [f"{robot.joint_names[j]}.B{i + 1}" for i in range(k)]
        for e in self.effects:
            out += list(e.parameter_names(robot))
        return tuple(out)

    def vector(self, robot: Robot, *, fv=None, fc=None, armature=None, compensator=None):
        """The standard parameter vector (p,) of ``robot`` with the given joint-level terms
        (zeros where not given)."""
        n = robot.nq
        parts = [jnp.ravel(robot.inertia)]
        for flag, v in ((self.viscous, fv), (self.coulomb, fc), (self.armature, armature)):
            if flag:
                parts.append(jnp.zeros(n) if v is None else jnp.asarray(v, dtype=float).reshape(n))
        if self.compensator:
            k = self.compensator[1]
            parts.append(jnp.zeros(k) if compensator is None else jnp.asarray(compensator, dtype=float).reshape(k))
        # the effects' coefficients as they hold them
        parts += [jnp.asarray(e.parameters(), dtype=float) for e in self.effects]
        return jnp.concatenate(parts)

    def __call__(self, robot: Robot, q, qd, qdd):
        """Regressor Y (n, p) of one sample: ``tau = Y @ theta``.

        **Arguments:** ``q``, ``qd``, ``qdd`` (n,) [rad, rad/s, rad/s^2].
        """
        q, qd, qdd = checked_arrays("Regressor", robot, q=q, qd=qd, qdd=qdd)
        return _rows(self, robot, q[None], qd[None], qdd[None])

    def _joint_columns(self, robot: Robot, q, qd, qdd):
        """The columns after the rigid block (n, p - 10 n) of one sample (some there must be)."""
        n = robot.nq
        cols = []
        eye = jnp.eye(n, dtype=jnp.result_type(float))
        if self.viscous:
            cols.append(eye * qd)
        if self.coulomb:
            s = jnp.tanh(qd / self.coulomb_width) if self.coulomb_width > 0 else jnp.sign(qd)
            cols.append(eye * s)
        if self.armature:
            cols.append(eye * qdd)
        if self.compensator:
            j, k = self.compensator
            c = -jnp.cos(jnp.arange(1, k + 1) * q[j])
            cols.append(jnp.zeros((n, k), dtype=eye.dtype).at[j].set(c))
        cols += [e.regressor(robot, q, qd, qdd) for e in self.effects]
        return jnp.concatenate(cols, axis=1)

    def stack(self, robot: Robot, q, qd, qdd):
        """Observation matrix A (N n, p) of N samples, rows sample-major (``tau.ravel()`` order).

        **Arguments:** ``q``, ``qd``, ``qdd`` (N, n).
        """
        if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves((robot, q, qd, qdd))):
            q, qd, qdd = (jnp.asarray(x) for x in (q, qd, qdd))
            q = guard(q, [~jnp.all(jnp.isfinite(x)) for x in (q, qd, qdd)],
                      [f"Regressor.stack: {f} contains NaN/inf" for f in ("q", "qd", "qdd")])
            return _rows(self, robot, q, qd, qdd)
        q = check_finite(check_shape(q, (None, robot.nq), "q", "Regressor.stack"), "q", "Regressor.stack")
        qd, qdd = (check_finite(check_shape(x, q.shape, f, "Regressor.stack"), f, "Regressor.stack")
                   for x, f in ((qd, "qd"), (qdd, "qdd")))
        # Blocks of one fixed size, the last padded: one compiled program serves every N (the
        # base-parameter search's few samples and the data's many), compiled once per robot
        # structure since the robot is an argument.
        N = q.shape[0]
        pad = ((0, -N % _BLOCK), (0, 0))
        q, qd, qdd = (np.pad(np.asarray(x, dtype=float), pad) for x in (q, qd, qdd))
        # all blocks dispatched before any is waited for: they run while Python dispatches
        parts = [_block(self, robot, q[i : i + _BLOCK], qd[i : i + _BLOCK], qdd[i : i + _BLOCK])
                 for i in range(0, q.shape[0], _BLOCK)]
        # device_put: jnp.asarray compiles a copy program per shape (jax 0.10)
        return jax.device_put(np.concatenate([np.asarray(x) for x in parts])[: N * robot.nq])


_BLOCK = 512  # samples per compiled regressor block


def _rigid(robot: Robot, q, qd, qdd):
    """Rigid-body regressor (n, 10 n, B) of B samples given as (n, B) each (the batch last):
    ``tau_i = sum_j S_i . (X_j Phi_j) pi_j`` over the bodies ``j`` that joint ``i`` carries, with
    the motion subspaces ``S_i`` and the body regressors ``Phi_j`` (6 x 10: the body force per unit
    of each inertial parameter) in world axes.

    In world axes the velocities and accelerations are sums over the ancestors and the forces
    need no backward pass, so only the placements are chained body by body; everything else is
    one batch over the bodies, a short program that traces and compiles in a fraction of the
    time of the scalarised kernels (``jflex.regressor``): the identification's start-up. The
    samples are the last axis, not a ``vmap``: a block of them traces as one sample does, in
    about half the time of the vmapped function.
    """
    n = robot.nq
    prism = np.array([t == PRISMATIC for t in robot.joint_types])[:, None]
    carries = np.zeros((n, n))  # carries[j, i]: joint i moves body j
    for j in range(n):
        carries[j, support(robot, j)] = 1.0
    # joint placements at q, then the world placements along the tree
    ax = robot.axis
    sw, sv = jnp.where(prism, 0.0, ax)[..., None], jnp.where(prism, ax, 0.0)[..., None]
    K, th = _hat(sw), jnp.where(prism, 0.0, q)[:, None, None, :]
    PR = robot.placement_R[..., None]
    R_loc = _mm(PR, jnp.eye(3)[..., None] + jnp.sin(th) * K + (1.0 - jnp.cos(th)) * _mm(K, K))
    p_loc = robot.placement_p[..., None] + _mv(PR, sv * q[:, None, :])
    oR, op = [None] * n, [None] * n
    for i, par in enumerate(robot.parents):
        oR[i], op[i] = (R_loc[i], p_loc[i]) if par < 0 else (_mm(oR[par], R_loc[i]), op[par] + _mv(oR[par], p_loc[i]))
    oR, op = jnp.stack(oR), jnp.stack(op)
    # world-axes motion subspaces, spatial velocities and accelerations (at the world origin);
    # the base accelerates upwards against gravity (Featherstone's trick)
    Sw = _mv(oR, sw)
    Sv = _mv(oR, sv) + _cross(op, Sw)

    def carried(x):  # (n, 3, B): summed over the joints that move each body
        return jnp.sum(carries[:, :, None, None] * x[None], axis=1)

    w0, v0 = carried(Sw * qd[:, None, :]), carried(Sv * qd[:, None, :])
    cw = _cross(w0, Sw * qd[:, None, :])
    cv = _cross(w0, Sv * qd[:, None, :]) + _cross(v0, Sw * qd[:, None, :])
    aw0 = carried(Sw * qdd[:, None, :] + cw)
    av0 = carried(Sv * qdd[:, None, :] + cv) - robot.gravity[:, None]
    # body axes, about the body origin, where the inertial parameters are given
    Rt = jnp.swapaxes(oR, -2, -3)
    w, aw = _mv(Rt, w0), _mv(Rt, aw0)
    v, av = _mv(Rt, v0 + _cross(w0, op)), _mv(Rt, av0 + _cross(aw0, op))
    Phi = _body_regressor(w, v, aw, av)  # (n, 6, 10, B)
    f0 = _mm(oR, Phi[:, 3:])
    n0 = _mm(oR, Phi[:, :3]) + _mm(_hat(op), f0)
    Y = jnp.sum(Sw[:, None, :, None, :] * n0[None] + Sv[:, None, :, None, :] * f0[None], axis=2)  # (i, j, 10, B)
    return (carries.T[:, :, None, None] * Y).reshape(n, 10 * n, -1)


# _hat(a)[i, j] = sum_k _HAT[i, j, k] a[k]: minus the Levi-Civita symbol
_HAT = np.zeros((3, 3, 3))
_HAT[0, 1, 2] = _HAT[1, 2, 0] = _HAT[2, 0, 1] = -1.0
_HAT[0, 2, 1] = _HAT[2, 1, 0] = _HAT[1, 0, 2] = 1.0
# I x == the (3, 6) map _INERTIA (3, 6, 3) applied to x, times (Ixx, Ixy, Iyy, Ixz, Iyz, Izz)
_INERTIA = np.zeros((3, 6, 3))
for _k, (_a, _b) in enumerate(((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))):
    _INERTIA[_a, _k, _b] = _INERTIA[_b, _k, _a] = 1.0


# Small vectors and matrices with the samples as the last axis, B (1 for one sample): products
# as broadcast sums, not dots (XLA:CPU fuses these, and compiles many small dots slowly).
def _mv(A, x):
    """``A @ x`` over leading axes: (..., r, c, B), (..., c, B) -> (..., r, B)."""
    return jnp.sum(A * x[..., None, :, :], axis=-2)


def _mm(A, B):
    """``A @ B`` over leading axes: (..., r, k, B), (..., k, c, B) -> (..., r, c, B)."""
    return jnp.sum(A[..., :, :, None, :] * B[..., None, :, :, :], axis=-3)


def _hat(a):
    """(..., 3, B) -> (..., 3, 3, B) with ``_hat(a) @ b == cross(a, b)``: one product with the
    Levi-Civita symbol (three operations to trace and compile, where slicing and stacking the
    entries took seventeen)."""
    return _mv(_HAT[..., None], a[..., None, :, :])


def _cross(a, b):
    """``cross(a, b)`` of (..., 3, B) vectors."""
    return _mv(_hat(a), b)


def _inertia_times(x):
    """(..., 3, B) -> (..., 3, 6, B): ``I x`` as a linear map of (Ixx, Ixy, Iyy, Ixz, Iyz, Izz)."""
    return _mv(_INERTIA[..., None], x[..., None, :, :])


def _body_regressor(w, v, aw, av):
    """(..., 6, 10, B): the body force ``[n; f]`` (body axes, about the body origin) of a body
    moving at ``(w, v)``, ``(aw, av)`` (spatial) per unit of each inertial parameter (Pinocchio's
    order): ``n = I aw + h x av + w x (I w + h x v) + v x (m v - h x w)``,
    ``f = m av - h x aw + w x (m v - h x w)``."""
    W, V = _hat(w), _hat(v)
    n_h = -_hat(av) - _mm(W, V) + _mm(V, W)
    f_h = _hat(aw) + _mm(W, W)
    n_I = _inertia_times(aw) + _mm(W, _inertia_times(w))
    f_m = (av + _cross(w, v))[..., None, :]
    top = jnp.concatenate([jnp.zeros_like(f_m), n_h, n_I], axis=-2)
    bottom = jnp.concatenate([f_m, f_h, jnp.zeros(f_m.shape[:-2] + (6,) + f_m.shape[-1:], f_m.dtype)], axis=-2)
    return jnp.concatenate([top, bottom], axis=-3)


def _rows(reg, robot, q, qd, qdd):
    """Rows (N n, p) of N samples (N, n) each, sample-major."""
    q, qd, qdd = (jnp.asarray(x) for x in (q, qd, qdd))
    rigid = jnp.moveaxis(_rigid(robot, q.T, qd.T, qdd.T), -1, 0)  # (N, n, 10 n)
    if reg.n_params(robot.nq) > 10 * robot.nq:
        rest = jax.vmap(lambda a, b, c: reg._joint_columns(robot, a, b, c))(q, qd, qdd)
        rigid = jnp.concatenate([rigid, rest], axis=-1)
    return rigid.reshape(-1, rigid.shape[-1])


# At XLA's backend optimisation level 0 this program compiles in 0.1 s instead of 0.3 s (TIAGo's
# 8 joints) and runs 10-30 % slower: the compile is most of an identification's wait up to 1e5
# samples.
_block = jax.jit(_rows, compiler_options={"xla_backend_optimization_level": 0})


def random_samples(robot: Robot, n_samples: int, seed: int = 0, scale: float = np.pi):
    """Random (q, qd, qdd), each (n_samples, n), within the joint limits where they are finite."""
    rng = np.random.default_rng(seed)
    n = robot.nq
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    lo = np.where(np.isfinite(lo), lo, -scale)
    hi = np.where(np.isfinite(hi), hi, scale)
    q = rng.uniform(lo, hi, size=(n_samples, n))
    qd = rng.uniform(-scale, scale, size=(n_samples, n))
    qdd = rng.uniform(-scale, scale, size=(n_samples, n))
    return q, qd, qdd
