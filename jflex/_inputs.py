"""Input signals for :func:`jflex.simulate`: steps, ramps, chirps, brakes and sampled data.

Each signal is a pytree ``u(t) -> (nu,)`` that also declares its discontinuities
(:meth:`AbstractInput.jump_times`), so the step controller lands a step exactly on them
instead of smearing or missing them. Amplitudes are per-actuator vectors, so one signal can
drive any subset of actuators; signals add with ``+``.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._errors import ParameterError, ShapeError


def _vec(a, name):
    a = jnp.atleast_1d(jnp.asarray(a, dtype=float))
    if a.ndim != 1:
        raise ShapeError(f"{name}: expected a vector (one entry per actuator), got shape {a.shape}")
    return a


def _concrete(x):
    try:
        return np.atleast_1d(np.asarray(x, dtype=float))
    except Exception:  # traced: the caller must pass jump times explicitly
        return None


class AbstractInput(eqx.Module):
    """A time signal ``u(t)`` of shape (nu,)."""

    def __call__(self, t):
        raise NotImplementedError

    def jump_times(self) -> tuple:
        """Times [s] at which ``u`` (or its derivative) is discontinuous; static floats."""
        return ()

    def __add__(self, other):
        return Sum((self, other))


class Sum(AbstractInput):
    """The sum of several signals (same ``nu``)."""

    parts: tuple

    def __call__(self, t):
        out = self.parts[0](t)
        for p in self.parts[1:]:
            out = out + p(t)
        return out

    def jump_times(self):
        return tuple(sorted(set(j for p in self.parts for j in p.jump_times())))

    def __add__(self, other):
        return Sum(self.parts + (other,))


class Zero(AbstractInput):
    """No input: ``u = 0`` (nu,)."""

    nu: int = eqx.field(static=True)

    def __call__(self, t):
        return jnp.zeros(self.nu)


class Step(AbstractInput):
    """``amplitude`` from ``t0`` on (until ``t1``, default forever), zero before.

    **Arguments:** ``amplitude`` (nu,) [N m or N], ``t0``, ``t1`` [s].
    """

    amplitude: jnp.ndarray
    t0: jnp.ndarray
    t1: jnp.ndarray

    def __init__(self, amplitude, t0=0.0, t1=jnp.inf):
        self.amplitude = _vec(amplitude, "Step.amplitude")
        self.t0 = jnp.asarray(t0, dtype=float)
        self.t1 = jnp.asarray(t1, dtype=float)
        if _concrete(t0) is not None and _concrete(t1) is not None and float(t1) <= float(t0):
            raise ParameterError(f"Step: t1 ({float(t1)} s) must be after t0 ({float(t0)} s)")

    def __call__(self, t):
        on = (t >= self.t0) & (t < self.t1)
        return jnp.where(on, 1.0, 0.0) * self.amplitude

    def jump_times(self):
        out = []
        for v in (self.t0, self.t1):
            c = _concrete(v)
            if c is not None and np.isfinite(c[0]):
                out.append(float(c[0]))
        return tuple(out)


def Brake(torque, t0, t1=jnp.inf) -> Step:
    """A braking torque/force applied from ``t0``: the mechanical brake of a revolute joint modelled
    as an equivalent negative torque, as in "Analytical and experimental investigation of the
    dynamic behavior of a revolute-prismatic manipulator with N flexible links and hubs". Same as
    :class:`Step`."""
    return Step(torque, t0, t1)


class Ramp(AbstractInput):
    """Linear rise from 0 at ``t0`` to ``amplitude`` at ``t1``, then held.

    **Arguments:** ``amplitude`` (nu,), ``t0 < t1`` [s].
    """

    amplitude: jnp.ndarray
    t0: jnp.ndarray
    t1: jnp.ndarray

    def __init__(self, amplitude, t0, t1):
        self.amplitude = _vec(amplitude, "Ramp.amplitude")
        self.t0 = jnp.asarray(t0, dtype=float)
        self.t1 = jnp.asarray(t1, dtype=float)
        if _concrete(t0) is not None and _concrete(t1) is not None and float(t1) <= float(t0):
            raise ParameterError(f"Ramp: t1 ({float(t1)} s) must be after t0 ({float(t0)} s)")

    def __call__(self, t):
        s = jnp.clip((t - self.t0) / (self.t1 - self.t0), 0.0, 1.0)
        return s * self.amplitude

    def jump_times(self):
        # the derivative jumps at both ends: a step there keeps high-order solvers accurate
        return tuple(float(c[0]) for c in (_concrete(self.t0), _concrete(self.t1)) if c is not None)


class Chirp(AbstractInput):
    """Linear chirp ``amplitude sin(2 pi (f0 (t-t0) + (f1-f0)(t-t0)^2 / (2 T)))`` on ``[t0, t0+T]``.

    **Arguments:** ``amplitude`` (nu,), ``f0``, ``f1`` [Hz], ``duration`` T [s], ``t0`` [s].
    """

    amplitude: jnp.ndarray
    f0: jnp.ndarray
    f1: jnp.ndarray
    duration: jnp.ndarray
    t0: jnp.ndarray

    def __init__(self, amplitude, f0, f1, duration, t0=0.0):
        self.amplitude = _vec(amplitude, "Chirp.amplitude")
        self.f0, self.f1 = jnp.asarray(f0, dtype=float), jnp.asarray(f1, dtype=float)
        self.duration, self.t0 = jnp.asarray(duration, dtype=float), jnp.asarray(t0, dtype=float)
        d = _concrete(duration)
        if d is not None and not d[0] > 0:
            raise ParameterError(f"Chirp.duration must be > 0 s, got {d[0]}")

    def __call__(self, t):
        tau = jnp.clip(t - self.t0, 0.0, self.duration)
        ph = 2 * jnp.pi * (self.f0 * tau + 0.5 * (self.f1 - self.f0) * tau**2 / self.duration)
        on = (t >= self.t0) & (t <= self.t0 + self.duration)
        return jnp.where(on, jnp.sin(ph), 0.0) * self.amplitude

    def jump_times(self):
        a, d = _concrete(self.t0), _concrete(self.duration)
        return () if a is None or d is None else (float(a[0]), float(a[0] + d[0]))


class Sampled(AbstractInput):
    """A sampled signal, linearly interpolated (``kind="linear"``) or held (``"zoh"``).

    **Arguments:** ``ts`` (N,) increasing [s]; ``values`` (N, nu). Outside ``ts`` the end values hold.
    """

    ts: jnp.ndarray
    values: jnp.ndarray
    kind: str = eqx.field(static=True)

    def __init__(self, ts, values, kind: str = "linear"):
        ts_np = np.asarray(ts, dtype=float)
        vals = np.asarray(values, dtype=float)
        if vals.ndim == 1:
            vals = vals[:, None]
        if ts_np.ndim != 1 or vals.shape[0] != ts_np.shape[0] or ts_np.size < 2:
            raise ShapeError(f"Sampled: ts must be (N,) with N >= 2 and values (N, nu); got {ts_np.shape} and {vals.shape}")
        if not np.all(np.diff(ts_np) > 0):
            raise ParameterError("Sampled.ts must be strictly increasing")
        if not np.isfinite(vals).all():
            raise ParameterError("Sampled.values contains NaN or inf")
        if kind not in ("linear", "zoh"):
            raise ParameterError(f"Sampled.kind must be 'linear' or 'zoh', got '{kind}'")
        self.ts, self.values, self.kind = jnp.asarray(ts_np), jnp.asarray(vals), kind

    def __call__(self, t):
        if self.kind == "zoh":
            k = jnp.clip(jnp.searchsorted(self.ts, t, side="right") - 1, 0, self.ts.shape[0] - 1)
            return self.values[k]
        return jnp.stack([jnp.interp(t, self.ts, self.values[:, j]) for j in range(self.values.shape[1])])

    def jump_times(self):
        # a held signal jumps at every sample; a linear one only has kinks, which the error
        # controller handles without forcing a step at each sample
        return tuple(np.asarray(self.ts).tolist()) if self.kind == "zoh" else ()


class Function(AbstractInput):
    """Any callable ``fn(t) -> (nu,)`` with declared ``jumps`` (tuple of floats [s])."""

    fn: callable = eqx.field(static=True)
    jumps: tuple = eqx.field(static=True, default=())

    def __call__(self, t):
        return jnp.asarray(self.fn(t))

    def jump_times(self):
        return tuple(float(j) for j in self.jumps)
