"""Output-error response sets of the gap diagnosis: records whose channels do not hold every
model joint (tip coordinates, a few joint angles) are compared with the model simulated under
the recorded applied torques from rest at the recorded posture ``q0``.

The simulated model is the rigid robot plus the torque-side terms fitted on the torque training
sets (:mod:`._torque`), as the laws of :mod:`jflex.effects` with the fitted coefficients (zero
where a term is absent, so that every model has the same structure), plus
the joint springs fitted on FRF/modal data (:class:`jflex.effects.FlexibleJoints`, reduced
model): the applied torque drives the motor side of a flexible joint, which carries the joint's
rotor inertia; the spring carries it to the link. Every candidate and every step of the forward
selection with the same set of flexible joints reuses one compiled solve. Terms that act on what
a torque sensor or a motor encoder reads rather than on the motion (``sensor_delay``, the
torque side's ``backlash``) and the virtual springs (orthogonal and link compliance) are left out
of the simulation; see ``docs/case_format.md``. Backlash inside a simulated spring (the
output-error candidate of :mod:`._simulated`) is the spring's own ``play``
(:class:`jflex.effects.FlexibleJoints`), its dead zone rounded over :data:`PLAY_SMOOTHING`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..._fold import fold_kinematics
from ..._model import Model
from ..._simulate import simulate
from ..._model import model_inverse_dynamics, initial_state
from ...effects import FlexibleJoints
from ...effects._flexible_joint import smooth_dead_zone
from ..._inputs import Sampled
from .._effect_term import FamilyCoefficients
from .._inertia import tolerance_spread
from ...effects._registry import ROTOR_INERTIA

TIP_CHANNELS = {"tip_x": 0, "tip_y": 1, "tip_z": 2}  # [m] origin of the case's tool_frame, base axes
RTOL, ATOL = 1e-7, 1e-9  # the records' noise is ~1e-4 of their spread: the solver error stays far below
MAX_STEPS = 200_000
PLAY_SMOOTHING = 1e-4  # [rad] rounding of a simulated spring's dead zone: a twentieth of the least play
# the screening tries (PLAYS of ._simulated), wide enough that the adaptive solve does not crawl through each contact
FAILED_ERROR = 10.0  # normalised error (1000 %) of samples a failed or diverged solve left non-finite


def simulation_model(robot, tfit, springs=None, rotor=None) -> Model:
    """The rigid robot plus the fitted torque terms (none when ``tfit`` is None) plus the joint
    springs ``{joint: (k, c)}`` [N m/rad, N m s/rad] (or ``(k, c, I_m)``: with the motor's inertia [kg m^2];
    ``(k, c, I_m, b)``: with play of half-width ``b`` [rad] inside the transmission; the others
    hold play 0, the plain spring).

    Each term puts its own effect into the model (:meth:`._torque.TorqueTerm.contribute`): the
    laws of :mod:`jflex.effects` with the fitted coefficients, zero where a term is absent (one
    structure for every model: one compiled solve), and a user's effect as itself; terms that act
    on what a sensor reads (a delay, play seen by a motor encoder) add nothing.
    ``rotor`` (n,) [kg m^2] is rotor inertia added to the fitted one (the nominal values of a case
    without torque training data). A spring's motor side carries the joint's rotor inertia and is
    driven by the applied torque; a flexible joint without rotor inertia is left rigid (a massless
    motor passes the applied torque through its spring unchanged)."""
    parts = FamilyCoefficients(robot)
    k = 0
    for term in tfit.terms if tfit is not None else ():
        term.contribute(parts, np.asarray(tfit.theta[k:k + term.n_params], float))
        k += term.n_params
    rot = parts.coeff[ROTOR_INERTIA]  # (n,): the family's one parameter per joint
    if rotor is not None:
        rot += np.asarray(rotor, float)
    for j, v in (springs or {}).items():
        if len(v) > 2:  # a spring fitted with its motor's inertia (:mod:`._simulated`)
            rot[j] = v[2]
    flex = sorted(j for j in (springs or {}) if rot[j] > 0)
    motor = np.array([rot[j] for j in flex])
    rot[flex] = 0.0  # on the motor side of the spring
    inert = np.asarray(robot.inertia, float).copy()
    if tfit is not None and tfit.delta is not None:
        inert += tfit.delta.reshape(inert.shape)  # the nominal identification's inertial parameters
    # without torque-side terms (no torque training data) every family but the rotor inertia is
    # zero for the whole diagnosis: left out, the 3-joint arm's dynamics took 1130 operations
    # instead of 1975, which every simulated program traces and compiles
    effects = parts.effects() if tfit is not None else parts.effects((ROTOR_INERTIA,) if np.any(rot) else ())
    if flex:
        kk = np.array([springs[j][0] for j in flex], float)
        cc = np.array([springs[j][1] for j in flex], float)
        # every spring holds a play leaf (0: exactly the plain spring, its dead zone's terms cancel
        # to the bit), so that a spring with play and one without are one structure: one compiled
        # solve for the screening of a joint's spring and of the play inside it
        play = jnp.asarray([float(springs[j][3]) if len(springs[j]) > 3 else 0.0 for j in flex])
        effects.append(FlexibleJoints(jnp.asarray(kk), jnp.asarray(cc), jnp.asarray(motor), joints=flex, coupling=False,
                                      play=play, play_smoothing=PLAY_SMOOTHING))
    return Model(robot.replace(inertia=jnp.asarray(inert)), effects)


def rest_coords(model: Model, q0, tau=None) -> np.ndarray:
    """Coordinates of the model at rest at link posture ``q0``: each spring preloaded by the
    static joint torque (gravity less the fitted compensators), ``theta = q0 + tau_static / k``
    (with play: the deflection of the spring's dead zone that holds it, :func:`rest_deflection`).
    ``tau``: :func:`static_torque` at ``q0`` when the caller has it already."""
    q0 = np.asarray(q0, float)
    flex = [e for e in model.effects if isinstance(e, FlexibleJoints)]
    if not flex:
        return q0
    fj = flex[0]
    idx = list(fj.joints)
    tau = static_torque(model, q0) if tau is None else tau
    if fj.play is None:
        return np.concatenate([q0, q0[idx] + tau[idx] / np.asarray(fj.stiffness)])
    return np.concatenate([q0, q0[idx] + rest_deflection(tau[idx], np.asarray(fj.stiffness), np.asarray(fj.play),
                                                         float(fj.play_smoothing))])


def static_torque(model: Model, q0) -> np.ndarray:
    """Joint torques (n,) holding the model's links at rest at ``q0`` (gravity less the fitted
    compensators), the motors at the links' angles (an unloaded spring)."""
    q0 = np.asarray(q0, float)
    fj = next(e for e in model.effects if isinstance(e, FlexibleJoints))
    x = jnp.asarray(np.concatenate([q0, q0[list(fj.joints)]]))
    return np.asarray(_static_torque(model, x))[: len(q0)]


