"""Data residuals for :func:`jflex.identify.fit`: torques through inverse dynamics, modal
tables and FRFs at many postures through the linearisation, time responses through
:func:`jflex.simulate` (several experiments, free initial states, multiple shooting)."""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import DataError
from .._model import model_inverse_dynamics
from ..linear import best_permutation, frf as model_frf, linearization, mac
from ..linear._common import tool_jacobian
from ..data._validate import check_finite, check_lengths, check_shape, check_time
from ._fit import AbstractData


def _nrmse(pred, meas, axis=0):
    scale = jnp.maximum(jnp.std(meas, axis=axis), 1e-300)
    return jnp.sqrt(jnp.mean((pred - meas) ** 2, axis=axis)) / scale


class TorqueData(AbstractData):
    """Joint torques measured along a motion: residual ``tau_model(q, qd, qdd) - tau``.

    **Arguments:** ``q``, ``qd``, ``qdd`` (N, n) [rad, rad/s, rad/s^2]; ``tau`` (N, n) [N m];
    ``weight`` (); ``name`` prefix of the channels (one per joint); ``source``: file name used
    in error messages. The model's inverse dynamics include its effects (friction, compensator).
    """

    q: jnp.ndarray
    qd: jnp.ndarray
    qdd: jnp.ndarray
    tau: jnp.ndarray
    weight: jnp.ndarray
    name: str = eqx.field(static=True)

    def __init__(self, q, qd, qdd, tau, *, weight=1.0, name="torque", source=None):
        arrs = {k: check_finite(v, k, source).astype(float) for k, v in dict(q=q, qd=qd, qdd=qdd, tau=tau).items()}
        check_lengths(arrs, source)
        for k, v in arrs.items():
            check_shape(v, (None, arrs["q"].shape[1] if arrs["q"].ndim == 2 else None), k, source)
        self.q, self.qd, self.qdd, self.tau = (jnp.asarray(arrs[k]) for k in ("q", "qd", "qdd", "tau"))
        self.weight = jnp.asarray(weight, dtype=float)
        self.name = name

    def predict(self, model):
        z = jnp.zeros(model.nz)
        f = lambda q, qd, qdd: model_inverse_dynamics(model, 0.0, q, qd, qdd, z)[: q.shape[0]]
        return jax.vmap(f)(self.q, self.qd, self.qdd)

    def residuals(self, model):
        e = self.predict(model) - self.tau
        scale = jnp.maximum(jnp.std(self.tau, axis=0), 1e-300) * jnp.sqrt(self.tau.shape[0])
        r = self.weight * e / scale
        names = model.rigid.joint_names
        return {f"{self.name}:{names[j]}": r[:, j] for j in range(r.shape[1])}

    def nrmse(self, model):
        v = _nrmse(self.predict(model), self.tau)
        names = model.rigid.joint_names
        return {f"{self.name}:{names[j]}": v[j] for j in range(v.shape[0])}


def model_modes(model, posture, *, hold="actuated", frame=None, reference="local_world_aligned", components="linear"):
    """Differentiable modal analysis at a posture: ``(f [Hz], zeta, shapes)`` sorted by |lambda|.

    Same quantities as :func:`jflex.modal_analysis` (the thesis "Posture Dependent Dynamics in Robotic Machining" Eqs. 4.10-4.13), but through
    ``lax.linalg.eig(..., enable_eigvec_derivs=True)`` so that fits can differentiate
    frequencies, damping ratios and (for distinct eigenvalues) shapes. ``shapes`` (s, n_modes)
    over the kept coordinates, or at ``frame`` through its Jacobian.
    """
    x0, lin = linearization(model, posture, hold)
    M, C, K = lin.M, lin.C, lin.K
    n = M.shape[0]
    A = jnp.block([[jnp.zeros((n, n)), jnp.eye(n)], [-jnp.linalg.solve(M, K), -jnp.linalg.solve(M, C)]])
    lam, V = jax.lax.linalg.eig(A, compute_left_eigenvectors=False, enable_eigvec_derivs=True)
    top = jnp.argsort(-lam.imag)[:n]
    top = top[jnp.argsort(jnp.abs(lam[top]))]
    lam, psi = lam[top], V[:n, top]
    w = jnp.abs(lam)
    zeta = -lam.real / jnp.where(w > 0, w, 1.0)
    if frame is not None:
        psi = tool_jacobian(model, x0, lin.keep, frame, reference, components) @ psi
    return w / (2 * jnp.pi), zeta, psi


