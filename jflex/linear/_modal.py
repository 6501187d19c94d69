"""Modal analysis at a posture: the first-order generalised eigenproblem of the thesis "Posture Dependent Dynamics in Robotic Machining"
Eqs. 4.10-4.13 (state-space form of ``M0 x'' + C0 x' + K0 x = 0``).

For ``(lambda^2 M + lambda C + K) psi = 0`` the state vectors are ``[psi; lambda psi]``; the
eigenvalues come in conjugate pairs ``lambda_r = -zeta_r w_r +- i w_r sqrt(1 - zeta_r^2)`` and

$$ f_r = |\\lambda_r| / 2\\pi, \\qquad \\zeta_r = -\\mathrm{Re}\\,\\lambda_r / |\\lambda_r| $$

(Eq. 4.12). Each mode also carries ``a_r = psi_r^T (2 lambda_r M + C) psi_r``, the
normalisation of the modal expansion ``H(s) = sum_r psi_r psi_r^T / (a_r (s - lambda_r))`` over
all 2n eigenpairs (the expansion for non-proportional damping of the course notes "Manipulator
modeling accounting for flexibilities"), and a modal mass
``mu_r = a_r / (2 i w_d,r)``, which is ``psi_r^T M psi_r`` for proportional damping.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._errors import ShapeError
from .._compiled import QUICK_COMPILE, compiled
from .._model import Model, resolve_hold
from ._common import check_inertia, linearization, mass_ok, require_mass, tool_jacobian
from ._qep import qep_newton

SOLVERS = ("eig", "newton")


def check_solver(solver):
    if solver not in SOLVERS:
        raise ShapeError(f"solver must be one of {SOLVERS}, got {solver!r}")


class Eigen(eqx.Module):
    """All 2n eigenpairs of a quadratic eigenproblem (unordered pairs; for the modal expansion)."""

    eigenvalue: jnp.ndarray  # (2n,) complex [rad/s]
    shape: jnp.ndarray  # (n, 2n) complex, displacement part
    a: jnp.ndarray  # (2n,) complex: psi^T (2 lambda M + C) psi


class Modes(eqx.Module):
    """Modal parameters at one posture, modes sorted by natural frequency.

    - ``frequency`` (m,) natural frequencies f_r = |lambda_r| / 2 pi [Hz].
    - ``damping_ratio`` (m,) zeta_r [-].
    - ``eigenvalue`` (m,) lambda_r with Im >= 0 [rad/s].
    - ``shape`` (nk, m) complex mode shapes over the kept coordinates ``names``, scaled so that
      the largest-magnitude entry of each is 1.
    - ``modal_mass`` (m,) complex mu_r = a_r / (2 i w_d) for that scaling [kg m^2 or kg].
    - ``a`` (m,) complex a_r = psi^T (2 lambda M + C) psi.
    - ``tool_shape`` (3 or 6, m) complex: J psi_r at the requested frame, or None.
    - ``names``: static, the coordinates of ``shape``'s rows.
    """

    frequency: jnp.ndarray
    damping_ratio: jnp.ndarray
    eigenvalue: jnp.ndarray
    shape: jnp.ndarray
    modal_mass: jnp.ndarray
    a: jnp.ndarray
    tool_shape: jnp.ndarray | None
    names: tuple[str, ...] = eqx.field(static=True, default=())

    def reorder(self, perm):
        """The same modes in the order ``perm`` (m,) (e.g. from :func:`jflex.linear.track_modes`)."""
        take = lambda a: None if a is None else jnp.take(a, perm, axis=-1)
        return Modes(
            take(self.frequency), take(self.damping_ratio), take(self.eigenvalue), take(self.shape),
            take(self.modal_mass), take(self.a), take(self.tool_shape), self.names,
        )


def eigen(M, C, K, *, solver: str = "eig") -> Eigen:
    """All 2n eigenpairs of ``(lambda^2 M + lambda C + K) psi = 0``.

    **Arguments:** ``M`` (n, n) positive definite, ``C``, ``K`` (n, n); ``solver``: ``"eig"``
    (the state matrix through ``jnp.linalg.eig``: any damping) or ``"newton"`` (Newton's method
    from the undamped modes, :func:`jflex.linear.qep_newton`: underdamped modes only, several
    times faster over posture batches; the conjugate halves are the complex conjugates).

    **Returns:** :class:`Eigen`.
    """
    check_solver(solver)
    M, C, K = (jnp.asarray(A, dtype=float) for A in (M, C, K))
    n = M.shape[0]
    if solver == "newton":
        lam, psi = qep_newton(M, C, K)
        lam, psi = jnp.concatenate([lam, lam.conj()]), jnp.concatenate([psi, psi.conj()], axis=1)
    else:
        MiK = jnp.linalg.solve(M, K)
        MiC = jnp.linalg.solve(M, C)
        A = jnp.block([[jnp.zeros((n, n)), jnp.eye(n)], [-MiK, -MiC]])
        # eigenvector derivatives are gauge-dependent in general; every consumer here (modal
        # expansion, normalised shapes) is invariant to each eigenvector's scale, so they are valid
        lam, V = jax.lax.linalg.eig(A, compute_left_eigenvectors=False, enable_eigvec_derivs=True)
        psi = V[:n]
    return Eigen(lam, psi, modal_a(lam, psi, M, C))


def modal_a(lam, psi, M, C):
    """``a_r = psi_r^T (2 lambda_r M + C) psi_r`` of each eigenpair (columns of ``psi``)."""
    return 2 * lam * jnp.einsum("ir,ij,jr->r", psi, M, psi) + jnp.einsum("ir,ij,jr->r", psi, C, psi)


def _normalise(psi):
    # scale each mode so its largest-magnitude entry is exactly 1 (phase and size fixed)
    k = jnp.argmax(jnp.abs(psi), axis=0)
    pivot = jnp.take_along_axis(psi, k[None, :], axis=0)
    pivot = jnp.where(jnp.abs(pivot) > 0, pivot, 1.0)
    return psi / pivot, pivot[0]


def modes(M, C, K, *, names: tuple[str, ...] = (), solver: str = "eig") -> Modes:
    """Natural frequencies, damping ratios, mode shapes and modal masses of ``M x'' + C x' + K x = 0``.

    **Arguments:** ``M`` (n, n) positive definite [kg, kg m^2], ``C`` (n, n), ``K`` (n, n).

    **Returns:** :class:`Modes` with n modes sorted by natural frequency. Of each conjugate
    pair the eigenvalue with Im >= 0 is kept; an overdamped mode shows up as a real eigenvalue
    with zeta = 1, a rigid-body mode as f = 0, zeta = 0 (``solver="eig"``; ``"newton"`` is for
    underdamped modes and raises otherwise, see :func:`eigen`).
    """
    e = eigen(M, C, K, solver=solver)
    n = e.shape.shape[0]
    # conjugate pairs: the n eigenvalues with the largest imaginary parts are the Im >= 0 halves
    top = jnp.argsort(-e.eigenvalue.imag)[:n] if solver == "eig" else jnp.arange(n)
    lam = e.eigenvalue[top]
    order = jnp.argsort(jnp.abs(lam))
    top = top[order]
    lam, psi, a = e.eigenvalue[top], e.shape[:, top], e.a[top]
    psi, pivot = _normalise(psi)
    a = a / pivot**2
    w = jnp.abs(lam)
    safe = jnp.where(w > 0, w, 1.0)
    zeta = jnp.where(w > 0, -lam.real / safe, 0.0)
    wd = lam.imag
    mu = jnp.where(jnp.abs(wd) > 0, a / (2j * jnp.where(jnp.abs(wd) > 0, wd, 1.0)), jnp.nan)
    return Modes(w / (2 * jnp.pi), zeta, lam, psi, mu, a, None, tuple(names))


def modal_analysis(
    model: Model,
    posture,
    *,
    hold=(),
    frame=None,
    reference: str = "local_world_aligned",
    components: str = "linear",
    solver: str = "eig",
) -> Modes:
    """Modal analysis of ``model`` linearised at a posture.

    **Arguments:**

    - ``model``: a :class:`jflex.Model` (rigid robot + effects, e.g. flexible joints).
    - ``posture``: (n,) robot joint angles q0 [rad] (effect coordinates completed at rest, e.g.
      theta = q) or (nx,) all coordinates x0.
    - ``hold``: coordinates clamped at the posture: ``"actuated"`` (perfect position control of
      every actuated coordinate: the motor side of flexible joints),
      names or glob patterns such as ``"theta_*"``, or ``()`` (free, the default).
    - ``frame``: optional frame (e.g. ``"tool"``) at which to express the mode shapes through
      its Jacobian; ``reference`` and ``components`` (``"linear"``, ``"angular"``, ``"full"``)
      as in :func:`jflex.jacobian`; or an effect output naming a point (``"beam.tip_position"``),
      which moves with the beam's modes too.
    - ``solver``: ``"eig"`` (any damping) or ``"newton"`` (underdamped modes, several times
      faster in posture sweeps; raises where it does not converge), see :func:`eigen`.

    **Returns:** :class:`Modes`; frequencies in Hz, damping ratios, complex shapes over the
    kept coordinates and (if ``frame``) at the frame. Jit- and vmap-compatible over postures;
    an un-jitted call runs one compiled program per model structure and options. A model with
    a free coordinate that moves no inertia (a singular mass matrix) raises
    :class:`jflex.ParameterError` (through ``eqx.error_if`` when traced).
    """
    check_solver(solver)
    check_inertia("modal_analysis", model)
    held = resolve_hold(model, hold)
    out, ok = _modal_program(model, jnp.asarray(posture, dtype=float), held, frame, reference, components, solver)
    return eqx.tree_at(lambda m: m.frequency, out, require_mass("modal_analysis", ok, out.frequency))


def _modal_impl(model, posture, held, frame, reference, components, solver):
    x0, lin = linearization(model, posture, held)
    out = modes(lin.M, lin.C, lin.K, names=lin.names, solver=solver)
    if frame is not None:
        J = tool_jacobian(model, x0, lin.keep, frame, reference, components)
        out = eqx.tree_at(lambda m: m.tool_shape, out, J @ out.shape, is_leaf=lambda x: x is None)
    return out, mass_ok(lin.M)


# one compiled program per model structure and options: the model's numbers and the posture are
# its arguments, so un-jitted calls at other postures (or on another model of the same
# structure) do not trace again
_modal_program = compiled(_modal_impl, compiler_options=QUICK_COMPILE)
