"""The tool payload of a frequency model: a rigid body through the log-Cholesky factor of its
pseudo-inertia, every parameter value a physical body."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ...identify._physical import log_cholesky_pseudo_inertia, pseudo_inertia_to_params

PAYLOAD_NAMES = ("log m", "c_x", "c_y", "c_z", "log r_1", "log r_2", "log r_3", "s_12", "s_23", "s_13")
PAYLOAD_COM_BOX = 0.25  # [m] the payload's centre of mass stays this close to the tool frame's origin (per axis)
def _payload_pseudo_params(th, T):
    # the payload's parameters (1, 4 or 10 of PAYLOAD_NAMES) as identify's log-Cholesky vector
    # (alpha = log m / 2, t = c; a point mass has a zero rotational factor: its log r at -inf)
    P = th.shape[0]
    z = jnp.zeros(())
    c = th[1:4] if P >= 4 else jnp.zeros(3)
    d, s = (th[4:7], th[7:10]) if P == 10 else (jnp.full(3, -jnp.inf), jnp.zeros(3))
    theta = jnp.concatenate([jnp.stack([0.5 * th[0] + z]), d, s, c])
    return pseudo_inertia_to_params(T @ log_cholesky_pseudo_inertia(theta) @ T.T)


_payload_pi = jax.jit(_payload_pseudo_params)
_payload_pi_jac = jax.jit(lambda th, T: (_payload_pseudo_params(th, T), jax.jacfwd(_payload_pseudo_params)(th, T)))


def payload_inertia(theta, T=None, jac: bool = False):
    """The payload's 10 inertial parameters about the body frame of its link, from its parameters
    ``theta`` (1, 4 or 10 of :data:`PAYLOAD_NAMES`, in the tool frame ``T`` (4, 4): the tool frame's
    pose in the link's frame); with ``jac``, also their derivatives (len(theta), 10).

    The log-Cholesky parametrisation of the pseudo-inertia (:func:`jflex.identify.log_cholesky_pseudo_inertia`,
    its ``alpha`` = ``log m / 2``, ``d_i`` = ``log r_i``, ``s_ij``, ``t`` = ``c``): ``m = e^{log m}``,
    ``c`` the centre of mass [m] in tool axes, every value a physical body (positive mass, triangle
    inequalities). Fewer parameters fix the rest: 1, a point mass at the tool frame's origin; 4, a
    point mass at ``c``. In the link's frame the pseudo-inertia is ``T J T^T``."""
    th = np.clip(np.asarray(theta, float), -60.0, 60.0)
    T = np.eye(4) if T is None else np.asarray(T, float)
    # a fit asks for the same parameters at every posture of a residual and again for its Jacobian
    out = _payload_memo(th.tobytes(), th.size, T.tobytes(), jac)
    return (out[0].copy(), out[1].copy()) if jac else out.copy()


@functools.lru_cache(maxsize=16)
def _payload_memo(th_b, n, T_b, jac):
    th = np.frombuffer(th_b, float, n)
    T = np.frombuffer(T_b, float, 16).reshape(4, 4)
    if not jac:
        return np.asarray(_payload_compiled(n, False)(th, T))
    pi, d = _payload_compiled(n, True)(th, T)
    return np.asarray(pi), np.asarray(d).T


@functools.lru_cache(maxsize=None)
def _payload_compiled(n, jac):
    # compiled ahead of time: a call costs a fraction of jit's dispatch (thousands per fit)
    f = _payload_pi_jac if jac else _payload_pi
    return f.lower(jax.ShapeDtypeStruct((n,), jnp.float64), jax.ShapeDtypeStruct((4, 4), jnp.float64)).compile()


def payload_start(n: int, m: float, com=(0.0, 0.0, 0.0), r: float = 0.02) -> np.ndarray:
    """Payload parameters (``n`` of :data:`PAYLOAD_NAMES`): mass ``m`` [kg] at ``com`` [m] (tool
    axes), its inertia about it that of a solid sphere of radius ``r sqrt(5/2)`` [m]."""
    full = np.r_[np.log(m), com, np.log([r, r, r]), 0.0, 0.0, 0.0]
    return full[:n]