def _postures(postures, source, field="postures"):
    p = check_finite(postures, field, source).astype(float)
    if p.ndim == 1:
        p = p[None]
    return p


class ModalData(AbstractData):
    """Measured natural frequencies, damping ratios and (optionally) mode shapes at P postures.

    Model mode ``mode_index[j]`` (sorted by frequency) is compared with measured mode ``j``;
    NaN entries in the tables are skipped (a mode not identified at a posture).

    **Arguments:**

    - ``postures`` (P, n) [rad]; ``frequency`` (P, m) [Hz]; ``damping`` (P, m) [-] (ratio).
    - ``shapes`` optional (P, s, m) (complex allowed), compared by MAC (residual ``1 - MAC``);
      over the coordinates of ``frame`` when given, else over the kept coordinates.
    - ``mode_index``: (m,) or per posture (P, m) static model-mode indices (default ``0..m-1``;
      e.g. from :func:`jflex.track_modes` when modes swap order across postures), or ``"mac"`` (default
      when shapes are given): pair each measured mode with a model mode by the best MAC at each
      posture, which survives modes swapping order while the parameters move.
    - ``hold``, ``frame``: as in :func:`jflex.modal_analysis` (the thesis: ``hold="actuated"``).
    - ``weights``: ``(w_f, w_zeta, w_mac)``; frequency residuals are relative in units of
      ``frequency_scale`` (default 0.01: one percent), damping residuals absolute in units of
      ``damping_scale`` (default 0.01: one percentage point), so that by default a 1 % frequency
      error weighs like a 1-point damping error (how EMA tables are usually compared).
    """

    postures: jnp.ndarray
    frequency: jnp.ndarray
    damping: jnp.ndarray
    shapes: jnp.ndarray | None
    weights: jnp.ndarray
    damping_scale: jnp.ndarray
    frequency_scale: jnp.ndarray
    mode_index: tuple | str = eqx.field(static=True)
    hold: object = eqx.field(static=True)
    frame: str | None = eqx.field(static=True)
    name: str = eqx.field(static=True)

    def __init__(self, postures, frequency, damping, shapes=None, *, mode_index=None, hold="actuated", frame=None,
                 weights=(1.0, 1.0, 1.0), damping_scale=0.01, frequency_scale=0.01, name="modal", source=None):
        p = _postures(postures, source)
        f = np.atleast_2d(np.asarray(frequency, dtype=float))
        z = np.atleast_2d(np.asarray(damping, dtype=float))
        for k, v in (("frequency", f), ("damping", z)):
            if v.shape != (p.shape[0], f.shape[1]):
                raise DataError(f"{source or 'ModalData'}: field '{k}': expected shape ({p.shape[0]}, m) (postures x modes), got {v.shape}")
            if np.isinf(v).any():
                raise DataError(f"{source or 'ModalData'}: field '{k}': contains inf (use NaN to mark a missing mode)")
        if (f[np.isfinite(f)] <= 0).any():
            raise DataError(f"{source or 'ModalData'}: field 'frequency': natural frequencies must be > 0 Hz")
        self.postures = jnp.asarray(p)
        self.frequency, self.damping = jnp.asarray(f), jnp.asarray(z)
        self.shapes = None if shapes is None else jnp.asarray(shapes)
        if self.shapes is not None and (self.shapes.ndim != 3 or self.shapes.shape[0] != p.shape[0] or self.shapes.shape[2] != f.shape[1]):
            raise DataError(f"{source or 'ModalData'}: field 'shapes': expected (P, s, m) = ({p.shape[0]}, s, {f.shape[1]}), got {self.shapes.shape}")
        self.weights = jnp.asarray(weights, dtype=float)
        self.damping_scale = jnp.asarray(damping_scale, dtype=float)
        self.frequency_scale = jnp.asarray(frequency_scale, dtype=float)
        if mode_index is None:
            mode_index = "mac" if shapes is not None else tuple(range(f.shape[1]))
        if isinstance(mode_index, str):
            if mode_index != "mac" or shapes is None:
                raise DataError(f"{source or 'ModalData'}: mode_index='mac' needs measured shapes; otherwise give model-mode indices")
            self.mode_index = "mac"
        else:
            mi = np.asarray(mode_index, dtype=int)
            mi = np.broadcast_to(mi, (p.shape[0], f.shape[1])) if mi.ndim == 1 else mi
            if mi.shape != (p.shape[0], f.shape[1]):
                raise DataError(f"{source or 'ModalData'}: mode_index: expected ({f.shape[1]},) or ({p.shape[0]}, {f.shape[1]}), got {mi.shape}")
            self.mode_index = tuple(tuple(int(i) for i in row) for row in mi)
        self.hold = hold if isinstance(hold, str) else tuple(hold)
        self.frame = frame
        self.name = name

    def predict(self, model):
        """(f (P, m) [Hz], zeta (P, m), shapes (P, s, m) or None) of the model."""
        m = self.frequency.shape[1]

        P = self.postures.shape[0]

        def one(q, measured, idx):
            f, z, sh = model_modes(model, q, hold=self.hold, frame=self.frame)
            if self.mode_index == "mac":
                S = jax.lax.stop_gradient(mac(measured, sh))  # (m, n_model)
                nm = S.shape[1]
                S = jnp.concatenate([S, jnp.zeros((nm - m, nm))]) if nm > m else S
                idx = best_permutation(S)[:m]
            return f[idx], z[idx], sh[:, idx]

        shapes = self.shapes if self.shapes is not None else jnp.zeros((P, 1, m))
        idx = jnp.zeros((P, m), int) if self.mode_index == "mac" else jnp.array(self.mode_index)
        return jax.vmap(one)(self.postures, shapes, idx)

    def _parts(self, model):
        f, z, sh = self.predict(model)
        ok_f = jnp.isfinite(self.frequency)
        ef = jnp.where(ok_f, (f - jnp.where(ok_f, self.frequency, 1.0)) / jnp.where(ok_f, self.frequency, 1.0), 0.0)
        ok_z = jnp.isfinite(self.damping)
        ez = jnp.where(ok_z, (z - jnp.where(ok_z, self.damping, 0.0)) / self.damping_scale, 0.0)
        em = None
        if self.shapes is not None:
            em = jax.vmap(lambda a, b: 1.0 - jnp.diag(mac(a, b)))(sh, self.shapes)
        return ef, ez, em, ok_f, ok_z

    def residuals(self, model):
        ef, ez, em, ok_f, ok_z = self._parts(model)
        nf = jnp.maximum(ok_f.sum(), 1)
        nz = jnp.maximum(ok_z.sum(), 1)
        out = {f"{self.name}:frequency": self.weights[0] * ef.ravel() / (self.frequency_scale * jnp.sqrt(nf)),
               f"{self.name}:damping": self.weights[1] * ez.ravel() / jnp.sqrt(nz)}
        if em is not None:
            out[f"{self.name}:mac"] = self.weights[2] * em.ravel() / jnp.sqrt(em.size)
        return out

    def nrmse(self, model):
        """Here: RMS relative frequency error, RMS damping error [ratio], mean 1 - MAC."""
        ef, _, em, ok_f, ok_z = self._parts(model)
        f, z, _ = self.predict(model)
        dz = jnp.where(ok_z, z - jnp.where(ok_z, self.damping, 0.0), 0.0)
        out = {f"{self.name}:frequency": jnp.sqrt(jnp.sum(ef**2) / jnp.maximum(ok_f.sum(), 1)),
               f"{self.name}:damping": jnp.sqrt(jnp.sum(dz**2) / jnp.maximum(ok_z.sum(), 1))}
        if em is not None:
            out[f"{self.name}:mac"] = jnp.mean(em)
        return out


