"""Candidates only a simulation shows: a flexible joint seen in output-error (tip) training data,
refitted through :func:`jflex.identify.fit` over :func:`jflex.simulate`.

A joint's spring with the motor's inertia on its far side changes where the tool goes under the
applied torques, but no linear column of the measured motion holds it when the motion is not
measured (tip coordinates only). So the candidate model, the current simulation model
(:func:`._response.simulation_model`) with a :class:`jflex.effects.FlexibleJoints` spring at the
joint, is fitted to the training records as output error. Every joint's candidate is screened by
simulation alone: stiffness x damping ratio on a grid, then a finer one around its best (the
misfit has local minima where the spring's mode crosses the motion's harmonics; each grid one
vmapped solve, one compiled program per joint, :func:`scan_spring`). The one the selection names is then identified (:func:`polish_spring`):
stiffness, damping (and the motor's inertia when the case does not state it) by
Levenberg-Marquardt with exact forward-mode Jacobians, each record's motor start angle free (the
spring's static preload follows the stiffness). A compiled Jacobian of the simulation costs about
15 s per structure on 2 cores: one per diagnosis, not one per joint.

Backlash inside a compliant transmission (the diagnosis' ``backlash`` at a joint whose spring the
simulation holds) is the same spring with play: :class:`jflex.effects.FlexibleJoints` ``play``,
the spring torque ``k dz(theta - q, b) + c (theta_dot - q_dot)``. It is tried once a spring is
placed at the joint (selected, or nominal): screened on a grid of play x stiffness around the
placed spring (:func:`scan_play`; the spring fitted without play is softer, as it averages the
free travel into its stiffness), then identified like the spring with the play free too, before
it is judged (a screened play's held-out gap hung on the grid: with one more stiffness in the
grid it went from 0.53 % to 2.10 % against the spring's 0.65 %, on the independent bench's play case). A
spring alone and a spring with play are nested: the play pays its parameter only when the free
travel across the gap shows in the records.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._dynamics import crba
from ..._fold import fold_kinematics
from ..._simulate import simulate
from ...effects import FlexibleJoints
from ...identify import Free, Log, ParameterSpec, TimeData, fit, levenberg_marquardt
from ..._inputs import Sampled
from . import _response as R

K_GRID = 17  # stiffnesses scanned (log-spaced) before the local fit
BASINS = 2  # starts of the identification: the best of the scan and the best of another basin in k
OTHER_BASIN = 3.0  # ... identified only when its start's training cost is within this factor of the first's result
MAX_STEPS = 10  # Levenberg-Marquardt steps of the local fit (each: one forward-mode simulation per parameter)
ZETAS = (0.01, 0.02, 0.04, 0.08, 0.15, 0.3)  # damping ratios of the spring's own mode scanned with the stiffness
# the screenings' solver tolerances: a grid point is a start, ranked by its training cost (the
# records' noise is ~1e-4 of their spread); identification and held-out evaluation solve at
# _response.RTOL / ATOL (on the independent bench's play case the spring screened at joint 3 is the same grid
# point, and a screening takes 4-6 s less)
SCREEN_RTOL, SCREEN_ATOL = 1e-5, 1e-7
PLAYS = tuple(np.geomspace(2e-3 / 8, 6.4e-2, 17))  # [rad] half-widths of the play screened (0.25-64 mrad)
PLAY_K = tuple(np.geomspace(0.7, 2.8, 6))  # the placed spring's stiffness scaled by these with each play
# (len(PLAY_K) x len(PLAYS) = K_GRID x len(ZETAS): the play screening runs the program of the spring's)


def time_data(s: R.ResponseSet, x0, name: str):
    """A :class:`jflex.identify.TimeData` of one response set (None when a frame output has only
    some of its coordinates recorded: the fit compares whole outputs)."""
    outs = {}
    for i, o in enumerate(s.outputs):
        cols = [(c, comp) for c, (k, comp) in enumerate(s.picks) if k == i]
        if cols[0][1] is None:
            outs[o] = s.y[:, cols[0][0]]
        elif sorted(comp for _, comp in cols) == [0, 1, 2]:
            outs[o] = s.y[:, [c for c, _ in sorted(cols, key=lambda t: t[1])]]
        else:
            return None
    kw = dict(rtol=R.RTOL, atol=R.ATOL, max_steps=R.MAX_STEPS)
    return TimeData(s.t, outs, x0, inputs=Sampled(s.t, s.tau), simulate_kw=kw, name=name)


def _spring_effect(model):
    return next((i, e) for i, e in enumerate(model.effects) if isinstance(e, FlexibleJoints))


def _model(robot, tfit, springs, rotor, j, k, c, im, b=None):
    sp = dict(springs)
    sp[j] = (k, c, im) if b is None else (k, c, im, b)
    return R.simulation_model(robot, tfit, sp, rotor)


@fold_kinematics
def _solve_batch(model, i, slot, ks, cs, ims, ts, x0s, inputs, outputs, bs):
    def one(k, c, im, x0, b, ts):
        fj = model.effects[i]
        m = eqx.tree_at(lambda m: (m.effects[i].stiffness, m.effects[i].damping, m.effects[i].rotor_inertia, m.effects[i].play),
                        model, (fj.stiffness.at[slot].set(k), fj.damping.at[slot].set(c), fj.rotor_inertia.at[slot].set(im),
                                fj.play.at[slot].set(b)))
        return simulate(m, ts, x0, inputs=inputs, outputs=outputs, rtol=SCREEN_RTOL, atol=SCREEN_ATOL, max_steps=R.MAX_STEPS,
                        throw=False).outputs

    # the times batched too: the solver's step times then start batched, and vmap's fixed point over
    # the while loops' carries settles in fewer retracings of their bodies (trace 9.0 -> 6.4 s, the same numbers)
    return jax.vmap(one)(ks, cs, ims, x0s, bs, jnp.broadcast_to(ts, ks.shape + ts.shape))


def _grid_costs(robot, tfit, springs, rotor, j, ks, cs, ims, sets, bs=None) -> np.ndarray:
    """Training costs of the springs ``(ks[b], cs[b])`` with motor inertias ``ims`` (scalar or
    (B,)) at joint ``j``: one vmapped simulation per record for the whole batch, the spring's
    leaves set inside the compiled program (a model built per grid point cost more than its
    simulation; one solve each was 14x slower on a 3-joint arm, bit for bit the same). The
    motor's rest angle of each spring follows its stiffness (the static joint torque does not
    depend on it). ``bs`` (B,): the play of each spring [rad] (None: a spring without play, the
    same program with play 0)."""
    ks = np.asarray(ks, float)
    cs = np.asarray(cs, float)
    ims = np.broadcast_to(np.asarray(ims, float), ks.shape)
    bs = np.zeros(ks.shape) if bs is None else np.asarray(bs, float)
    model = _model(robot, tfit, springs, rotor, j, ks[0], cs[0], ims[0], float(bs[0]))
    i, fj = _spring_effect(model)
    slot = list(fj.joints).index(j)
    total = np.zeros(len(ks))
    for s in sets:
        tau = R.static_torque(model, s.q0)
        x0s = np.tile(np.asarray(R.rest_coords(model, s.q0, tau), float), (len(ks), 1))
        x0s[:, robot.nq + slot] = s.q0[j] + R.rest_deflection(tau[j], ks, bs, float(fj.play_smoothing))
        out = _solve_batch(model, i, slot, jnp.asarray(ks), jnp.asarray(cs), jnp.asarray(ims), jnp.asarray(s.t),
                           jnp.asarray(x0s), Sampled(s.t, s.tau), s.outputs, jnp.asarray(bs))
        e, _ = R.error(R.channels(out, s), s)
        total += np.sum(e**2, axis=(1, 2))
    return total


def _coarse_then_fine(la, lb, costs):
    """The grid ``la x lb`` (log axes), then a finer grid of the same size (the same compiled
    program) around its best, one coarse step either side in each: ``[(A, B, cost)]`` for each,
    ``A, B`` the grid points (raveled), ``cost = costs(A, B)``."""
    def grid(x, y):
        A, B = (np.exp(a.ravel()) for a in np.meshgrid(x, y, indexing="ij"))
        return A, B, costs(A, B)

    coarse = grid(la, lb)
    b = int(np.argmin(coarse[2]))
    da, db = la[1] - la[0], lb[1] - lb[0]
    fine = grid(np.log(coarse[0][b]) + np.linspace(-da, da, len(la)), np.log(coarse[1][b]) + np.linspace(-db, db, len(lb)))
    return coarse, fine


def scan_spring(robot, tfit, springs: dict, rotor, j: int, sets, basins: int = 1):
    """``(k, c, I_m)`` of a spring at joint ``j`` placed on the output-error training ``sets``
    (:class:`._response.ResponseSet`), the other joints' springs ``springs`` held: a grid in
    stiffness (the spring's link-side mode from 1 Hz to a quarter of the sampling rate, log
    spaced) times damping ratio (:data:`ZETAS`), then a finer grid of the same size around its
    best (how far the spring's mode rings and where it sits trade off: at one damping ratio the
    best stiffness was 70 % off). ``I_m`` is the rotor inertia the case states in ``rotor`` (0 or
    None: unknown, a fifth of the link inertia the joint carries). Simulations only, vmapped, one
    compiled solve per joint: the screening of every joint's candidate (:func:`polish_spring`
    then identifies the one selected). ``basins`` > 1: a list of up to that many starts, the
    best first, then the best of each other local minimum of the coarse grid in k."""
    q_ref = np.asarray(sets[0].q0, float)
    m_jj = float(np.asarray(crba(robot, q_ref))[j, j])
    im = float(rotor[j]) if rotor is not None and rotor[j] > 0 else 0.2 * m_jj
    fs = 1.0 / float(np.mean(np.diff(sets[0].t)))
    lk = np.log(m_jj * (2 * np.pi * np.geomspace(1.0, 0.25 * fs, K_GRID)) ** 2)
    lz = np.log(ZETAS)

    (_, _, cost), (kf, zf, costf) = _coarse_then_fine(
        lk, lz, lambda ks, zs: _grid_costs(robot, tfit, springs, rotor, j, ks, 2 * zs * np.sqrt(ks * im), im, sets))
    dk = lk[1] - lk[0]
    bf = int(np.argmin(costf))
    best = (float(kf[bf]), float(2 * zf[bf] * np.sqrt(kf[bf] * im)), im)
    if basins <= 1:
        return best
    C = cost.reshape(K_GRID, len(ZETAS))
    per_k = C.min(axis=1)
    minima = [i for i in range(K_GRID) if all(per_k[i] < per_k[m] for m in (i - 1, i + 1) if 0 <= m < K_GRID)]
    others = sorted((per_k[i], i) for i in minima if abs(lk[i] - np.log(best[0])) > 1.5 * dk)
    out = [best]
    for _, i in others[:basins - 1]:
        z = float(np.exp(lz[int(np.argmin(C[i]))]))
        k = float(np.exp(lk[i]))
        out.append((k, 2 * z * np.sqrt(k * im), im))
    return out


def spring_at(robot, tfit, springs: dict, rotor, j: int) -> tuple:
    """``(k, c, I_m)`` of the spring at joint ``j`` as the simulation holds it (a nominal or FRF
    spring's motor inertia read from the simulation model)."""
    v = springs[j]
    if len(v) >= 3:
        return tuple(float(a) for a in v[:3])
    i, fj = _spring_effect(R.simulation_model(robot, tfit, springs, rotor))
    return float(v[0]), float(v[1]), float(np.asarray(fj.rotor_inertia)[list(fj.joints).index(j)])


def scan_play(robot, tfit, springs: dict, rotor, j: int, sets) -> list:
    """``[(k, c, I_m, b)]``: play of half-width ``b`` [rad] inside the spring the simulation holds
    at joint ``j`` (``springs[j]``), screened on the output-error training ``sets``: each play of
    :data:`PLAYS` with the spring's stiffness scaled by each of :data:`PLAY_K` (its damping with
    the square root: the same damping ratio), then a finer grid of the same size around its best,
    one vmapped solve per record each; the other springs held. :func:`polish_spring` then
    identifies it."""
    k0, c0, im = spring_at(robot, tfit, springs, rotor, j)
    # the finer grid too: the coarse grid's best alone was as far off as its step (which grid point
    # lay nearest decided whether the play paid for itself on held-out data)
    _, (F, B, cost) = _coarse_then_fine(
        np.log(PLAY_K), np.log(PLAYS),
        lambda F, B: _grid_costs(robot, tfit, springs, rotor, j, k0 * F, c0 * np.sqrt(F), im, sets, bs=B))
    b = int(np.argmin(cost))
    return [(float(k0 * F[b]), float(c0 * np.sqrt(F[b])), im, float(B[b]))]


_WHERE: dict = {}  # accessors of the free leaves, one object per leaf: specs of the same leaves compare equal


def _where(kind, i):
    if kind == "x0":
        return _WHERE.setdefault((kind, i), lambda d: d[i].x0s)
    return _WHERE.setdefault((kind, i), lambda m: getattr(m.effects[i], kind))


def polish_spring(robot, tfit, springs: dict, rotor, j: int, starts, sets) -> tuple:
    """The spring at joint ``j`` identified from each of ``starts``, ``[(k, c, I_m), ...]``
    (:func:`scan_spring`; the lowest training cost kept), on
    the training ``sets`` by :func:`jflex.identify.fit` over :func:`jflex.simulate`:
    Levenberg-Marquardt with exact forward-mode Jacobians in log k, log c (and log I_m when the
    case does not state it), each record's motor start angle free (the spring's static preload
    moves with k). Returns ``(k, c, I_m)``, or the first start when a record cannot be compared whole.
    Each identification compiles its own residual and Jacobian (:func:`jflex.identify.fit`
    keeps none across calls), so a second basin costs a second compilation: it is tried only
    when its screened cost is within OTHER_BASIN of the first's result.
    Starts ``(k, c, I_m, b)`` (:func:`scan_play`): a spring with play, ``log b`` free too; returns
    ``(k, c, I_m, b)``."""
    first = _polish_one(robot, tfit, springs, rotor, j, starts[0], sets)
    if first is None:
        return tuple(starts[0])
    if len(starts) == 1:
        return first

    def costs(items):  # training costs, padded to the scan's batch (its compiled program)
        items = list(items) + [items[0]] * (K_GRID * len(ZETAS) - len(items))
        ks, cs, ims = (np.array([it[i] for it in items]) for i in range(3))
        return _grid_costs(robot, tfit, springs, rotor, j, ks, cs, ims, sets)

    c = costs([first] + list(starts[1:]))
    found = [(c[0], first)]
    for m, start in enumerate(starts[1:], 1):
        # another basin is identified only when its start already fits within OTHER_BASIN x the
        # identified cost: one far worse at its best grid point does not hold the minimum
        if c[m] <= OTHER_BASIN * c[0]:
            out = _polish_one(robot, tfit, springs, rotor, j, start, sets)
            if out is not None:
                found.append((costs([out])[0], out))
    return min(found, key=lambda t: t[0])[1]


def _polish_one(robot, tfit, springs, rotor, j, start, sets):
    k0, c0, im0 = start[:3]
    b0 = start[3] if len(start) > 3 else None
    model = _model(robot, tfit, springs, rotor, j, k0, c0, im0, b0)
    i, fj = _spring_effect(model)
    slot = list(fj.joints).index(j)
    data = [time_data(s, R.rest_coords(model, s.q0), f"set{m}") for m, s in enumerate(sets)]
    if any(d is None for d in data):
        return None
    frees = [Free("k", _where("stiffness", i), index=slot, transform=Log()),
             Free("c", _where("damping", i), index=slot, transform=Log())]
    if not (rotor is not None and rotor[j] > 0):
        frees.append(Free("Im", _where("rotor_inertia", i), index=slot, transform=Log()))
    if b0 is not None:
        frees.append(Free("b", _where("play", i), index=slot, transform=Log()))
    frees += [Free(f"set{m}.x0", _where("x0", m), index=(0, robot.nq + slot), on="data") for m in range(len(data))]
    res = fit(model, ParameterSpec(frees), data, levenberg_marquardt(), max_steps=MAX_STEPS, progress=False, stall=5)
    e = res.model.effects[i]
    out = (float(np.asarray(e.stiffness)[slot]), float(np.asarray(e.damping)[slot]), float(np.asarray(e.rotor_inertia)[slot]))
    return out if b0 is None else out + (float(np.asarray(e.play)[slot]),)
