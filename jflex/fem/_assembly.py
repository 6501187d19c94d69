"""Assembly of planar finite-element models by connectivity (press paper, Eqs. 13-22), damping and modes.

A node carries three DOF slots ``(ux, uy, th)``; ``node_dofs`` maps each slot to a global DOF
index, or to -1 where the slot is held fixed. Two nodes of different links at one pin share
their translation indices (a perfect revolute joint) or keep their own and are joined by bar
elements (a joint with stiffness). This index map is the paper's Boolean matrix ``B_i``
(Eqs. 13-14) stored as integers; ``B_i^T k B_i`` becomes a scatter-add.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._errors import ParameterError, ShapeError
from ._elements import bar_matrices, beam_matrices


def _positive(name: str, value, allow_zero: bool = False) -> None:
    v = np.asarray(value, dtype=float)
    bad = (v < 0) if allow_zero else (v <= 0)
    if not np.all(np.isfinite(v)) or np.any(bad):
        want = "non-negative" if allow_zero else "positive"
        raise ParameterError(f"{name}: every value must be finite and {want}, got {v.tolist()}")


class FEModel(eqx.Module):
    """A planar frame of beam elements, bar elements and lumped masses with static connectivity.

    Build it with :func:`fe_model`; assemble with :meth:`matrices`.
    """

    n_dof: int = eqx.field(static=True)
    node_dofs: tuple[tuple[int, int, int], ...] = eqx.field(static=True)
    beam_nodes: tuple[tuple[int, int], ...] = eqx.field(static=True)
    bar_nodes: tuple[tuple[int, int], ...] = eqx.field(static=True)
    mass_nodes: tuple[int, ...] = eqx.field(static=True)
    beam_E: Float[Array, " nb"]
    beam_A: Float[Array, " nb"]
    beam_I: Float[Array, " nb"]
    beam_rho: Float[Array, " nb"]
    bar_E: Float[Array, " nr"]
    bar_A: Float[Array, " nr"]
    bar_L: Float[Array, " nr"]
    bar_rho: Float[Array, " nr"]
    lumped_m: Float[Array, " nm"]
    lumped_J: Float[Array, " nm"]

    @property
    def n_nodes(self) -> int:
        return len(self.node_dofs)

    def matrices(
        self,
        X: Float[ArrayLike, "nn 2"],
        bar_angles: Float[ArrayLike, " nr"] | None = None,
        bar_E: Float[ArrayLike, " nr"] | None = None,
    ) -> tuple[Float[Array, "n n"], Float[Array, "n n"]]:
        """Assembled mass and stiffness ``(M, K)`` of the free DOFs (Eqs. 21-22).

        **Arguments:**

        - `X`: node positions, shape (n_nodes, 2), m.
        - `bar_angles`: axis direction of each bar, rad, shape (n_bars,); default: from node i to j.
        - `bar_E`: modulus of each bar, Pa; default: the model's ``bar_E`` (pass it for bimodular joints).

        **Returns:** ``(M, K)``, each (n_dof, n_dof).
        """
        X = jnp.asarray(X, float)
        if X.shape != (self.n_nodes, 2):
            raise ShapeError(f"X: expected node positions of shape ({self.n_nodes}, 2), got {X.shape}")
        return _assemble(self, X, bar_angles, bar_E)

    def _assemble(self, X, bar_angles, bar_E):
        n = self.n_dof
        dofs = np.asarray(self.node_dofs, dtype=int).reshape(-1, 3)
        dofs = np.where(dofs < 0, n, dofs)  # fixed slots go to a dump row/column that is sliced off
        K = jnp.zeros((n + 1, n + 1))
        M = jnp.zeros((n + 1, n + 1))
        if self.beam_nodes:
            bi = np.asarray(self.beam_nodes, dtype=int)
            kb, mb = jax.vmap(beam_matrices)(self.beam_E, self.beam_A, self.beam_I, self.beam_rho, X[bi[:, 0]], X[bi[:, 1]])
            idx = np.concatenate([dofs[bi[:, 0]], dofs[bi[:, 1]]], axis=1)
            K = K.at[idx[:, :, None], idx[:, None, :]].add(kb)
            M = M.at[idx[:, :, None], idx[:, None, :]].add(mb)
        if self.bar_nodes:
            ri = np.asarray(self.bar_nodes, dtype=int)
            if bar_angles is None:
                d = X[ri[:, 1]] - X[ri[:, 0]]
                bar_angles = jnp.arctan2(d[:, 1], d[:, 0])
            E = self.bar_E if bar_E is None else jnp.asarray(bar_E)
            kr, mr = jax.vmap(bar_matrices)(E, self.bar_A, self.bar_L, self.bar_rho, jnp.asarray(bar_angles))
            idx = np.concatenate([dofs[ri[:, 0], :2], dofs[ri[:, 1], :2]], axis=1)
            K = K.at[idx[:, :, None], idx[:, None, :]].add(kr)
            M = M.at[idx[:, :, None], idx[:, None, :]].add(mr)
        if self.mass_nodes:
            mi = dofs[np.asarray(self.mass_nodes, dtype=int)]
            M = M.at[mi[:, 0], mi[:, 0]].add(self.lumped_m)
            M = M.at[mi[:, 1], mi[:, 1]].add(self.lumped_m)
            M = M.at[mi[:, 2], mi[:, 2]].add(self.lumped_J)
        return M[:n, :n], K[:n, :n]

    def gather(self, nodal: Float[ArrayLike, "nn 3"]) -> Float[Array, " n"]:
        """Global DOF vector from per-node values ``(ux, uy, th)`` (e.g. rigid-body accelerations).

        Nodes that share a DOF must carry equal values there; fixed slots are dropped.
        """
        nodal = jnp.asarray(nodal)
        dofs = np.asarray(self.node_dofs, dtype=int).reshape(-1)
        keep = dofs >= 0
        return jnp.zeros(self.n_dof).at[dofs[keep]].set(nodal.reshape(-1)[keep])

    def scatter(self, U: Float[ArrayLike, "... n"]) -> Float[Array, "... nn 3"]:
        """Per-node values ``(ux, uy, th)`` of a global DOF vector (fixed slots read 0)."""
        U = jnp.asarray(U)
        dofs = np.asarray(self.node_dofs, dtype=int)
        Up = jnp.concatenate([U, jnp.zeros(U.shape[:-1] + (1,))], axis=-1)
        return Up[..., np.where(dofs < 0, self.n_dof, dofs)]


_assemble = eqx.filter_jit(FEModel._assemble)


def fe_model(
    node_dofs,
    beams=(),
    bars=(),
    masses=(),
) -> FEModel:
    """Build an :class:`FEModel`, checking connectivity and parameters before any tracing.

    **Arguments:**

    - `node_dofs`: per node, three global DOF indices ``(ux, uy, th)`` (-1 = fixed). Indices
      must be exactly ``0 .. n_dof-1``; sharing an index couples two nodes.
    - `beams`: ``(i, j, E, A, I, rho)`` per beam element (SI units).
    - `bars`: ``(i, j, E, A, L, rho)`` per bar element.
    - `masses`: ``(node, m, J)`` per lumped mass (kg, kg m^2).

    **Returns:** the model.
    """
    node_dofs = tuple(tuple(int(d) for d in nd) for nd in node_dofs)
    if any(len(nd) != 3 for nd in node_dofs):
        raise ShapeError("node_dofs: every node needs three DOF indices (ux, uy, th)")
    used = sorted({d for nd in node_dofs for d in nd if d >= 0})
    if used != list(range(len(used))):
        raise ShapeError("node_dofs: free DOF indices must be exactly 0..n_dof-1 without gaps")
    nn = len(node_dofs)

    def nodes_ok(name, pairs):
        for k, (i, j) in enumerate(pairs):
            if not (0 <= i < nn and 0 <= j < nn) or i == j:
                raise ShapeError(f"{name}[{k}]: nodes ({i}, {j}) must be two different nodes in 0..{nn - 1}")

    beams = [tuple(b) for b in beams]
    bars = [tuple(b) for b in bars]
    masses = [tuple(m) for m in masses]
    nodes_ok("beams", [(int(b[0]), int(b[1])) for b in beams])
    nodes_ok("bars", [(int(b[0]), int(b[1])) for b in bars])
    col = lambda rows, k: jnp.asarray(np.asarray([r[k] for r in rows], dtype=float).reshape(-1))
    for k, name in ((2, "beam E"), (3, "beam A"), (4, "beam I")):
        _positive(name, [b[k] for b in beams])
    _positive("beam rho", [b[5] for b in beams], allow_zero=True)
    for k, name in ((2, "bar E"), (3, "bar A"), (4, "bar L")):
        _positive(name, [b[k] for b in bars])
    _positive("bar rho", [b[5] for b in bars], allow_zero=True)
    _positive("lumped mass", [m[1] for m in masses], allow_zero=True)
    _positive("lumped inertia", [m[2] for m in masses], allow_zero=True)
    for k, m in enumerate(masses):
        if not 0 <= int(m[0]) < nn:
            raise ShapeError(f"masses[{k}]: node {m[0]} not in 0..{nn - 1}")
    return FEModel(
        n_dof=len(used),
        node_dofs=node_dofs,
        beam_nodes=tuple((int(b[0]), int(b[1])) for b in beams),
        bar_nodes=tuple((int(b[0]), int(b[1])) for b in bars),
        mass_nodes=tuple(int(m[0]) for m in masses),
        beam_E=col(beams, 2), beam_A=col(beams, 3), beam_I=col(beams, 4), beam_rho=col(beams, 5),
        bar_E=col(bars, 2), bar_A=col(bars, 3), bar_L=col(bars, 4), bar_rho=col(bars, 5),
        lumped_m=col(masses, 1), lumped_J=col(masses, 2),
    )


class Modes(eqx.Module):
    """Mass-normalised modes of ``K phi = w^2 M phi`` (press paper, Eqs. 24-28): ``Phi^T M Phi = I``."""

    omega: Float[Array, " r"]
    """Natural angular frequencies, rad/s, ascending."""
    Phi: Float[Array, "n r"]
    """Mode shapes as columns, mass-normalised."""


@eqx.filter_jit
def modes(M: Float[ArrayLike, "n n"], K: Float[ArrayLike, "n n"], n_modes: int | None = None) -> Modes:
    """Generalized symmetric eigenproblem by Cholesky reduction (differentiable, jit-able).

    **Arguments:**

    - `M`: mass matrix, symmetric positive definite, (n, n).
    - `K`: stiffness matrix, symmetric positive semi-definite, (n, n).
    - `n_modes`: keep this many lowest modes (static); default all.

    **Returns:** :class:`Modes`.
    """
    M = jnp.asarray(M)
    K = jnp.asarray(K)
    Lc = jnp.linalg.cholesky(0.5 * (M + M.T))
    Li = jax.scipy.linalg.solve_triangular(Lc, jnp.eye(M.shape[0]), lower=True)
    A = Li @ K @ Li.T
    lam, V = jnp.linalg.eigh(0.5 * (A + A.T))
    Phi = Li.T @ V
    lam = eqx.error_if(lam, jnp.any(jnp.isnan(lam)), "modes: NaN eigenvalues (is M positive definite?)")
    omega = jnp.sqrt(jnp.clip(lam, 0.0, None))
    if n_modes is not None:
        omega, Phi = omega[:n_modes], Phi[:, :n_modes]
    return Modes(omega=omega, Phi=Phi)


def rayleigh_damping(M: ArrayLike, K: ArrayLike, alpha: ArrayLike, beta: ArrayLike) -> Array:
    """Rayleigh damping ``C = alpha M + beta K`` (press paper, Eq. 33).

    **Arguments:** `M`, `K` (n, n); `alpha` in 1/s, `beta` in s.

    **Returns:** ``C``, (n, n), N s/m.
    """
    return alpha * jnp.asarray(M) + beta * jnp.asarray(K)


def rayleigh_coefficients(omega1: ArrayLike, omega2: ArrayLike, zeta1: ArrayLike, zeta2: ArrayLike) -> tuple[Array, Array]:
    """``(alpha, beta)`` such that ``zeta(w) = alpha/(2w) + beta w/2`` hits ``zeta1`` at ``omega1`` and ``zeta2`` at ``omega2``.

    **Arguments:** angular frequencies in rad/s, damping ratios dimensionless.

    **Returns:** ``(alpha, beta)`` in 1/s and s.
    """
    w1, w2 = jnp.asarray(omega1), jnp.asarray(omega2)
    A = jnp.array([[1 / (2 * w1), w1 / 2], [1 / (2 * w2), w2 / 2]])
    ab = jnp.linalg.solve(A, jnp.stack([jnp.asarray(zeta1), jnp.asarray(zeta2)]))
    return ab[0], ab[1]


def modal_damping(M: ArrayLike, K: ArrayLike, zeta: ArrayLike) -> Array:
    """Damping matrix with ratio ``zeta`` in every mode: ``C = M Phi diag(2 zeta w) Phi^T M`` (Eq. 35).

    **Arguments:** `M`, `K` (n, n); `zeta` scalar or (n,) per mode (ascending frequency).

    **Returns:** ``C``, (n, n).
    """
    md = modes(M, K)
    MP = jnp.asarray(M) @ md.Phi
    return MP @ jnp.diag(2.0 * jnp.broadcast_to(zeta, md.omega.shape) * md.omega) @ MP.T
