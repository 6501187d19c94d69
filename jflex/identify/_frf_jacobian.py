"""The structured (sparse) exact Jacobian of an FRF fit (:class:`FRFData`).

A free parameter of an FRF fit (a joint stiffness, a damping, a rotor inertia) usually moves only a
few entries of the linearised ``M``, ``C``, ``K``: 4 for a joint spring or damper, 1 for a rotor
inertia. ``jflex.frf``'s own JVP (``jflex.linear._frf._direct_jvp``) is generic: it contracts the
DENSE tangents ``dM``, ``dC``, ``dK`` (n^2 entries each) with the inverse at every frequency, so an
18-parameter ``jax.jacfwd`` of a UR5 tool-FRF residual costs 7-12x the residual. Here the tangent
``dH = -Y dD X`` (``X = G T^T``, ``Y = T G``, ``G = (K - w^2 M + i w C)^-1``, ``dD = dK - w^2 dM +
i w dC``) is contracted only over the entries where ``d(M, C, K)/du`` can be non-zero, and only for
the FRF entries the data compare: 2.5-4x the residual (``benchmarks/bench_identify_flexible.py``).

Use it through :func:`jflex.identify.fit` (``jacobian="sparse"``) or, to drive an optimistix solver
yourself, :func:`sparse_frf_residual`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import DataError, ParameterError
from ..linear._common import expand_posture, linearization, tool_jacobian
from ..linear._frf import _frequency_dependent, _inverses, _kind_factor
from ._fit import ParameterSpec, _pair
from ._residuals import FRFData

# An entry of d(M, C, K)/du outside the pattern found at build time is tolerated up to this fraction
# of the largest entry of the same matrix and parameter (round-off); above it the JVP raises.
_LEAK_RTOL = 1e-12
_PROBE_SCALE = 0.3  # spread of the random probe points about the start, in the optimisation variables u


def _fail(where, what):
    return f"{where}: {what}; use the dense Jacobian (fit(..., jacobian='dense'), or jax.jacfwd of residual_vector)"


def _check_data_frees(spec, data, index, where):
    """A free parameter on this FRFData's own arrays (``Free(on="data")``) moves the FRF by more
    than ``d(M, C, K)``: not supported."""
    d = data[index]
    for f in spec.frees:
        if f.on != "data":
            continue
        leaf = f.where(data)
        for field in ("postures", "omega", "H", "weights"):
            if leaf is getattr(d, field):
                raise ParameterError(_fail(where, f"free parameter '{f.name}' acts on FRFData '{d.name}' field '{field}'; "
                                               "only model parameters are supported"))


class SparseFRFResidual:
    """``u -> residual_vector(spec.apply(model, u), data)`` for one :class:`FRFData`, with an exact
    JVP that exploits the sparsity of ``d(M, C, K)/du``. Built by :func:`sparse_frf_residual`.

    - ``self(u)``: the residual (m,). Its primal IS the plain residual; its JVP (hence
      ``jax.jacfwd``, ``jax.linearize``, ``jax.grad``) computes the whole Jacobian (m, size) once per
      point and applies it to the tangent, so ``jax.jacfwd`` pays for it once, not per column.
    - ``residual_and_jacobian(u)``: ``(r, J)`` directly.
    - ``channels``: the residual's channel names and lengths, in order (as ``FRFData.residuals``).
    - ``entries_per_parameter``: how many (matrix, i, j) entries of ``(M, C, K)`` each parameter moves;
      ``pattern``: those entries, bool (3, n, n, size) (matrix M, C, K; row; column; parameter).
    """

    def __init__(self, spec, pair, index, u0, *, probes=3, seed=0, where="sparse_frf_residual"):
        data = pair[1]
        d = data[index]
        if not isinstance(d, FRFData):
            raise DataError(_fail(where, f"the sparse FRF Jacobian applies to FRFData only, got {type(d).__name__}"))
        _check_data_frees(spec, data, index, where)
        labels = spec.labels()
        post, omega, hold = d.postures, d.omega, d.hold
        frame, reference, components = d.frame, d.reference, d.components

        def model_of(u):
            return spec.apply(pair, u)[0]

        def lin(u):
            """``(stack(M, C, K), T)`` at every posture: (P, 3, n, n), (P, p, n) (T (P, 0) without a frame)."""
            m = model_of(u)

            def one(q):
                x0, li = linearization(m, q, hold)
                T = jnp.zeros(0) if frame is None else tool_jacobian(m, x0, li.keep, frame, reference, components)
                return jnp.stack([li.M, li.C, li.K]), T

            return jax.vmap(one)(post)

        extras = []

        def find_extras(u):  # traced only (jax.eval_shape): which effects add a dynamic stiffness is static
            m = model_of(u)
            extras.extend(_frequency_dependent(m, expand_posture(m, post[0])))
            return jnp.zeros(())

        jax.eval_shape(find_extras, u0)
        if extras:
            raise ParameterError(_fail(where, f"effects {sorted({type(e).__name__ for e in extras})} add a frequency-dependent "
                                              "stiffness, which the sparse FRF Jacobian does not carry"))

        # --- the sparsity pattern, at build time ---------------------------------------------------
        # Entry (A, i, j, k) is in the pattern when dA_ij/du_k is non-zero at ANY posture at the start
        # u0 or at one of `probes` random points about it (Gaussian, std _PROBE_SCALE in u). Why this
        # is safe: (1) the entries of d(M, C, K)/du are analytic functions of u for the effects'
        # smooth laws, and an analytic function that is not identically zero vanishes only on a set
        # of measure zero, so a structural non-zero is missed only if it vanishes at every probe (the
        # random ones with probability zero; one that vanishes by coincidence at u0, e.g. a symmetric
        # start, is caught by them); (2) at EVERY evaluation the JVP computes d(M, C, K)/du densely
        # anyway (cheap: n^2 per posture and parameter; the cost is in the FRF contraction) and
        # raises if anything outside the pattern exceeds round-off (_LEAK_RTOL), so a missed entry
        # (say of a piecewise law) can never give a silently wrong Jacobian.
        jac_lin = jax.jit(jax.jacfwd(lin))
        rng = np.random.default_rng(seed)
        u0 = np.asarray(u0, dtype=float)
        nu = u0.shape[0]
        mask = None
        for i, pt in enumerate([u0] + [u0 + rng.normal(scale=_PROBE_SCALE, size=nu) for _ in range(int(probes))]):
            dA, dT = (np.asarray(a) for a in jac_lin(jnp.asarray(pt)))
            if not (np.isfinite(dA).all() and np.isfinite(dT).all()):
                if i == 0:
                    raise ParameterError(_fail(where, "d(M, C, K)/du is not finite at the start parameters"))
                continue  # a probe outside the model's valid range (e.g. a negative mass): skip it
            if np.any(dT != 0):
                ks = np.flatnonzero(np.any(dT.reshape(-1, nu) != 0, axis=0))
                raise ParameterError(_fail(where, f"the tool Jacobian (FRFData field 'frame' = {frame!r}) depends on the "
                                                  f"free parameters {[labels[k] for k in ks]}"))
            nz = np.any(dA != 0, axis=0)  # (3, n, n, nu), union over the postures
            mask = nz if mask is None else mask | nz
        ent = [np.argwhere(mask[..., k]) for k in range(nu)]
        cap = max([1] + [len(e) for e in ent])
        idx = np.zeros((nu, cap, 3), dtype=int)
        valid = np.zeros((nu, cap))
        for k, e in enumerate(ent):
            idx[k, : len(e)], valid[k, : len(e)] = e, 1.0
        which, I, J = idx[..., 0], idx[..., 1], idx[..., 2]
        self.entries_per_parameter = tuple(len(e) for e in ent)
        self.pattern = mask

        w = jnp.asarray(omega)
        # d D / d A for A = M, C, K at each frequency: -w^2, i w, 1; per pattern entry (nf, nu, cap)
        fac = jnp.stack([-(w**2) + 0j, 1j * w, jnp.ones_like(w) + 0j])
        fac = jnp.moveaxis(fac[which], 2, 0)
        outside = jnp.asarray(~mask)
        tt = np.arange(nu)[:, None]
        ii = np.array([e[0] for e in d.entries])
        jj = np.array([e[1] for e in d.entries])
        kf = _kind_factor(w, d.kind)[:, None, None]
        leak_msg = (f"{where}: d(M, C, K)/du has a non-zero entry outside the sparsity pattern found at build time, or "
                    "the tool Jacobian depends on the parameters, at this point; use the dense Jacobian "
                    "(fit(..., jacobian='dense'))")

        def contract(A, T, coef):
            """One posture: the predicted FRF (nf, a, b) and ``dH / H`` over ``entries`` (nf, e, nu)."""
            G = _inverses(A[0], A[1], A[2], w, ())  # the inverse jflex.frf uses
            if frame is None:
                H = X = Y = G
            else:
                Y = jax.vmap(lambda g: T @ g)(G)
                H = jax.vmap(lambda y: y @ T.T)(Y)  # = jflex.frf(..., frame) (receptance) at this posture
                X = jnp.einsum("fij,aj->fia", G, T)
            Ye, Xe = Y[:, ii, :], X[:, :, jj]  # (nf, e, n), (nf, n, e)
            cw = coef[None] * fac  # (nf, nu, cap): the dD entries
            dH = 0.0
            for c in range(cap):  # -sum_c cw Y[:, i_c] X[j_c, :]: elementwise (XLA's tiny complex dots are slow)
                dH = dH - Ye[:, :, I[:, c]] * jnp.moveaxis(Xe[:, J[:, c], :], 1, 2) * cw[:, None, :, c]
            # d log(kind H) = dH / H: the kind factor (i w, -w^2) does not depend on u
            return H * kf, dH / H[:, ii, jj][..., None]

        def lin_twice(u):
            out = lin(u)
            return out, out

        def residual_and_jacobian(u):
            (dA, dT), (A, T) = jax.jacfwd(lin_twice, has_aux=True)(u)  # d(M, C, K, T)/du and (M, C, K, T)
            col = jnp.max(jnp.abs(dA), axis=(0, 2, 3))  # (3, nu)
            leak = jnp.max(jnp.abs(jnp.where(outside, dA, 0.0)), axis=(0, 2, 3))
            bad = jnp.any(leak > _LEAK_RTOL * col) | jnp.any(dT != 0)
            coef = dA[:, which, I, J, tt] * valid  # (P, nu, cap)
            coef = eqx.error_if(coef, bad, leak_msg)
            Hp, JL = jax.vmap(contract)(A, T, coef)  # (P, nf, a, b), (P, nf, e, nu)
            r = jnp.concatenate([jnp.ravel(v) for v in d._residuals_of(Hp).values()])
            scale = d.weights / np.sqrt(JL[..., 0].size)
            Jr = jnp.concatenate([scale[0] * JL.real.reshape(-1, nu), scale[1] * JL.imag.reshape(-1, nu)])
            return r, Jr

        def plain(u):
            return jnp.concatenate([jnp.ravel(v) for v in d.residuals(model_of(u)).values()])

        @jax.custom_jvp
        def resid(u):
            return plain(u)

        @resid.defjvp
        def _jvp(primals, tangents):
            (u,), (du,) = primals, tangents
            r, Jr = residual_and_jacobian(u)
            return r, Jr @ du

        half = len(d.entries) * post.shape[0] * w.shape[0]
        self.channels = ((f"{d.name}:log_magnitude", half), (f"{d.name}:phase", half))
        self._resid = resid
        self.residual_and_jacobian = residual_and_jacobian

    def __call__(self, u):
        return self._resid(u)

    def parts(self, u) -> dict:
        """The residual split into ``FRFData.residuals``'s channels (dict name -> vector)."""
        r = self(u)
        (a, n), (b, _) = self.channels
        return {a: r[:n], b: r[n:]}


