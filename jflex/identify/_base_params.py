"""Base (identifiable) parameters found numerically: the numerical rank of the regressor stacked
over random samples (Gautier's numerical method, with the singular values in place of pivoted
QR's diagonal), with the grouping of every standard parameter into the base parameters."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._robot import Robot
from ._regressor import Regressor, random_samples


class BaseParameters(eqx.Module):
    """``psi = theta[independent] + beta @ theta[dependent]``: the base parameters of a regressor.

    Columns of the standard regressor that never vary (``zero``) do not enter the torques at all.

    **Fields:** ``beta`` (r, d) grouping coefficients; static ``independent`` (r indices),
    ``dependent`` (d indices), ``zero`` (indices), ``names`` (all standard parameter names).
    """

    beta: jnp.ndarray
    independent: tuple[int, ...] = eqx.field(static=True)
    dependent: tuple[int, ...] = eqx.field(static=True)
    zero: tuple[int, ...] = eqx.field(static=True)
    names: tuple[str, ...] = eqx.field(static=True)

    @property
    def rank(self) -> int:
        """Number of base parameters."""
        return len(self.independent)

    def project(self, theta):
        """Base parameters (r,) of a standard parameter vector (p,)."""
        theta = jnp.asarray(theta)
        return theta[jnp.array(self.independent)] + self.beta @ theta[jnp.array(self.dependent, dtype=int)]

    def matrix(self):
        """The (r, p) matrix K with ``psi = K theta``."""
        p = len(self.names)
        K = np.zeros((self.rank, p))
        K[np.arange(self.rank), self.independent] = 1.0
        if self.dependent:
            K[:, self.dependent] = np.asarray(self.beta)
        return jnp.asarray(K)

    def columns(self, A):
        """Base regressor ``A[:, independent]`` (rows, r) of a standard one (rows, p)."""
        return jnp.asarray(A)[:, jnp.array(self.independent)]

    def groups(self, tol: float = 1e-9) -> list[dict]:
        """Per base parameter: its name and the standard parameters grouped into it with their
        coefficients (``{"base": name, "terms": {std_name: coeff}}``)."""
        beta = np.asarray(self.beta)
        out = []
        for i, col in enumerate(self.independent):
            terms = {self.names[col]: 1.0}
            for j, dep in enumerate(self.dependent):
                if abs(beta[i, j]) > tol:
                    terms[self.names[dep]] = float(beta[i, j])
            out.append({"base": self.names[col], "terms": terms})
        return out

    def report(self, tol: float = 1e-9) -> str:
        """Human-readable list: ``psi_k = a*x + b*y + ...``, then the unidentifiable parameters."""
        lines = [f"{self.rank} base parameters out of {len(self.names)} standard parameters"]
        for k, g in enumerate(self.groups(tol)):
            expr = " + ".join(f"{c:.6g}*{n}" if c != 1.0 else n for n, c in g["terms"].items())
            lines.append(f"psi_{k + 1:<3d} = {expr}")
        if self.zero:
            lines.append("no effect on the torques: " + ", ".join(self.names[i] for i in self.zero))
        return "\n".join(lines)


_PREFER = ("Izz", "Ixx", "Ixy", "Ixz", "Iyz", "mcx", "mcy", "Iyy", "mcz", "m")


def _preference(name: str, index: int):
    tag = name.rsplit(".", 1)[-1]
    return (0, index // 10, _PREFER.index(tag)) if tag in _PREFER else (1, index, 0)


def base_parameters(
    robot: Robot,
    regressor: Regressor = Regressor(viscous=False, coulomb=False),
    *,
    n_samples: int = 100,
    seed: int = 0,
    rtol: float = 1e-8,
    samples=None,
) -> BaseParameters:
    """Find the base parameters of ``robot`` numerically.

    Stacks the regressor over random samples (or the given ``samples = (q, qd, qdd)``) and takes
    its numerical rank: the singular values above ``rtol`` times the largest (a structural
    dependency leaves a singular value at round-off, far below any ``rtol`` worth using); then
    picks that many independent columns in a preferred order and solves for the grouping
    coefficients ``A_dep = A_ind beta``.

    **Returns:** :class:`BaseParameters`.
    """
    names = regressor.names(robot)
    if samples is None:
        samples = random_samples(robot, n_samples, seed)
    A = np.asarray(regressor.stack(robot, *samples))
    colnorm = np.linalg.norm(A, axis=0)
    scale_ref = max(colnorm.max(), 1.0)
    zero = tuple(int(i) for i in np.flatnonzero(colnorm <= rtol * scale_ref))
    nz = np.flatnonzero(colnorm > rtol * scale_ref)
    # NumPy's SVD, not SciPy's pivoted QR: importing scipy.linalg costs a fresh process 0.3 s,
    # a tenth of a whole identification, and the rank is all that is taken from it
    d = np.linalg.svd(A[:, nz], compute_uv=False)
    r = int(np.sum(d > rtol * d[0]))
    # Which columns stand for each group is a choice. Keep, in a preferred order, every column
    # that adds to the span, so the groups read like Khalil's (m, mcz, Iyy of a revolute link
    # fold into its parent's parameters; Table A.1).
    order = sorted(nz, key=lambda i: _preference(names[i], i))
    Q = np.zeros((A.shape[0], 0))
    independent = []
    for i in order:
        v = A[:, i] - Q @ (Q.T @ A[:, i])
        if np.linalg.norm(v) > 10 * rtol * max(colnorm[i], 1e-300) * np.sqrt(len(independent) + 1) and len(independent) < r:
            Q = np.column_stack([Q, v / np.linalg.norm(v)])
            independent.append(int(i))
    independent = tuple(sorted(independent))
    dependent = tuple(int(i) for i in nz if i not in independent)
    if dependent:
        beta, *_ = np.linalg.lstsq(A[:, independent], A[:, dependent], rcond=None)
        beta[np.abs(beta) < 1e-10 * max(1.0, np.abs(beta).max())] = 0.0
    else:
        beta = np.zeros((len(independent), 0))
    return BaseParameters(jnp.asarray(beta), independent, dependent, zero, names)
