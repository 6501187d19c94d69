"""The damping laws of :mod:`jflex.effects` at a frequency model's sites: each law's complex modulus
with unit loss (``psi``), in which every law is linear (its loss leaf), checked once and cached on
the frequency grids a fit asks for again and again."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ...effects import KelvinVoigt, complex_modulus

VISCOUS = KelvinVoigt(1.0)  # every site's default law: the loss stiffness c_s is a viscous coefficient


def law_key(law) -> tuple:
    """A hashable key of a unit-loss law prototype: its class and structural exponent."""
    shape = type(law).shape
    return (type(law).__name__,) + ((round(float(getattr(law, shape[0])), 6),) if shape else ())


def law_name(law) -> str:
    """The law's name in reports: its candidate name, or ``viscous`` for the default."""
    return type(law).candidate or ("viscous" if isinstance(law, KelvinVoigt) else type(law).__name__)


def with_loss(law, theta):
    """The prototype ``law`` with its loss leaf set to ``theta``."""
    return eqx.tree_at(lambda l: getattr(l, type(l).loss), law, jnp.asarray(float(theta)))


def unit_loss(law, omega, tabulated: bool = False) -> np.ndarray:
    """``psi(omega)``: the law's complex modulus with unit loss, less the unit stiffness (cached on
    data grids; the law is checked once to be linear in its loss leaf).

    ``tabulated``: for the few, ever-changing frequencies of a modal iteration, interpolate
    ``log|psi|`` and the phase of ``psi`` in ``log omega`` on a dense table of the law, which is
    exact for the power laws (viscous, hysteretic, fractional) and within ~1e-5 for smooth
    others; frequencies off the table, or a law with ``psi = 0`` on it, are evaluated exactly."""
    w = np.asarray(omega, float)
    if tabulated:
        tab = _table(law)
        if tab is not None and w.size and np.all((w >= _TABLE_W[0]) & (w <= _TABLE_W[-1])):
            lw = np.log(w)
            return np.exp(np.interp(lw, _TABLE_LW, tab[0])) * np.exp(1j * np.interp(lw, _TABLE_LW, tab[1]))
    # keyed on the law object (kept alive in the value, so its id is not reused): a fit asks for
    # the same law on the same grid thousands of times
    ck = (id(law), w.shape, w.tobytes())
    hit = _PSI.get(ck)
    if hit is None:
        _check_linear(law)
        if len(_PSI) > 512:
            _PSI.clear()
        hit = _PSI[ck] = (law, (np.asarray(complex_modulus(law, w.ravel())) - 1.0).reshape(w.shape))
    return hit[1]


_TABLE_W = np.logspace(-3, 6, 4501)
_TABLE_LW = np.log(_TABLE_W)


def _table(law):
    ck = (id(law), "table")
    hit = _PSI.get(ck)
    if hit is None:
        psi = unit_loss(law, _TABLE_W)
        tab = None if np.any(psi == 0) else (np.log(np.abs(psi)), np.unwrap(np.angle(psi)))
        hit = _PSI[ck] = (law, tab)
    return hit[1]


def _check_linear(law):
    key = law_key(law)
    if key in _LINEAR_CHECKED:
        return
    if type(law).loss is None:
        raise TypeError(f"{type(law).__name__}: a damping law tried as a candidate must name its loss leaf (class attribute 'loss')")
    wt = np.array([1.0, 10.0, 100.0])
    p1 = np.asarray(complex_modulus(law, wt)) - 1.0
    p2 = np.asarray(complex_modulus(with_loss(law, 2.0), wt)) - 1.0
    if not np.allclose(p2, 2 * p1, rtol=1e-9, atol=1e-12):
        raise ValueError(f"{type(law).__name__}: its small-motion loss is not linear in '{type(law).loss}'")
    _LINEAR_CHECKED[key] = bool(np.ptp(p1.real) > 1e-12 * max(np.abs(p1).max(), 1e-300))


def frequency_dependent(law) -> bool:
    """Whether the law's storage stiffness changes with frequency (a fractional law's does)."""
    _check_linear(law)
    return _LINEAR_CHECKED[law_key(law)]


_PSI: dict = {}
_LINEAR_CHECKED: dict = {}  # law key -> frequency dependent