class FRFData(AbstractData):
    """Measured FRFs at P postures, compared in log-magnitude and phase.

    The residual of one entry is ``log(H_model / H_meas)``: real part the log-magnitude error,
    imaginary part the phase error (wrapped), so peaks and anti-resonances weigh by their
    relative, not absolute, error.

    **Arguments:**

    - ``postures`` (P, n) [rad]; ``omega`` (F,) [rad/s]; ``H`` (P, F, a, b) complex (as returned by
      :func:`jflex.frf` for the same ``hold``/``frame``/``reference``/``components``/``kind``).
    - ``entries``: optional static list of (i, j) entries to use (default all).
    - ``weights``: (magnitude, phase).
    """

    postures: jnp.ndarray
    omega: jnp.ndarray
    H: jnp.ndarray
    weights: jnp.ndarray
    entries: tuple = eqx.field(static=True)
    hold: object = eqx.field(static=True)
    frame: str | None = eqx.field(static=True)
    reference: str = eqx.field(static=True)
    components: str = eqx.field(static=True)
    kind: str = eqx.field(static=True)
    name: str = eqx.field(static=True)

    def __init__(self, postures, omega, H, *, entries=None, hold="actuated", frame=None, reference="local_world_aligned",
                 components="linear", kind="receptance", weights=(1.0, 1.0), name="frf", source=None):
        p = _postures(postures, source)
        w = check_finite(omega, "omega", source).astype(float)
        if w.ndim != 1 or (np.diff(w) <= 0).any():
            raise DataError(f"{source or 'FRFData'}: field 'omega': expected strictly increasing frequencies (F,) [rad/s]")
        Hm = check_finite(H, "H", source)
        if Hm.ndim == 3:
            Hm = Hm[None]
        if Hm.ndim != 4 or Hm.shape[:2] != (p.shape[0], w.shape[0]):
            raise DataError(f"{source or 'FRFData'}: field 'H': expected (P, F, a, b) = ({p.shape[0]}, {w.shape[0]}, a, b), got {Hm.shape}")
        if (np.abs(Hm) == 0).any():
            raise DataError(f"{source or 'FRFData'}: field 'H': exact zeros cannot be compared in log-magnitude; drop those entries")
        self.postures, self.omega, self.H = jnp.asarray(p), jnp.asarray(w), jnp.asarray(Hm.astype(complex))
        self.entries = tuple((int(i), int(j)) for i in range(Hm.shape[2]) for j in range(Hm.shape[3])) if entries is None else tuple(tuple(e) for e in entries)
        self.weights = jnp.asarray(weights, dtype=float)
        self.hold = hold if isinstance(hold, str) else tuple(hold)
        self.frame, self.reference, self.components, self.kind, self.name = frame, reference, components, kind, name

    def predict(self, model):
        f = lambda q: model_frf(model, q, self.omega, hold=self.hold, frame=self.frame, reference=self.reference,
                                components=self.components, kind=self.kind)
        return jax.vmap(f)(self.postures)

    def _log_ratio(self, model):
        return self._log_ratio_of(self.predict(model))

    def _log_ratio_of(self, Hp):
        """``log(H_model / H_meas)`` over ``entries`` (P, F, e) from a prediction ``Hp`` (P, F, a, b)."""
        ii = jnp.array([e[0] for e in self.entries])
        jj = jnp.array([e[1] for e in self.entries])
        return jnp.log(Hp[:, :, ii, jj] / self.H[:, :, ii, jj])

    def residuals(self, model):
        return self._residuals_of(self.predict(model))

    def _residuals_of(self, Hp):
        """:meth:`residuals` from a predicted FRF ``Hp`` (P, F, a, b) (as :meth:`predict` returns)."""
        L = self._log_ratio_of(Hp)
        n = jnp.sqrt(L.size)
        return {f"{self.name}:log_magnitude": self.weights[0] * jnp.real(L).ravel() / n,
                f"{self.name}:phase": self.weights[1] * jnp.imag(L).ravel() / n}

    def nrmse(self, model):
        """RMS log-magnitude error [neper] and RMS phase error [rad]."""
        L = self._log_ratio(model)
        return {f"{self.name}:log_magnitude": jnp.sqrt(jnp.mean(jnp.real(L) ** 2)),
                f"{self.name}:phase": jnp.sqrt(jnp.mean(jnp.imag(L) ** 2))}


