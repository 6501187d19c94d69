"""The kinds of frequency-side candidate the gap diagnosis tries, one class each, and the table that
names them (:func:`frequency_kinds`), as :mod:`._torque_terms` does for the torque side.

A kind says where it is tried (:meth:`FrequencyKind.tried_at`), how many parameters it adds (the
information criterion's penalty) and how it enters a :class:`._frequency_model.FrequencyModel`
(:meth:`FrequencyKind.add`: the new structure and its fitted parameters). The elastic sites
(a joint's spring, a bearing's tilt, a link's bending) are new coordinates of the model; the tool
payload is a :class:`jflex.effects.Payload`; every damping law of :mod:`jflex.effects` that names
itself a candidate (:func:`jflex.effects.damping_laws`, a user's own among them) is a
:class:`DampingLaw` on the joint springs, read off the law's class when asked.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ...effects import damping_laws
from ...effects._registry import JOINT_FLEXIBILITY, LINK_FLEXIBILITY, ORTHOGONAL_COMPLIANCE, PAYLOAD, SITE_EFFECTS
from . import _model as L


def law_candidates() -> dict:
    """``{candidate name: law class}``, read when asked (a law defined after import counts too)."""
    return {c.candidate: c for c in damping_laws()}


class FrequencyKind:
    """A frequency-side candidate kind. ``per_joint``: tried at each joint (else once, ``joint``
    None); ``on_link``: its index is a link's (a link's bending), not a joint's."""

    name: str = ""
    per_joint: bool = True
    on_link: bool = False
    n_params: int = 1
    signature: str = ""

    def tried_at(self, pb, joint, flexible: set) -> bool:
        """Whether the candidate is tried at ``joint`` (``flexible``: the nominally flexible joints)."""
        return True

    def params(self, pb) -> int:
        """The parameters it adds on ``pb``'s training data (:attr:`n_params` unless the data decide)."""
        return self.n_params

    def add(self, pb, lm, x, joint):
        """``(model, x)``: ``lm`` with this candidate added at ``joint``, refitted on ``pb.ftrain``
        from ``x``."""
        raise NotImplementedError


class NewSites(FrequencyKind):
    """New elastic coordinates, each a spring with the default (viscous) damping law."""

    signature = "extra FRF peak / unmatched mode"

    def sites(self, joint) -> list:
        raise NotImplementedError

    def add(self, pb, lm, x, joint):
        return add_sites(pb, lm, x, self.sites(joint))


class JointSpring(NewSites):
    """A joint the nominal model holds rigid, made flexible (its link side a new coordinate)."""

    name = JOINT_FLEXIBILITY
    n_params = 2

    def tried_at(self, pb, joint, flexible):
        return joint not in flexible

    def sites(self, joint):
        return [L.Site("joint", joint)]


class BearingTilt(NewSites):
    """A bearing's tilt stiffness: a full 2x2 (coupled) stiffness about the two axes perpendicular
    to the joint's rotation axis."""

    name = ORTHOGONAL_COMPLIANCE
    n_params = 4

    def sites(self, joint):
        return [L.Site("orth", joint, 0), L.Site("orth", joint, 1, coupled=True)]


class LinkBending(NewSites):
    """A link's first bending mode, lumped: two coupled hinges half-way along the link."""

    name = LINK_FLEXIBILITY
    n_params = 4
    on_link = True

    def sites(self, joint):
        return [L.Site("link", joint, 0), L.Site("link", joint, 1, coupled=True)]


class ToolPayload(FrequencyKind):
    """A rigid body at the tool (:class:`jflex.effects.Payload`), tried on frequency data alone:
    on FRFs its mass and its centre of mass in the tool frame (:attr:`n_params`; 10 would free its
    rotational inertia too), every value a physical body (:func:`._frequency_model.payload_inertia`);
    on modal tables alone its mass at the tool frame's origin (:attr:`MODAL_PARAMS`). (Torque data
    identify a payload's 10 inertial parameters: :mod:`._torque_terms`.)

    A few modes per posture do not pin a centre of mass: on the independent modal payload case
    (3 modes at 3 training postures, 1 % frequency noise) mass and centre of mass left the held-out
    gap at 2.23 % where the mass alone reached 1.68 % (the noise floor), and its three more
    parameters cost it the selection. On FRFs the centre of mass took the independent FRF payload
    case from 79 % to 98 % of the excess gap closed (benchmarks/bench_gap_independent.py;
    mass 2.278 kg for 2.278). Its rotational inertia freed too (10 parameters) closed 96 %, named
    two more effects that are not there and ran 297 s against 116 s (load ~6 on 2 cores): a sphere
    of a few centimetres adds a fraction of the lever arm's inertia, which two postures' FRFs do
    not pin."""

    name = PAYLOAD
    per_joint = False
    n_params = 4  # on FRF data, of _frequency_model.PAYLOAD_NAMES: mass and centre of mass
    MODAL_PARAMS = 1  # on modal tables alone: the mass
    STARTS = (0.1, 1.0, 10.0)  # [kg] the mass's starts

    def tried_at(self, pb, joint, flexible):
        return self.name not in {e for e, _ in pb.nominal} and not pb.ttrain

    def params(self, pb):
        return self.n_params if any(d.kind == "frf" for d in pb.ftrain) else self.MODAL_PARAMS

    def add(self, pb, lm, x, joint):
        st = lm.structure
        S = len(st.springs)
        P = self.params(pb)
        ks, cs = list(x[:S]), list(x[S:2 * S])
        cpl = list(x[2 * S + int(st.payload):])
        lm2 = pb._frequency_model(lm.robot, L.Structure(st.springs, P))
        # a point mass at the tool frame's origin first (the rest of the body held), from each
        # start mass, as the springs are fitted (peaks, then the FRF); then the whole body from the
        # best, within PAYLOAD_COM_BOX of the origin
        xs = [np.concatenate([ks, cs, L.payload_start(P, m), cpl]) for m in self.STARTS]
        free = np.ones(len(xs[0]), bool)
        free[2 * S + 1:2 * S + P] = False
        x1, _ = L.fit_linear(lm2, xs[0], pb.ftrain, free=free, starts=xs[1:])
        if P == 1:
            return lm2, x1
        xf, _ = L.fit_linear(lm2, x1, pb.ftrain, peaks_first=False)
        return lm2, xf