def sparse_frf_residual(spec: ParameterSpec, model, data: FRFData, *, probes: int = 3, seed: int = 0) -> SparseFRFResidual:
    """The FRF-fit residual ``u -> residual_vector(spec.apply(model, u), data)`` with a structured
    exact Jacobian: :class:`SparseFRFResidual` (callable).

    The same function of ``u`` as the plain residual, with a custom JVP that contracts ``dH = -Y dD
    X`` only over the entries of ``(M, C, K)`` each parameter moves (found once here, at ``u0 =
    spec.pack(model)`` and ``probes`` random points about it; values by forward-mode AD of the
    linearisation at every point, never finite differences) and only for ``data.entries``. For
    Gauss-Newton-type solvers this Jacobian costs 2.5-4x the residual, against 7-12x through
    ``jflex.frf``'s generic JVP. :func:`fit` uses it with ``jacobian="sparse"``.

    **Arguments:** ``spec``: :class:`ParameterSpec` (bound here to ``model``); ``model``: the start
    :class:`jflex.Model` (or a ``(model, data tuple)`` pair whose data tuple is ``(data,)``);
    ``data``: one :class:`FRFData` (any ``entries``, ``weights``, ``hold``, ``frame``,
    ``reference``, ``components``, ``kind``); ``probes``, ``seed``: the random points of the
    pattern search.

    **Raises** ``DataError`` when ``data`` is not an :class:`FRFData`; ``ParameterError`` when the
    tool Jacobian (``frame``) depends on the parameters, when an effect adds a frequency-dependent
    stiffness (e.g. a hysteretic spring), when a free parameter acts on the data's own arrays, or
    (at evaluation) when ``d(M, C, K)/du`` leaves the pattern found here. Use the dense Jacobian
    then.
    """
    if not isinstance(data, FRFData):
        raise DataError(_fail("sparse_frf_residual", f"the sparse FRF Jacobian applies to FRFData only, got {type(data).__name__}"))
    pair = _pair(model)
    pair = (pair[0], pair[1] or (data,))
    if len(pair[1]) != 1 or pair[1][0] is not data:
        raise ParameterError("sparse_frf_residual: model must be a Model or a (model, (data,)) pair holding this data")
    spec = spec.bind(pair)
    u0 = jnp.asarray(spec.pack(pair), dtype=jnp.result_type(float))
    return SparseFRFResidual(spec, pair, 0, u0, probes=probes, seed=seed)


def sparse_parts(spec, pair, u0, *, where="fit(jacobian='sparse')"):
    """For :func:`fit`: ``{index: SparseFRFResidual}`` for every FRFData in the pair's data tuple."""
    out = {i: SparseFRFResidual(spec, pair, i, u0, where=where) for i, d in enumerate(pair[1]) if isinstance(d, FRFData)}
    if not out:
        raise DataError(f"{where}: the sparse FRF Jacobian applies to FRFData; the data are "
                        f"{[type(d).__name__ for d in pair[1]]}")
    return out
