"""Frequency response functions at a posture (the thesis "Posture Dependent Dynamics in Robotic Machining" Eqs. 4.7-4.9, the course notes "Manipulator modeling accounting for flexibilities" "forced response").

Joint space: ``G_theta(w) = (K0 - w^2 M0 + i w C0)^-1`` (direct form) or its modal expansion
``sum_r psi_r psi_r^T / (a_r (i w - lambda_r))`` over the 2n eigenpairs. At a frame:
``G_X = J G_theta J^T``. Receptance [m/N], mobility (x i w) or accelerance (x -w^2).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from .._errors import ParameterError, ShapeError
from .._model import Model
from ._common import check_frequencies, expand_posture, linearization, resolve_hold, tool_jacobian
from ._modal import Eigen, check_solver, eigen, modal_a
from ._qep import qep_newton

_KINDS = ("receptance", "mobility", "accelerance")
_METHODS = ("direct", "modal")


def _inv_small(D):
    """Inverse of a small (n, n) matrix. n <= 3: the adjugate, which XLA vectorises across a batch
    (LAPACK's per-matrix calls dominate otherwise); larger n: LU."""
    n = D.shape[-1]
    if n == 1:
        return 1.0 / D
    if n == 2:
        a, b, c, d = D[0, 0], D[0, 1], D[1, 0], D[1, 1]
        det = a * d - b * c
        return jnp.stack([jnp.stack([d, -b]), jnp.stack([-c, a])]) / det
    if n == 3:
        c0, c1, c2 = D[:, 0], D[:, 1], D[:, 2]
        # rows of the inverse are cross products of the columns, over the determinant
        r0, r1, r2 = jnp.cross(c1, c2), jnp.cross(c2, c0), jnp.cross(c0, c1)
        det = jnp.dot(c0, r0)
        return jnp.stack([r0, r1, r2]) / det
    return jnp.linalg.inv(D)


def _dstiff(M, C, K, w, E):
    """Dynamic stiffness ``K - w^2 M + i w C`` plus the extra terms ``E`` at one frequency."""
    D = K - w**2 * M + 1j * w * C
    for e in E:
        D = D + e
    return D


def _inverses(M, C, K, omega, E):
    """``G(w) = D(w)^-1`` over the grid (nf, n, n)."""
    return jax.vmap(lambda w, *e: _inv_small(_dstiff(M, C, K, w, e)))(omega, *E)


@jax.custom_jvp
def _direct(M, C, K, omega, T, E):
    """Direct-form FRF over the grid: ``T G(w) T^T`` (``T`` None: ``G(w)``), ``G = D^-1``,
    ``D = K - w^2 M + i w C + sum(E)`` with ``E`` a tuple of (nf, n, n) extra dynamic stiffnesses
    (frequency-dependent effect terms). Its derivatives come from :func:`_direct_jvp`."""
    G = _inverses(M, C, K, omega, E)
    return G if T is None else jax.vmap(lambda g: T @ g @ T.T)(G)


def _direct_jvp(primals, tangents):
    """Tangent of :func:`_direct`: ``dH = dT X + Y dT^T - Y dD X`` with ``X = G T^T`` (n, p),
    ``Y = T G`` (p, n) (``X = Y = G`` without T) and
    ``dD = dK - w^2 dM + i w dC + sum(dE) + (i C - 2 w M) dw``.

    Differentiating through the inverse instead re-runs its triangular solves with an (n, n)
    right-hand side for every tangent and frequency (an 18-parameter ``jax.jacfwd`` of a UR5's
    6x6 tool FRF cost 25-30x the FRF). Here the inverse is computed once; each
    frequency-independent tangent dK, dM, dC multiplies X at all frequencies in ONE real (n, n) @
    (n, nf 2p) product (under ``jax.jacfwd`` the tangents stack into its rows: one GEMM for all
    of them), and ``Y (dD X)`` is one real (2p, n) @ (n, 2p) product per frequency. Complex
    products are split into real ones (XLA:CPU's small complex matrix products run several times
    slower than the real ones they stand for). Symbolic-zero tangents (e.g. ``dT`` when the
    kinematics are not being differentiated, ``dw``, ``dE``) cost nothing."""
    M, C, K, omega, T, E = primals
    dM, dC, dK, dw, dT, dE = tangents
    live = lambda t: not isinstance(t, SymbolicZero)
    G = _inverses(M, C, K, omega, E)
    if T is None:
        H = X = Y = G
    else:
        Y = jax.vmap(lambda g: T @ g)(G)
        H = jax.vmap(lambda y: y @ T.T)(Y)
        X = jnp.einsum("fij,aj->fia", G, T)
    nf, n, p = X.shape
    Xr, Xi = X.real, X.imag
    w = omega[:, None, None]
    Ys = jnp.concatenate([Y.real, Y.imag], axis=1)  # (nf, 2p, n)
    P = None  # Y dD X as [[Yr Zr, Yr Zi], [Yi Zr, Yi Zi]] with Z = dD X, (nf, 2p, 2p)
    # the frequency-independent parts in ONE real product: [dK dM dC] @ [X; -w^2 X; i w X]
    A, V = [], []
    if live(dK):
        A.append(dK), V.append((Xr, Xi))
    if live(dM):
        A.append(dM), V.append((-(w**2) * Xr, -(w**2) * Xi))
    if live(dC):
        A.append(dC), V.append((-w * Xi, w * Xr))
    if A:
        Vs = jnp.concatenate([jnp.moveaxis(jnp.concatenate(v, axis=2), 1, 0) for v in V], axis=0)  # (k n, nf, 2p)
        Z = (jnp.concatenate(A, axis=1) @ Vs.reshape(len(A) * n, nf * 2 * p)).reshape(n, nf, 2 * p)
        P = jnp.einsum("fai,ifb->fab", Ys, Z)
    dDc = [de for de in dE if live(de)]  # complex, frequency-dependent parts of dD
    if live(dw):
        dDc.append(dw[:, None, None] * (1j * C - 2 * w * M))
    if dDc:
        B = sum(dDc[1:], dDc[0])
        mm = lambda a, x: jnp.einsum("fij,fjb->fib", a, x)
        Z = jnp.concatenate([mm(B.real, Xr) - mm(B.imag, Xi), mm(B.real, Xi) + mm(B.imag, Xr)], axis=2)
        Pc = jnp.einsum("fai,fib->fab", Ys, Z)
        P = Pc if P is None else P + Pc
    dH = jnp.zeros_like(H)
    if P is not None:  # -Y Z, Y = Yr + i Yi
        dH = dH + jax.lax.complex(P[:, p:, p:] - P[:, :p, :p], -(P[:, :p, p:] + P[:, p:, :p]))
    if T is not None and live(dT):
        dH = dH + jnp.einsum("ai,fib->fab", dT, X) + jnp.einsum("fai,bi->fab", Y, dT)
    return H, dH


_direct.defjvp(_direct_jvp, symbolic_zeros=True)


def _kind_factor(omega, kind):
    if kind == "receptance":
        return jnp.ones_like(omega, dtype=complex)
    if kind == "mobility":
        return 1j * omega
    return -(omega**2) + 0j


def _check_kind_method(kind, method):
    if kind not in _KINDS:
        raise ShapeError(f"frf: kind must be one of {_KINDS}, got '{kind}'")
    if method not in _METHODS:
        raise ShapeError(f"frf: method must be one of {_METHODS}, got '{method}'")


def frf_matrices(M, C, K, omega, *, kind: str = "receptance", method: str = "direct", T=None, solver: str = "eig"):
    """FRF of ``M x'' + C x' + K x = f`` on a frequency grid.

    **Arguments:** ``M``, ``C``, ``K`` (n, n); ``omega`` (nf,) [rad/s], increasing, >= 0;
    ``kind`` receptance | mobility | accelerance; ``method`` direct | modal; ``T`` optional
    (p, n) output/input map (e.g. a Jacobian): returns ``T H T^T``; ``solver`` of the modal
    form: ``"eig"`` or ``"newton"`` (underdamped modes; see :func:`jflex.linear.eigen`).

    **Returns:** complex (nf, n, n) (or (nf, p, p)).
    """
    _check_kind_method(kind, method)
    check_solver(solver)
    omega = check_frequencies(omega)
    M, C, K = (jnp.asarray(A, dtype=float) for A in (M, C, K))
    if method == "modal" and solver == "newton":
        return synthesize_frf(pole_residue_matrices(M, C, K, T=T, solver="newton"), omega, kind=kind)
    elif method == "modal":
        H = modal_frf(eigen(M, C, K), omega, T=T)
    else:
        H = _direct(M, C, K, omega, T, ())
    return H * _kind_factor(omega, kind)[:, None, None]


class PoleResidue(eqx.Module):
    """Pole-residue model of an FRF matrix over underdamped modes (what EMA software stores):

    ``H(i w) = sum_r R_r / (i w - lambda_r) + conj(R_r) / (i w - conj(lambda_r))``.

    - ``pole`` (m,) complex lambda_r with Im > 0 [rad/s].
    - ``residue`` (p, p, m) complex R_r = u_r u_r^T / a_r with u_r the shape at the output
      (e.g. ``J psi_r`` at the tool) [m/N/s or rad/(N m s)].

    Built by :func:`pole_residue`; :func:`synthesize_frf` evaluates it on a frequency grid. The
    split lets a posture sweep solve the eigenproblems in large batches and synthesise the
    (large) FRF arrays in cache-sized blocks (:func:`jflex.frf_sweep`).
    """

    pole: jnp.ndarray
    residue: jnp.ndarray


def pole_residue_matrices(M, C, K, *, T=None, solver: str = "newton") -> PoleResidue:
    """:class:`PoleResidue` of ``M x'' + C x' + K x = f`` with output/input map ``T`` (p, n)
    (None: the coordinates themselves). Every mode must be underdamped; ``solver`` as in
    :func:`jflex.linear.eigen` (``"newton"`` raises otherwise; with ``"eig"`` an overdamped or
    rigid-body mode raises here)."""
    check_solver(solver)
    M, C, K = (jnp.asarray(A, dtype=float) for A in (M, C, K))
    n = M.shape[0]
    if solver == "newton":  # the Im > 0 halves only (eigen() would also build their conjugates)
        lam, psi = qep_newton(M, C, K)
        a = modal_a(lam, psi, M, C)
    else:
        e = eigen(M, C, K, solver=solver)
        top = jnp.argsort(-e.eigenvalue.imag)[:n]
        lam, psi, a = e.eigenvalue[top], e.shape[:, top], e.a[top]
        lam = eqx.error_if(
            lam, jnp.any(~(lam.imag > 0)),
            "pole-residue FRF: a mode is overdamped or rigid (real eigenvalue); use method='direct' or 'modal' with frf()",
        )
    u = psi if T is None else T @ psi
    return PoleResidue(lam, u[:, None, :] * u[None, :, :] / a)


def synthesize_frf(pr: PoleResidue, omega, *, kind: str = "receptance"):
    """FRF (nf, p, p) of a symmetric :class:`PoleResidue` model on the grid ``omega`` [rad/s].

    For a pole lambda = alpha + i beta with residue R, R / (i w - lambda) + conj(R) / (i w -
    conj(lambda)) = 2 (U + i w V) / (|lambda|^2 - w^2 - 2 i alpha w) with V = Re R and
    U = -alpha Re R - beta Im R: real numerators and one complex reciprocal per mode and
    frequency, half the work of the 2n-pole sum. Only the upper triangle is computed (the
    residues of a reciprocal system are symmetric)."""
    if kind not in _KINDS:
        raise ShapeError(f"synthesize_frf: kind must be one of {_KINDS}, got '{kind}'")
    omega = check_frequencies(omega)
    lam, R = pr.pole, pr.residue
    p = R.shape[0]
    al, be = lam.real, lam.imag
    iu, ju = np.triu_indices(p)
    Rr, Ri = R.real[iu, ju], R.imag[iu, ju]  # (p(p+1)/2, m)
    V = 2.0 * Rr
    U = 2.0 * (-al * Rr - be * Ri)
    ne = len(iu)
    Hr, Hi = [0.0] * ne, [0.0] * ne  # one (nf,) array per distinct entry: contiguous loops
    for r in range(lam.shape[0]):
        A = al[r] ** 2 + be[r] ** 2 - omega**2
        B = 2.0 * al[r] * omega
        den = A * A + B * B
        dr, di = A / den, B / den
        wdr, wdi = omega * dr, omega * di
        for e in range(ne):
            Hr[e] = Hr[e] + U[e, r] * dr - V[e, r] * wdi
            Hi[e] = Hi[e] + U[e, r] * di + V[e, r] * wdr
    if kind == "mobility":  # x i w, in the real planes (no complex pass over the output)
        Hr, Hi = [-omega * h for h in Hi], [omega * h for h in Hr]
    elif kind == "accelerance":  # x -w^2
        Hr, Hi = [-(omega**2) * h for h in Hr], [-(omega**2) * h for h in Hi]
    H = [jax.lax.complex(Hr[e], Hi[e]) for e in range(ne)]
    index = {}
    for k, (i, j) in enumerate(zip(iu, ju)):
        index[i, j] = index[j, i] = k
    # one interleaving stack into (nf, p, p) (a gather from the triangle was a slow extra pass)
    return jnp.stack([H[index[i, j]] for i in range(p) for j in range(p)], axis=-1).reshape(omega.shape[0], p, p)


def _frequency_dependent(model: Model, x0):
    r, lay = model.rigid, model.layout
    return [e for e, s in zip(model.effects, lay.slots) if e.dynamic_stiffness(r, s, x0, 1.0) is not None]


def _require_viscous(extras, what: str):
    if extras:
        names = sorted({type(e).__name__ for e in extras})
        raise ParameterError(
            f"{what} needs a viscous model, but {names} add frequency-dependent stiffness; use method='direct'"
        )


def pole_residue(
    model: Model,
    posture,
    *,
    hold=(),
    frame=None,
    reference: str = "local_world_aligned",
    components: str = "linear",
    solver: str = "newton",
) -> PoleResidue:
    """Pole-residue model of ``model``'s FRF at a posture (the modal form of :func:`frf`).

    Arguments as in :func:`frf`; every mode must be underdamped and the model viscous (no
    frequency-dependent effect). ``synthesize_frf(pole_residue(model, q, ...), omega, kind=k)``
    equals ``frf(model, q, omega, ..., kind=k, method="modal")``.
    """
    check_solver(solver)
    x0, lin = linearization(model, posture, hold)
    _require_viscous(_frequency_dependent(model, x0), "pole_residue")
    T = None if frame is None else tool_jacobian(model, x0, lin.keep, frame, reference, components)
    return pole_residue_matrices(lin.M, lin.C, lin.K, T=T, solver=solver)


def modal_frf(e: Eigen, omega, *, T=None):
    """Receptance from the modal expansion over all 2n eigenpairs, optionally mapped by ``T``."""
    u = e.shape if T is None else T @ e.shape
    R = u[:, None, :] * u[None, :, :] / e.a  # (p, p, 2n) residues
    pole = 1.0 / (1j * omega[:, None] - e.eigenvalue[None, :])  # (nf, 2n)
    return jnp.einsum("ijr,fr->fij", R, pole)


def frf(
    model: Model,
    posture,
    omega,
    *,
    hold=(),
    frame=None,
    reference: str = "local_world_aligned",
    components: str = "linear",
    kind: str = "receptance",
    method: str = "direct",
    solver: str = "eig",
):
    """Frequency response of ``model`` linearised at a posture (the thesis Eqs. 4.7-4.9).

    **Arguments:**

    - ``model``, ``posture`` ((n,) q0 or (nx,) x0), ``hold``: as in :func:`jflex.modal_analysis`.
    - ``omega``: (nf,) angular frequencies [rad/s]; finite, >= 0, strictly increasing.
    - ``frame``: None for the joint-space FRF over the kept coordinates; a frame name (e.g.
      ``"tool"``) for ``G_X = J G J^T`` with ``reference`` / ``components`` as in
      :func:`jflex.jacobian` (``"linear"``: the 3x3 translational FRF of Eq. 4.8); or an
      effect output naming a point, e.g. ``"beam.tip_position"`` of a flexible link, whose FRF
      includes the link's deflection (a rigid frame is not carried by a beam's modes).
    - ``kind``: ``"receptance"`` [m/N, rad/(N m)], ``"mobility"`` (x i w) or
      ``"accelerance"`` (x -w^2).
    - ``method``: ``"direct"`` (inverse of the dynamic stiffness, including frequency-dependent
      effect terms) or ``"modal"`` (modal expansion; viscous models only).
    - ``solver``: eigen-solver of the modal form, ``"eig"`` (any damping) or ``"newton"``
      (underdamped modes, faster in posture sweeps), see :func:`jflex.linear.eigen`.

    **Returns:** complex (nf, p, p).
    """
    _check_kind_method(kind, method)
    check_solver(solver)
    omega = check_frequencies(omega)
    x0, lin = linearization(model, posture, hold)
    T = None if frame is None else tool_jacobian(model, x0, lin.keep, frame, reference, components)
    r, lay = model.rigid, model.layout
    idx = jnp.array(lin.keep, dtype=int)
    extras = _frequency_dependent(model, x0)
    if not extras:
        return frf_matrices(lin.M, lin.C, lin.K, omega, kind=kind, method=method, T=T, solver=solver)
    if method == "modal":
        _require_viscous(extras, "frf: method='modal'")

    def stack(e, s):  # the effect's extra dynamic stiffness over the grid, kept coordinates
        return jax.vmap(lambda w: e.dynamic_stiffness(r, s, x0, w)[jnp.ix_(idx, idx)])(omega)

    E = tuple(stack(e, s) for e, s in zip(model.effects, lay.slots) if any(e is x for x in extras))
    return _direct(lin.M, lin.C, lin.K, omega, T, E) * _kind_factor(omega, kind)[:, None, None]


def half_power_damping(omega, H):
    """Damping ratio of the highest peak of ``|H|`` by the half-power bandwidth (the course notes):
    ``zeta ~ (w+ - w-) / (2 w_peak)`` with ``|H(w+-)| = |H|max / sqrt 2`` (linear interpolation
    between grid points). Accurate for isolated, lightly damped modes.

    **Arguments:** ``omega`` (nf,) increasing [rad/s]; ``H`` (nf,) complex or real FRF.

    **Returns:** ``(zeta, w_peak)``; zeta is NaN when a half-power point lies off the grid.
    """
    w = check_frequencies(omega)
    h = jnp.abs(jnp.asarray(H))
    if h.shape != w.shape:
        raise ShapeError(f"half_power_damping: H must have the shape of omega {w.shape}, got {h.shape}")
    nf = w.shape[0]
    k = jnp.argmax(h)
    level = h[k] / jnp.sqrt(2.0)
    i = jnp.arange(nf)
    below = h < level
    # last grid point below the level left of the peak, first one right of it
    left = jnp.max(jnp.where(below & (i < k), i, -1))
    right = jnp.min(jnp.where(below & (i > k), i, nf))

    def cross(i0, i1):
        h0, h1 = h[i0], h[i1]
        t = (level - h0) / (h1 - h0)
        return w[i0] + t * (w[i1] - w[i0])

    wl = cross(jnp.clip(left, 0, nf - 1), jnp.clip(left + 1, 0, nf - 1))
    wr = cross(jnp.clip(right - 1, 0, nf - 1), jnp.clip(right, 0, nf - 1))
    ok = (left >= 0) & (right < nf)
    # peak frequency from a parabola through the three samples around the maximum
    k0 = jnp.clip(k, 1, nf - 2)
    y0, y1, y2 = h[k0 - 1], h[k0], h[k0 + 1]
    den = y0 - 2 * y1 + y2
    d = jnp.where(den != 0, 0.5 * (y0 - y2) / jnp.where(den != 0, den, 1.0), 0.0)
    wpk = w[k0] + d * 0.5 * (w[k0 + 1] - w[k0 - 1])
    return jnp.where(ok, (wr - wl) / (2 * wpk), jnp.nan), wpk


__all__ = [
    "PoleResidue", "frf", "frf_matrices", "modal_frf", "pole_residue", "pole_residue_matrices", "synthesize_frf",
    "half_power_damping", "expand_posture", "resolve_hold",
]