@dataclasses.dataclass(frozen=True)
class DampingLaw(FrequencyKind):
    """A damping law of :mod:`jflex.effects` (``law``, its class) in place of the viscous damping at
    a nominally flexible joint; a law with a structural exponent (``shape``) frees it too."""

    law: type

    @property
    def name(self):
        return self.law.candidate

    @property
    def n_params(self):
        return 1 + int(self.law.shape is not None)

    @property
    def signature(self):
        return self.law.signature

    def tried_at(self, pb, joint, flexible):
        return joint in flexible and (self.name, joint) not in pb.nominal

    def add(self, pb, lm, x, joint):
        return fit_damping_law(pb, lm, x, joint, self.law)


# the kind of each site of the registry (jflex.effects._registry.SITE_EFFECTS), in its order
_BY_SITE = {"joint": JointSpring, "orth": BearingTilt, "link": LinkBending, "tool": ToolPayload}
SITE_KINDS = {name: _BY_SITE[site]() for name, site in SITE_EFFECTS.items()}


def frequency_kinds() -> dict:
    """The frequency-side candidates by name, in the order the diagnosis tries them at a joint."""
    return {**SITE_KINDS, **{name: DampingLaw(c) for name, c in law_candidates().items()}}


# --- fits -------------------------------------------------------------------------------------------
def fit_damping_law(pb, lm, x, joint, cls):
    """``lm`` with the damping law ``cls`` at the flexible ``joint``: each of the law's prototypes
    fitted, then its exponent refined (when it has one); the best fit."""
    st = lm.structure
    S = len(st.springs)
    springs = list(st.springs)
    i = next(i for i, s in enumerate(springs) if s.kind == "joint" and s.where == joint)
    shape = cls.shape
    tried = {}

    def fit_law(proto):
        key = L.law_key(proto)
        sp = list(springs)
        sp[i] = dataclasses.replace(sp[i], law=proto)
        lm2 = pb._frequency_model(lm.robot, L.Structure(tuple(sp), st.payload))
        lm2._cache = lm._cache  # same geometry and postures: the matrices carry over
        x2 = np.array(x, float)
        w = 2 * np.pi * pb._ref_freq()
        c = np.exp(x2[S + i])
        # the same loss at the reference frequency as the viscous damping it replaces is only a
        # guess (the spring's own mode may lie elsewhere): scan the new loss around it, then
        # fit everything from the best (no peaks phase: the picked peaks' half-power damping
        # is what a damping law must not chase)
        c0 = np.log(w * c / np.abs(L.unit_loss(proto, w)))
        best0 = None
        for dc in np.arange(-3.0, 3.01, 0.5):
            x2[S + i] = c0 + dc
            r = L.residual(lm2, x2, pb.ftrain, peaks=False)
            if best0 is None or r @ r < best0[0]:
                best0 = (float(r @ r), x2.copy())
        xf, cost = L.fit_linear(lm2, best0[1], pb.ftrain, peaks_first=False)
        tried[key[1] if shape else 0.0] = (cost, lm2, xf)
        return cost

    protos = cls.prototypes()
    for proto in protos:
        fit_law(proto)
    if shape is not None:
        # refine the exponent: steps of 0.1, 0.05 and 0.025 either side of the best value tried,
        # then the vertex of a parabola through the best and its (now close) neighbours (one
        # parabola through the wide grid stopped 0.07 off the fractional order)
        leaf, lo_a, hi_a = shape
        at = lambda a: eqx.tree_at(lambda l: getattr(l, leaf), protos[0], jnp.asarray(a))
        best_a = lambda: min(tried, key=lambda a: tried[a][0])
        for h in (0.1, 0.05, 0.025):
            a0 = best_a()
            for a_new in (a0 - h, a0 + h):
                a_new = round(float(np.clip(a_new, lo_a, hi_a)), 3)
                if a_new not in tried:
                    fit_law(at(a_new))
        al = sorted(tried)
        kb = min(max(al.index(best_a()), 1), len(al) - 2)
        xa = np.array(al[kb - 1:kb + 2])
        ya = np.log(np.array([tried[a][0] for a in xa]))
        cpar = np.polyfit(xa - xa[1], ya, 2)
        if cpar[0] > 0:
            a_new = round(float(np.clip(xa[1] - cpar[1] / (2 * cpar[0]), xa[0], xa[2])), 3)
            if a_new not in tried:
                fit_law(at(a_new))
    cost, lm2, xf = min(tried.values(), key=lambda t: t[0])
    return lm2, xf