@fold_kinematics
def _static_torque(model, x):
    # compiled: run op by op, the first calls compiled each of the dynamics' primitives on its own
    # (7 s of a spring screening on a 3-joint arm)
    z = jnp.zeros(x.shape[0])
    return model_inverse_dynamics(model, 0.0, x, z, z, initial_state(model))


def rest_deflection(torque, k, b, eps) -> np.ndarray:
    """Deflection ``d`` (broadcast shape) of a spring with play at which it holds ``torque``:
    ``k smooth_dead_zone(d, b, eps) = torque`` (:func:`jflex.effects._flexible_joint.smooth_dead_zone`,
    monotone), by bisection on ``[tau/k - b, tau/k + b]``; exactly ``torque / k`` where ``b = 0``."""
    y = np.asarray(torque, float) / np.asarray(k, float)
    b = np.broadcast_to(np.asarray(b, float), y.shape)
    if not np.any(b > 0):  # (every simulated spring holds a play leaf: most are 0)
        return y
    lo, hi = y - b, y + b
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        above = np.asarray(smooth_dead_zone(jnp.asarray(mid), jnp.asarray(b), eps)) > y
        hi, lo = np.where(above, mid, hi), np.where(above, lo, mid)
    return np.where(b > 0, 0.5 * (lo + hi), y)


@dataclasses.dataclass
class ResponseSet:
    """One output-error record: ``y`` (N, k) at ``t`` under ``tau`` from rest at ``q0``."""

    name: str
    t: np.ndarray
    tau: np.ndarray
    y: np.ndarray
    channels: tuple
    q0: np.ndarray
    outputs: tuple  # simulate output names, one per distinct output
    picks: tuple  # per channel: (index into outputs, component or None)
    scale: np.ndarray  # (k,) normalisation of each channel [m or rad]: std of a joint channel, the
    # tip's RMS distance from its mean position for every tip channel