class TimeData(AbstractData):
    """One experiment's measured time responses, compared with :func:`jflex.simulate`.

    The record can be cut into ``segments`` for multiple shooting: segment k starts from its own
    state ``(x0s[k], xd0s[k], z0s[k])`` and a continuity residual ties the end of segment k to the
    start of segment k + 1. Free those start states with :meth:`initial_state_frees` (segment 0
    only: unknown initial state; all: multiple shooting), otherwise they stay as given.

    **Arguments:**

    - ``ts`` (N,) [s], strictly increasing; ``outputs``: dict output name (any name
      :func:`jflex.simulate` knows: ``"joint2"``, ``"beam.tip_deflection"``, ``"frame:tool"``)
      -> measured (N, ...) values.
    - ``x0``, ``xd0``, ``z0``: initial state of the experiment (nx,), (nx,), (nz,) (for
      multiple shooting the later segments start from the states interpolated on ``guess``, a
      dict ``{"x": (N, nx), "xd": (N, nx), "z": (N, nz)}``, or repeat the initial state).
    - ``inputs``: a :class:`jflex.AbstractInput` (default zero); ``segments``; ``weights``: dict
      output -> weight; ``continuity_weight``; ``simulate_kw``: passed to :func:`jflex.simulate`
      (solver, rtol, atol, max_steps, adjoint; default adjoint ``diffrax.ForwardMode()`` since
      Levenberg-Marquardt builds Jacobians column by column in forward mode).
    """

    ts: jnp.ndarray
    measured: dict
    x0s: jnp.ndarray
    xd0s: jnp.ndarray
    z0s: jnp.ndarray
    inputs: object
    weights: dict
    continuity_weight: jnp.ndarray
    segments: int = eqx.field(static=True)
    simulate_kw: tuple = eqx.field(static=True)
    name: str = eqx.field(static=True)

    def __init__(self, ts, outputs: dict, x0, xd0=None, z0=None, *, inputs=None, segments: int = 1, guess=None,
                 weights=None, continuity_weight=10.0, simulate_kw=None, name="time", source=None):
        t = check_time(ts, "ts", source)
        meas = {}
        for k, v in outputs.items():
            a = check_finite(v, k, source).astype(float)
            if a.shape[0] != t.shape[0]:
                raise DataError(f"{source or 'TimeData'}: field '{k}': has {a.shape[0]} samples but 'ts' has {t.shape[0]}")
            meas[k] = jnp.asarray(a)
        if not meas:
            raise DataError(f"{source or 'TimeData'}: no measured outputs given")
        S = int(segments)
        if not 1 <= S <= t.shape[0] // 2:
            raise DataError(f"{source or 'TimeData'}: segments must be between 1 and {t.shape[0] // 2}, got {segments}")
        if t.shape[0] % S:
            raise DataError(f"{source or 'TimeData'}: {t.shape[0]} samples do not split into {S} equal segments; trim the record")
        x0 = np.asarray(x0, float)
        xd0 = np.zeros_like(x0) if xd0 is None else np.asarray(xd0, float)
        z0 = np.zeros(0) if z0 is None else np.asarray(z0, float)
        L = t.shape[0] // S
        starts = np.arange(S) * L
        if guess is not None:
            x0s = np.asarray(guess["x"], float)[starts]
            xd0s = np.asarray(guess["xd"], float)[starts]
            z0s = np.asarray(guess["z"], float)[starts] if "z" in guess else np.tile(z0, (S, 1))
            x0s[0], xd0s[0], z0s[0] = x0, xd0, z0
        else:
            x0s, xd0s, z0s = np.tile(x0, (S, 1)), np.tile(xd0, (S, 1)), np.tile(z0, (S, 1))
        self.ts, self.measured = jnp.asarray(t), meas
        self.x0s, self.xd0s, self.z0s = jnp.asarray(x0s), jnp.asarray(xd0s), jnp.asarray(z0s)
        self.inputs = inputs
        self.weights = {k: jnp.asarray((weights or {}).get(k, 1.0), dtype=float) for k in meas}
        self.continuity_weight = jnp.asarray(continuity_weight, dtype=float)
        self.segments = S
        self.simulate_kw = tuple(sorted((simulate_kw or {}).items()))
        self.name = name

    def initial_state_frees(self, index: int, *, segments="first", velocities: bool = True, coords=None):
        """:class:`Free` entries for the start states of this data object, ``index`` being its
        position in the data sequence passed to :func:`fit`. ``segments``: ``"first"`` (unknown
        initial state) or ``"all"`` (multiple shooting); ``coords``: optional index list of the
        coordinates to free (default all)."""
        from ._fit import Free

        rows = slice(0, 1) if segments == "first" else slice(None)
        cols = slice(None) if coords is None else np.asarray(coords)
        ix = (rows, cols) if coords is None else np.ix_(np.arange(self.segments)[rows], np.asarray(coords))
        out = [Free(f"{self.name}.x0", lambda d: d[index].x0s, index=ix, on="data")]
        if velocities:
            out.append(Free(f"{self.name}.xd0", lambda d: d[index].xd0s, index=ix, on="data"))
        return out

    def _simulate(self, model):
        import diffrax

        from .._simulate import simulate

        kw = dict(self.simulate_kw)
        kw.setdefault("adjoint", diffrax.ForwardMode())
        kw.setdefault("throw", False)
        S = self.segments
        L = self.ts.shape[0] // S
        names = tuple(self.measured)
        want = names + (("x", "xd", "z") if S > 1 else ())
        tseg = self.ts.reshape(S, L)
        # Each segment integrates to the next segment's first sample, for the continuity residual.
        t_next = jnp.concatenate([tseg[1:, 0], self.ts[-1:] + (self.ts[-1] - self.ts[-2])])
        grid = jnp.concatenate([tseg, t_next[:, None]], axis=1)

        def one(tt, x0, xd0, z0):
            r = simulate(model, tt, x0, xd0, z0 if z0.shape[0] else None, inputs=self.inputs, outputs=want, **kw)
            return r.outputs

        if S == 1:
            # one segment: no vmap (batching the solver's while loops retraces their bodies until
            # the batched carries settle; that was 60 % of the trace, and jacfwd batches it again)
            out = jax.tree.map(lambda v: v[None], one(grid[0], self.x0s[0], self.xd0s[0], self.z0s[0]))
        else:
            out = jax.vmap(one)(grid, self.x0s, self.xd0s, self.z0s)
        pred = {k: out[k][:, :L].reshape((S * L,) + out[k].shape[2:]) for k in names}
        cont = None
        if S > 1:
            cont = (out["x"][:-1, L] - self.x0s[1:], out["xd"][:-1, L] - self.xd0s[1:],
                    out["z"][:-1, L] - self.z0s[1:] if self.z0s.shape[1] else jnp.zeros((S - 1, 0)))
        return pred, cont

    def predict(self, model):
        """Simulated outputs, dict name -> (N, ...)."""
        return self._simulate(model)[0]

    def residuals(self, model):
        pred, cont = self._simulate(model)
        out = {}
        for k, meas in self.measured.items():
            scale = jnp.maximum(jnp.std(meas, axis=0), 1e-300) * jnp.sqrt(meas.shape[0])
            out[f"{self.name}:{k}"] = self.weights[k] * ((pred[k] - meas) / scale).ravel()
        if cont is not None:
            # States scaled by their spread over the shooting nodes, so that every coordinate counts.
            for lab, c, ref in zip(("x", "xd", "z"), cont, (self.x0s, self.xd0s, self.z0s)):
                if c.shape[1]:
                    sc = jnp.maximum(jnp.std(ref, axis=0), 1e-9) * jnp.sqrt(c.shape[0])
                    out[f"{self.name}:continuity_{lab}"] = self.continuity_weight * (c / sc).ravel()
        return out

    def nrmse(self, model):
        pred = self.predict(model)
        return {f"{self.name}:{k}": jnp.mean(_nrmse(pred[k], meas)) for k, meas in self.measured.items()}

    def nrmse_from_residuals(self, residuals: dict) -> dict | None:
        # each column's residual is w (pred - meas) / (std sqrt(N)): its 2-norm over the samples
        # is w times that column's NRMSE (saves fit a second compiled simulation)
        out = {}
        for k, meas in self.measured.items():
            w = np.asarray(self.weights[k])
            if not np.all(w != 0):
                return None
            r = np.asarray(residuals[f"{self.name}:{k}"]).reshape(meas.shape) / w
            out[f"{self.name}:{k}"] = float(np.mean(np.sqrt(np.sum(r.reshape(meas.shape[0], -1) ** 2, axis=0))))
        return out
