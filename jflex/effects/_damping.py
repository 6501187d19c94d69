"""Damping laws and linear damping effects.

A *damping law* maps a deformation vector ``e`` (m,) with its stiffness matrix ``K`` (m, m) to a
resisting force ``F`` (m,) (the generalised force on ``e`` is ``-F``), possibly with internal
states. Laws are used by :class:`StructuralDamping` (any coordinates, constant ``K``) and by
:class:`jflex.effects.FlexibleLink` (its beam stiffness, which varies with a sliding link's
length). Each law also gives its exact frequency-domain term, which
:func:`jflex.dynamic_stiffness` adds to what linearising the time-domain force already gives.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import ParameterError, ShapeError
from ._base import AbstractEffect, Slots


def _pos(v, name, strict=False):
    a = np.asarray(v, dtype=float)
    if not np.all(np.isfinite(a)) or (np.any(a <= 0) if strict else np.any(a < 0)):
        raise ParameterError(f"{name} must be finite and {'> 0' if strict else '>= 0'}, got {v}")
    return jnp.asarray(a)


class AbstractDampingLaw(eqx.Module):
    """Resisting force ``F(K, e, ed, z)`` of a structural damping law on deformations ``e`` (m,).

    ``P`` (r, m) projects ``e`` onto the displacements a displacement-driven law (hysteresis)
    acts on (default identity); the force returned is already mapped back, ``P^T F_r``.

    Class attributes a law may set, read by the analyses that try laws as candidates
    (:func:`jflex.gap.diagnose`), so that a law written here becomes one with no edit there:

    - ``loss``: the leaf that scales the law's small-motion loss linearly (``k_e``, ``eta``);
    - ``candidate``: the name under which the law is tried (None: never tried, e.g. the default
      Kelvin-Voigt law every spring already has);
    - ``shape``: ``(leaf, low, high)`` of a structural exponent the fit refines within bounds
      (the fractional order), or None;
    - :meth:`prototypes`: the law with unit loss, one per start value of its exponent;
    - ``signature``: what the law's loss looks like in measured data (a report's hint).
    """

    loss: ClassVar[str | None] = None
    candidate: ClassVar[str | None] = None
    shape: ClassVar[tuple | None] = None
    signature: ClassVar[str] = ""

    @classmethod
    def prototypes(cls) -> tuple:
        return ()

    def state_suffixes(self, m: int, r: int) -> tuple[str, ...]:
        return ()

    def initial_state(self, m: int, r: int):
        return jnp.zeros(len(self.state_suffixes(m, r)))

    def force(self, K, e, ed, z, P):
        raise NotImplementedError

    def state_rate(self, K, e, ed, z, P):
        return jnp.zeros(len(self.state_suffixes(e.shape[0], P.shape[0])))

    def frequency_term(self, K, omega, P):
        """Exact complex dynamic stiffness (m, m) at ``omega`` [rad/s] minus what the
        linearisation of :meth:`force` (with states frozen) already contributes; ``None``: nothing."""
        return None


def _registered(cls, out):
    for sub in cls.__subclasses__():
        out.append(sub)
        _registered(sub, out)
    return out


def damping_laws() -> tuple:
    """Every damping law class defined so far (the built-in ones and any a user imported) that
    names itself a ``candidate``."""
    return tuple(c for c in dict.fromkeys(_registered(AbstractDampingLaw, [])) if c.candidate)


def complex_modulus(law: AbstractDampingLaw, omega) -> jnp.ndarray:
    """Small-motion complex stiffness (F,) of a spring of unit stiffness on one coordinate with
    ``law``, at angular frequencies ``omega`` (F,) [rad/s]: ``1 + dF/de + i omega dF/d(ed)`` at rest
    (states at their initial values) plus the law's exact :meth:`~AbstractDampingLaw.frequency_term`,
    i.e. what :func:`jflex.dynamic_stiffness` gives a :class:`Spring` with this law."""
    return _complex_modulus(law, jnp.atleast_1d(jnp.asarray(omega, dtype=float)))


@eqx.filter_jit
def _complex_modulus(law, w):
    K, P, e0 = jnp.ones((1, 1)), jnp.eye(1), jnp.zeros(1)
    z0 = law.initial_state(1, 1)
    ke = jax.jacfwd(lambda e: law.force(K, e, e0, z0, P))(e0)[0, 0]
    ce = jax.jacfwd(lambda v: law.force(K, e0, v, z0, P))(e0)[0, 0]
    out = 1.0 + ke + 1j * w * ce
    if law.frequency_term(K, 1.0, P) is not None:
        out = out + jax.vmap(lambda wi: law.frequency_term(K, wi, P)[0, 0])(w)
    return out


class KelvinVoigt(AbstractDampingLaw):
    """Stiffness-proportional (Kelvin-Voigt) damping ``F = k_e K ed`` (Eq. 14 of "Numerical Implementation and Comparison Between the Viscous, Fractional and Hysteretic Damping Models of a Rigid-Flexible Planar Manipulator").

    **Arguments:** ``k_e`` [s]: the retardation time ``sigma = E (eps + k_e d eps/dt)``; for a
    Kelvin-Voigt coefficient ``K_v`` [Pa s] of "Analytical and experimental investigation of the dynamic behavior of a revolute-prismatic manipulator with N flexible links and hubs", ``k_e = K_v / E``.
    """

    k_e: jnp.ndarray
    loss: ClassVar[str] = "k_e"

    def __init__(self, k_e):
        self.k_e = _pos(k_e, "KelvinVoigt.k_e")

    @classmethod
    def prototypes(cls) -> tuple:
        return (cls(1.0),)

    def force(self, K, e, ed, z, P):
        return self.k_e * (K @ ed)


class StructuralDamping(AbstractEffect):
    """A damping law on chosen coordinates with a constant stiffness matrix.

    **Arguments:** ``coords`` indices into the model's ``x`` (static); ``stiffness`` (m, m)
    [N/m or N m/rad]; ``law``: an :class:`AbstractDampingLaw`; ``name`` prefixes its state names.
    """

    stiffness: jnp.ndarray
    law: AbstractDampingLaw
    coords: tuple[int, ...] = eqx.field(static=True)
    name: str = eqx.field(static=True, default="damping")

    def __check_init__(self):
        m = len(self.coords)
        if jnp.shape(self.stiffness) != (m, m):
            raise ShapeError(f"StructuralDamping.stiffness: expected shape ({m}, {m}) for coords {self.coords}, got {jnp.shape(self.stiffness)}")

    def _P(self):
        return jnp.eye(len(self.coords))

    def state_names(self, robot):
        m = len(self.coords)
        return tuple(f"{self.name}.{s}" for s in self.law.state_suffixes(m, m))

    def initial_state(self, robot, slots: Slots):
        m = len(self.coords)
        return self.law.initial_state(m, m)

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        idx = jnp.array(self.coords)
        F = self.law.force(self.stiffness, x[idx], xd[idx], z[slots.states], self._P())
        return jnp.zeros(slots.nx).at[idx].add(-F)

    def state_rate(self, robot, slots: Slots, t, x, xd, z):
        idx = jnp.array(self.coords)
        return self.law.state_rate(self.stiffness, x[idx], xd[idx], z[slots.states], self._P())

    def dynamic_stiffness(self, robot, slots: Slots, x0, omega):
        D = self.law.frequency_term(self.stiffness, omega, self._P())
        if D is None:
            return None
        idx = jnp.array(self.coords)
        return jnp.zeros((slots.nx, slots.nx), complex).at[jnp.ix_(idx, idx)].add(D)


class ViscousDamping(AbstractEffect):
    """Linear viscous damping ``f = -C xd`` on chosen coordinates.

    **Arguments:** ``coords`` indices into ``x`` (static); ``C`` (m, m) [N s/m or N m s/rad],
    symmetric positive semi-definite (or (m,) for a diagonal).
    """

    C: jnp.ndarray
    coords: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, coords, C):
        self.coords = tuple(int(i) for i in coords)
        m = len(self.coords)
        C = jnp.asarray(C, dtype=float)
        if C.shape == (m,):
            C = jnp.diag(C)
        if C.shape != (m, m):
            raise ShapeError(f"ViscousDamping.C: expected ({m},) or ({m}, {m}), got {C.shape}")
        try:
            Cn = np.asarray(C)
        except Exception:  # traced (fitting, gradients): values were checked where they were concrete
            Cn = None
        if Cn is not None and (not np.all(np.isfinite(Cn)) or np.linalg.eigvalsh(0.5 * (Cn + Cn.T)).min() < -1e-12 * max(1.0, np.abs(Cn).max())):
            raise ParameterError("ViscousDamping.C must be finite and positive semi-definite (a damper that adds energy is non-physical)")
        self.C = jnp.asarray(C)

    def generalized_force(self, robot, slots: Slots, t, x, xd, z):
        idx = jnp.array(self.coords)
        return jnp.zeros(slots.nx).at[idx].add(-self.C @ xd[idx])


def rayleigh_damping(model, x0, alpha, beta, coords=None) -> ViscousDamping:
    """Rayleigh damping ``C = alpha M + beta K`` of ``model`` linearised at posture ``x0``.

    **Arguments:** ``alpha`` [1/s], ``beta`` [s]; ``coords``: names (or indices) of the
    coordinates it acts on (default all). ``K`` is the linearised stiffness (gravity stiffness
    included). **Returns:** a :class:`ViscousDamping` to add to the model.
    """
    from .._model import linearize

    if float(alpha) < 0 or float(beta) < 0:
        raise ParameterError(f"rayleigh_damping: alpha and beta must be >= 0, got {alpha}, {beta}")
    lay = model.layout
    idx = list(range(lay.nx)) if coords is None else list(lay.indices(coords, "rayleigh_damping: "))
    lin = linearize(model, x0)
    ii = np.ix_(idx, idx)
    C = float(alpha) * np.asarray(lin.M)[ii] + float(beta) * np.asarray(lin.K)[ii]
    return ViscousDamping(idx, 0.5 * (C + C.T))


def coordinate_indices(model, names) -> tuple[int, ...]:
    """Indices of named coordinates in a model's ``x`` (named error for an unknown one)."""
    return model.layout.indices(names)