def add_sites(pb, lm, x, new):
    """``lm`` with the elastic sites ``new`` added (a pair's second site coupled), fitted from a
    scan of starting stiffnesses."""
    st = lm.structure
    S = len(st.springs)
    ks, cs = list(x[:S]), list(x[S:2 * S])
    pay = list(x[2 * S:2 * S + int(st.payload)])
    cpl = list(x[2 * S + len(pay):])  # couplings of virtual pairs already in the model
    sp = list(st.springs) + list(new)
    lm2 = pb._frequency_model(lm.robot, L.Structure(tuple(sp), st.payload))
    # starting stiffnesses: the new spring(s) alone would put a mode at f_t; f_t is scanned over a
    # log grid from below the measured band to well above it (a compliance whose modes lie
    # above the band shows only as a posture-dependent static softening), both springs of a
    # pair together and each alone stiff, keeping the starts with the lowest misfit. (One start
    # at the frequency of the largest misfit put link modes far below the band, from where the
    # bounded fit could not return.)
    P = lm2.mats(pb._ref_posture())
    f_lo, f_hi = pb._freq_band()
    targets = list(np.geomspace(f_lo, 3.0 * f_hi, 12)) + pb._unmatched_freqs(lm, x)[:1]
    meff = [max(P.M[S + s, S + s], 1e-9) for s in range(len(new))]

    def start(fts):
        nk = [np.log((2 * np.pi * ft) ** 2 * m) for ft, m in zip(fts, meff)]
        nc = [np.log(2 * 0.02 * np.sqrt(np.exp(k) * m)) for k, m in zip(nk, meff)]
        return np.concatenate([ks, nk, cs, nc, pay, cpl, np.zeros(len(new) - 1)])

    grid = [[ft] * len(new) for ft in targets]
    if len(new) == 2:
        grid += [[ft, 10 * f_hi] for ft in targets] + [[10 * f_hi, ft] for ft in targets]
    scored = []
    for fts in grid:
        xs = start(fts)
        r = L.residual(lm2, xs, pb.ftrain, peaks=False)
        scored.append((float(r @ r), len(scored), xs))
    scored.sort(key=lambda t: t[:2])
    starts = [t[2] for t in scored[:2]]
    # and the new modes near the measured mode the model misses most (where the nominal fit is
    # far off, the grid's misfit says little: a peaks phase first sorts the modes out)
    P0 = P.M[:S, :S]
    for ft in pb._unmatched_freqs(lm, x)[:1]:
        for scale in (0.6, 1.6):
            nk, nc = [], []
            for s in range(len(new)):
                ii = S + s
                # (pinv: a site carrying no inertia of its own leaves P0 singular)
                me = max(P.M[ii, ii] - P.M[ii, :S] @ (np.linalg.pinv(P0) @ P.M[:S, ii]) if S else P.M[ii, ii], 1e-9)
                k = scale * (2 * np.pi * ft) ** 2 * me * (1.0 + 0.5 * s)
                nk.append(np.log(k))
                nc.append(np.log(2 * 0.02 * np.sqrt(k * me)))
            starts.append(np.concatenate([ks, nk, cs, nc, pay, cpl, np.zeros(len(new) - 1)]))
    # from each start: first the new stiffness(es) alone, the nominal springs and the new
    # damping held (freed here, the damping of a misplaced new mode ran to zero, hiding the
    # mode between the fitted frequencies); then everything
    Sn = len(sp)
    free = np.zeros(len(starts[0]), bool)
    free[S:Sn] = True
    # a new pair's coupling is held at zero from every start and freed once, from the best
    # (the uncoupled fit puts the pair's modes in place; the coupling then turns its axes)
    nc_new = len(starts[0]) - 2 * Sn - len(pay) - len(cpl)
    held = np.ones(len(starts[0]), bool)
    held[len(held) - nc_new:] = False
    best = None
    for x0 in starts:
        x1, _ = L.fit_linear(lm2, x0, pb.ftrain, free=free)
        xf, cost = L.fit_linear(lm2, x1, pb.ftrain, free=held, peaks_first=False)
        if best is None or cost < best[0]:
            best = (cost, xf)
    if nc_new:
        best = L.fit_linear(lm2, best[1], pb.ftrain, peaks_first=False)[::-1]
    return lm2, best[1]