def response_set(robot, ds, tool_frame) -> ResponseSet:
    a = ds.arrays
    ch = tuple(a["channels"])
    outputs, picks = [], []
    for c in ch:
        name = f"frame:{tool_frame}" if c in TIP_CHANNELS else c
        if name not in outputs:
            outputs.append(name)
        picks.append((outputs.index(name), TIP_CHANNELS.get(c)))
    y = a["y"]
    sd = y.std(axis=0)
    tip = [i for i, c in enumerate(ch) if c in TIP_CHANNELS]
    scale = np.maximum(sd, 1e-12)
    if tip:
        # one scale for the tip coordinates, the RMS distance of the tip from its mean position: an
        # error counts the same in every direction, and a coordinate the motion hardly moves (x of
        # a sweep in the y-z plane) does not turn its noise or a small drift into the gap
        scale[tip] = np.sqrt(np.sum(sd[tip] ** 2))
    return ResponseSet(ds.name, a["t"], a["tau"], y, ch, a["q0"], tuple(outputs), tuple(picks), np.maximum(scale, 1e-12))


@fold_kinematics
def _solve(model, ts, x0, inputs, outputs):
    r = simulate(model, ts, x0, inputs=inputs, outputs=outputs, rtol=RTOL, atol=ATOL, max_steps=MAX_STEPS, throw=False)
    return r.outputs


def channels(out: dict, s: ResponseSet) -> np.ndarray:
    """The set's channels (..., N, k) from simulated outputs ``{name: (..., N, ...)}``."""
    cols = []
    for i, comp in s.picks:
        v = np.asarray(out[s.outputs[i]])
        cols.append(v if comp is None else v[..., comp])
    return np.stack(cols, axis=-1)


def predict(model: Model, s: ResponseSet) -> np.ndarray:
    """Simulated channels (N, k); NaN where the solve failed."""
    return channels(_solve(model, jnp.asarray(s.t), jnp.asarray(rest_coords(model, s.q0)), Sampled(s.t, s.tau), s.outputs), s)


def error(pred, s: ResponseSet) -> tuple[np.ndarray, np.ndarray]:
    """Normalised output error (..., N, k) of predicted channels, and per record (...) the number
    of samples a failed solve left non-finite or a diverged one put beyond ``FAILED_ERROR`` (1000 %
    of the channel's scale); their error is capped there."""
    e = (pred - s.y) / s.scale
    bad = ~np.all(np.isfinite(e) & (np.abs(np.nan_to_num(e)) <= FAILED_ERROR), axis=-1)
    e = np.clip(np.nan_to_num(e, nan=FAILED_ERROR, posinf=FAILED_ERROR, neginf=-FAILED_ERROR), -FAILED_ERROR, FAILED_ERROR)
    return e, bad.sum(axis=-1)


def residual(model: Model, s: ResponseSet) -> tuple[np.ndarray, int]:
    """:func:`error` of the model's simulation of ``s``."""
    e, bad = error(predict(model, s), s)
    return e, int(bad)


def cad_spread(robot, tfit, springs, rotor, sets, prior, step: float = 1e-3) -> dict:
    """Per output-error set in ``sets``: the spread [% NRMSE, one std] of its gap that the CAD
    inertias' tolerance alone gives (``u ~ N(0, I)``, ``delta = s u``, ``s`` the prior's scale), to
    first order (:func:`._inertia.tolerance_spread`), one simulation per inertial parameter (the
    inertias are leaves: one compiled solve). Tool positions alone cannot identify the inertias,
    and an open-loop record carries their error along it (a few per cent of mass made a gap of
    50 % on the 3-joint arm's 1 s records): a gap of this size does not fault the model."""
    P0 = np.asarray(robot.inertia, float)

    def residuals(delta):
        m = simulation_model(robot.replace(inertia=jnp.asarray(P0 + delta.reshape(P0.shape))), tfit, springs, rotor)
        out = {}
        for st in sets:
            e = residual(m, st)[0]
            out[st.name] = e.ravel() / np.sqrt(e.size)  # (sum of squares: the NRMSE^2)
        return out

    return tolerance_spread(prior, residuals, step)
