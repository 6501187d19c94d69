"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, how far it
shrinks once that effect is added and refitted, judged on held-out validation data.

The gap of a validation data set is its NRMSE [%]: torques ``rms(tau_model - tau) / std(tau)``
per joint; FRFs ``sqrt(sum |H_model - H|^2 / sum |H|^2)`` per entry; modal tables the RMS
relative frequency error (unmatched measured modes included through their nearest model mode)
plus ``0.1 x`` the relative damping error; output-error responses (channels lacking some joint,
e.g. tip coordinates, simulated under their applied torques from rest at ``q0``, :mod:`._response`)
``rms(y_model - y) / scale`` per channel. The noise floor is the NRMSE that measurement noise
alone would leave (from repeated records, else from the residual's high-frequency content), and
the *excess* gap ``sqrt(max(nrmse^2 - floor^2, 0))`` is what a model can close: ``shrink`` is
the percentage of the excess closed.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ._case import Case, load_case
from ._effect_term import EffectCandidate, EffectTerm
from ._inertia import inertia_prior, link_moves
from . import _linear as L
from . import _response as R
from . import _torque as T

TORQUE_EFFECTS = ("viscous_friction", "coulomb_friction", "stribeck_friction", "rotor_inertia", "gravity_compensator",
                  "backlash", "payload", "sensor_delay")
LINEAR_EFFECTS = ("joint_flexibility", "orthogonal_compliance", "link_flexibility", "hysteretic_damping",
                  "fractional_damping", "payload")
# pairs a single data set cannot always tell apart (issue 6): reported as ambiguous when close
CONFOUNDED = {frozenset(p) for p in [("sensor_delay", "viscous_friction"), ("payload", "joint_flexibility"),
                                     ("payload", "rotor_inertia"), ("coulomb_friction", "hysteretic_damping"),
                                     ("coulomb_friction", "backlash"), ("coulomb_friction", "stribeck_friction"),
                                     ("orthogonal_compliance", "link_flexibility"),
                                     ("fractional_damping", "hysteretic_damping")]}
SIGNIFICANCE = 1.2  # a gap is significant when nrmse > 1.2 x its noise floor (+ MIN_GAP)
MIN_GAP = 0.2  # [%] below this a gap is never significant
MIN_STEP_SHRINK = 10.0  # [%] of the current excess an added effect must close to be selected
MIN_NAMED_SHRINK = 50.0  # [%] of the nominal excess the first effect must close to be named at all
EXPLAINED_SHRINK = 80.0  # [%] of the nominal excess closed in all for the verdict 'explained'
DEFAULT_OPTIONS = {"inertia_prior": 1.0, "refit_inertia": True, "filter_cutoff_hz": "auto", "decimate": 1,
                   "max_effects": 3}


@dataclasses.dataclass(frozen=True)
class Candidate:
    """An effect placed at a joint (index) or link (index) or nowhere (None)."""

    effect: str
    joint: int | None = None

    def label(self, names):
        return self.effect if self.joint is None else f"{self.effect}@{names[self.joint]}"


@dataclasses.dataclass
class State:
    """A model under diagnosis: torque terms and the linear structure with their fitted values."""

    tfit: object | None
    lm: object | None
    x: np.ndarray | None
    added: tuple = ()


def _is_torque(d) -> bool:
    return d.kind == "torque" or (d.kind == "response" and "q" in d.arrays)


def _is_output_error(d) -> bool:
    return d.kind == "response" and "q" not in d.arrays


# ---------------------------------------------------------------------------------------------
class Problem:
    """Precomputed data of a case for repeated refits."""

    def __init__(self, case: Case, candidates=()):
        self.case = case
        self.robot = case.robot
        self.names = tuple(self.robot.joint_names)
        self.n = self.robot.nq
        # responses whose channels hold every model joint enter as equation-error (torque) sets
        self.options = dict(DEFAULT_OPTIONS, **(getattr(case, "options", None) or {}))
        proc = dict(cutoff_hz=self.options["filter_cutoff_hz"], decimate=int(self.options["decimate"]))
        self.ttrain = [T.torque_set(self.robot, d, **proc) for d in case.split("train") if _is_torque(d)]
        self.tval = [T.torque_set(self.robot, d, **proc) for d in case.split("validation") if _is_torque(d)]
        # the nominal identification refits the CAD inertial parameters (prior toward CAD, within
        # its tolerance) unless the case holds them fixed
        self.inertia = (inertia_prior(self.robot, float(self.options["inertia_prior"]))
                        if self.ttrain and self.options["refit_inertia"] else None)
        self.ftrain = [d for d in case.datasets if d.split == "train" and d.kind in ("frf", "modal")]
        self.fval = [d for d in case.datasets if d.split == "validation" and d.kind in ("frf", "modal")]
        # the others are simulated under their applied torques and compared as output error, on
        # validation only: a refit through the simulation would cost one nonlinear fit per candidate
        self.rval = [R.response_set(self.robot, d, case.tool_frame) for d in case.split("validation") if _is_output_error(d)]
        self.responses = [d for d in case.split("train") if _is_output_error(d)]
        self.nominal = {(e["effect"], self.names.index(j)) for e in case.nominal_effects for j in e["joints"]}
        # candidate effects given as jflex.effects effects (the user's own laws among them)
        self.user = {}
        for ec in candidates:
            if not isinstance(ec, EffectCandidate):
                raise TypeError(f"diagnose: candidates must be jflex.gap.EffectCandidate, got {type(ec).__name__}")
            j = None if ec.joint is None else self.names.index(ec.joint) if ec.joint in self.names else None
            if ec.joint is not None and j is None:
                from .._errors import ParameterError

                raise ParameterError(f"EffectCandidate '{ec.name}': joint '{ec.joint}' is not a model joint {list(self.names)}")
            self.user[Candidate(ec.name, j)] = ec.bind(self.robot)
        self.nominal_effects = case.nominal_effects
        # rotor inertia [kg m^2] the case states (nominal rotor_inertia with a value): the motor
        # side of a simulated spring when no torque training set fits it
        self.rotor_nominal = np.zeros(self.n)
        for e in case.nominal_effects:
            if e["effect"] == "rotor_inertia" and "value" in e:
                for j, v in zip(e["joints"], e["value"]):
                    self.rotor_nominal[self.names.index(j)] = v

    # --- nominal model -------------------------------------------------------------------------
    def nominal_state(self) -> State:
        terms, delay = [], 0.0
        for e in self.nominal_effects:
            if e["effect"] in TORQUE_EFFECTS and e["effect"] not in ("payload", "sensor_delay"):
                for j in e["joints"]:
                    h = {"stribeck_friction": T.STRIBECK_VS[2], "backlash": 0.01}.get(e["effect"])
                    terms.append(T.Term(e["effect"], self.names.index(j), h))
            elif e["effect"] == "payload":
                terms.append(T.Term("payload", None))
            elif e["effect"] == "sensor_delay":
                delay = float(e.get("value", [0.0])[0])
                terms.append(T.Term("sensor_delay", None, delay))
        tfit = None
        if self.ttrain:
            # twice: the prior's weight is relative to the residual level of the fit itself
            tfit = T.fit_terms(tuple(terms), delay, self.ttrain, self.inertia)
            if self.inertia is not None:
                self.inertia.sigma = T.with_inertia_sigma(tfit, self.ttrain)
                tfit = T.fit_terms(tuple(terms), delay, self.ttrain, self.inertia)
        lm = x = None
        if self.ftrain or self.fval:
            springs, x0 = [], []
            for e in self.nominal_effects:
                if e["effect"] == "joint_flexibility":
                    law = "viscous"
                    for j in e["joints"]:
                        springs.append(L.Spring("joint", self.names.index(j), law=law))
                    k = e.get("stiffness", np.full(len(e["joints"]), 1e5))
                    c = e.get("damping", 1e-3 * k)
                    x0.append((np.log(k), np.log(np.maximum(c, 1e-9))))
            # hysteretic / fractional nominal laws switch the spring at that joint
            laws = {}
            for e in self.nominal_effects:
                if e["effect"] in ("hysteretic_damping", "fractional_damping"):
                    for j in e["joints"]:
                        laws[self.names.index(j)] = "hysteretic" if e["effect"] == "hysteretic_damping" else "fractional"
            springs = [dataclasses.replace(s, law=laws.get(s.where, s.law)) for s in springs]
            ks = np.concatenate([a for a, _ in x0]) if x0 else np.zeros(0)
            cs = np.concatenate([b for _, b in x0]) if x0 else np.zeros(0)
            structure = L.LinearStructure(tuple(springs), payload=False)
            lm = L.LinearModel(self.robot, structure, self.case.tool_frame)
            x = np.concatenate([ks, cs])
            if self.ftrain and len(springs):
                x, _ = L.fit_linear(lm, x, self.ftrain)
        return State(tfit, lm, x)

    # --- candidates ----------------------------------------------------------------------------
    def candidates(self) -> list[Candidate]:
        out = []
        nom = {e for e, _ in self.nominal}
        if self.ttrain:
            for eff in TORQUE_EFFECTS:
                if eff in ("payload", "sensor_delay"):
                    if eff not in nom:
                        out.append(Candidate(eff, None))
                    continue
                for j in range(self.n):
                    if (eff, j) in self.nominal:
                        continue
                    if eff == "coulomb_friction" and ("stribeck_friction", j) in self.nominal:
                        continue
                    out.append(Candidate(eff, j))
        if self.ttrain:
            out += list(self.user)
        if self.ftrain:
            flex = {s.where for s in self._nominal_springs()}
            for j in range(self.n):
                if j not in flex:
                    out.append(Candidate("joint_flexibility", j))
                out.append(Candidate("orthogonal_compliance", j))
                out.append(Candidate("link_flexibility", j))
                if j in flex:
                    if ("hysteretic_damping", j) not in self.nominal:
                        out.append(Candidate("hysteretic_damping", j))
                    if ("fractional_damping", j) not in self.nominal:
                        out.append(Candidate("fractional_damping", j))
            if "payload" not in nom and not self.ttrain:
                out.append(Candidate("payload", None))
        return out

    def _nominal_springs(self):
        return [L.Spring("joint", self.names.index(j)) for e in self.nominal_effects
                if e["effect"] == "joint_flexibility" for j in e["joints"]]

    # --- refits --------------------------------------------------------------------------------
    def add(self, state: State, cand: Candidate) -> State:
        """Refit with ``cand`` added (warm start from ``state``)."""
        tfit, lm, x = state.tfit, state.lm, state.x
        if cand in self.user and self.ttrain:
            tfit = T.fit_with(tfit.terms, tfit.delay, EffectTerm(self.user[cand], cand.joint), self.ttrain, self.inertia)
        elif cand.effect in TORQUE_EFFECTS and self.ttrain:
            if cand.effect == "sensor_delay":
                base = tuple(t for t in tfit.terms if t.effect != "sensor_delay")
                tfit = T.fit_with(base, 0.0, T.Term("sensor_delay", None), self.ttrain, self.inertia)
            else:
                tfit = T.fit_with(tfit.terms, tfit.delay, T.Term(cand.effect, cand.joint, T.STRIBECK_VS[2]), self.ttrain,
                                  self.inertia)
        if cand.effect in LINEAR_EFFECTS and self.ftrain and lm is not None:
            lm, x = self._add_linear(lm, x, cand)
        return State(tfit, lm, x, state.added + (cand,))

    def _add_linear(self, lm, x, cand):
        st = lm.structure
        S = len(st.springs)
        ks, cs = list(x[:S]), list(x[S:2 * S])
        pay = list(x[2 * S:2 * S + 1]) if st.payload else []
        cpl = list(x[2 * S + len(pay):])  # couplings of virtual pairs already in the model
        springs = list(st.springs)
        new_idx = []
        if cand.effect in ("hysteretic_damping", "fractional_damping"):
            i = next(i for i, s in enumerate(springs) if s.kind == "joint" and s.where == cand.joint)
            law = "hysteretic" if cand.effect == "hysteretic_damping" else "fractional"
            tried = {}

            def fit_alpha(a):
                sp = list(springs)
                sp[i] = dataclasses.replace(sp[i], law=law, alpha=round(float(a), 3))
                lm2 = L.LinearModel(self.robot, L.LinearStructure(tuple(sp), st.payload), self.case.tool_frame)
                lm2._cache = lm._cache  # same geometry and postures: the matrices carry over
                x2 = np.array(x, float)
                w = 2 * np.pi * self._ref_freq()
                k, c = np.exp(x2[i]), np.exp(x2[S + i])
                # the same loss at the reference frequency (eta = w c / k, c_frac = w c / w^alpha) is
                # only a guess (the spring's own mode may lie elsewhere): scan the new damping
                # coefficient around it, then fit everything from the best (no peaks phase: the
                # picked peaks' half-power damping is what a damping law must not chase)
                c0 = np.log(w * c / k) if law == "hysteretic" else np.log(w * c / w**a)
                best0 = None
                for dc in np.arange(-3.0, 3.01, 0.5):
                    x2[S + i] = c0 + dc
                    r = L.residual(lm2, x2, self.ftrain, peaks=False)
                    if best0 is None or r @ r < best0[0]:
                        best0 = (float(r @ r), x2.copy())
                xf, cost = L.fit_linear(lm2, best0[1], self.ftrain, peaks_first=False)
                tried[float(a)] = (cost, lm2, xf)
                return cost

            if law == "hysteretic":
                fit_alpha(0.5)
            else:
                for a in L.ALPHAS:
                    fit_alpha(a)
                # refine the order: steps of 0.1, 0.05 and 0.025 either side of the best order tried,
                # then the vertex of a parabola through the best and its (now close) neighbours (one
                # parabola through the wide grid stopped 0.07 off the order)
                best_a = lambda: min(tried, key=lambda a: tried[a][0])
                for h in (0.1, 0.05, 0.025):
                    a0 = best_a()
                    for a_new in (a0 - h, a0 + h):
                        a_new = round(float(np.clip(a_new, 0.1, 0.95)), 3)
                        if a_new not in tried:
                            fit_alpha(a_new)
                al = sorted(tried)
                kb = min(max(al.index(best_a()), 1), len(al) - 2)
                xa = np.array(al[kb - 1:kb + 2])
                ya = np.log(np.array([tried[a][0] for a in xa]))
                cpar = np.polyfit(xa - xa[1], ya, 2)
                if cpar[0] > 0:
                    a_new = round(float(np.clip(xa[1] - cpar[1] / (2 * cpar[0]), xa[0], xa[2])), 3)
                    if a_new not in tried:
                        fit_alpha(a_new)
            cost, lm2, xf = min(tried.values(), key=lambda t: t[0])
            return lm2, xf
        if cand.effect == "payload":
            st2 = L.LinearStructure(tuple(springs), True)
            lm2 = L.LinearModel(self.robot, st2, self.case.tool_frame)
            xs = [np.concatenate([ks, cs, [np.log(m)], cpl]) for m in (0.1, 1.0, 10.0)]
            xf, _ = L.fit_linear(lm2, xs[0], self.ftrain, starts=xs[1:])
            return lm2, xf
        if cand.effect == "joint_flexibility":
            new = [L.Spring("joint", cand.joint)]
        elif cand.effect == "orthogonal_compliance":
            # a bearing's tilt stiffness: a full 2x2 (coupled) stiffness about the two axes
            new = [L.Spring("orth", cand.joint, 0), L.Spring("orth", cand.joint, 1, coupled=True)]
        else:
            new = [L.Spring("link", cand.joint, 0), L.Spring("link", cand.joint, 1, coupled=True)]
        sp = springs + new
        lm2 = L.LinearModel(self.robot, L.LinearStructure(tuple(sp), st.payload), self.case.tool_frame)
        # starting stiffnesses: the new spring(s) alone would put a mode at f_t; f_t is scanned over a
        # log grid from below the measured band to well above it (a compliance whose modes lie
        # above the band shows only as a posture-dependent static softening), both springs of a
        # pair together and each alone stiff, keeping the starts with the lowest misfit. (One start
        # at the frequency of the largest misfit put link modes far below the band, from where the
        # bounded fit could not return.)
        P = lm2.mats(self._ref_posture())
        f_lo, f_hi = self._freq_band()
        targets = list(np.geomspace(f_lo, 3.0 * f_hi, 12)) + self._unmatched_freqs(lm, x)[:1]
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
            r = L.residual(lm2, xs, self.ftrain, peaks=False)
            scored.append((float(r @ r), len(scored), xs))
        scored.sort(key=lambda t: t[:2])
        starts = [t[2] for t in scored[:2]]
        # and the new modes near the measured mode the model misses most (where the nominal fit is
        # far off, the grid's misfit says little: a peaks phase first sorts the modes out)
        P0 = P.M[:S, :S]
        for ft in self._unmatched_freqs(lm, x)[:1]:
            for scale in (0.6, 1.6):
                nk, nc = [], []
                for s in range(len(new)):
                    ii = S + s
                    me = max(P.M[ii, ii] - P.M[ii, :S] @ np.linalg.solve(P0, P.M[:S, ii]) if S else P.M[ii, ii], 1e-9)
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
            x1, _ = L.fit_linear(lm2, x0, self.ftrain, free=free)
            xf, cost = L.fit_linear(lm2, x1, self.ftrain, free=held, peaks_first=False)
            if best is None or cost < best[0]:
                best = (cost, xf)
        if nc_new:
            best = L.fit_linear(lm2, best[1], self.ftrain, peaks_first=False)[::-1]
        return lm2, best[1]

    def _ref_posture(self):
        return self.ftrain[0].arrays["q0"]

    def _freq_band(self):
        fs = []
        for d in self.ftrain:
            fs += list(np.asarray(d.arrays["freq"], float))
        return (float(min(fs)), float(max(fs))) if fs else (1.0, 100.0)

    def _ref_freq(self):
        fs = []
        for d in self.ftrain:
            a = d.arrays
            if d.kind == "modal":
                fs += list(a["freq"])
            else:
                fs.append(a["freq"][np.argmax(np.abs(a["H"]).sum(axis=(1, 2)))])
        return float(np.median(fs)) if fs else 10.0

    def _unmatched_freqs(self, lm, x):
        out = []
        for d in self.ftrain:
            a = d.arrays
            if d.kind == "modal":
                f, _ = lm.modes(x, a["q0"])
                _, rel = L.match_modes(f, a["freq"])
                out += [float(fm) for fm, r in zip(a["freq"], rel) if abs(r) > 0.05]
            else:
                Hm = lm.frf(x, a["q0"], a["freq"])
                e = np.abs(Hm - a["H"]).sum(axis=(1, 2))
                out.append(float(a["freq"][np.argmax(e)]))
        return out

    # --- simulation of output-error sets -----------------------------------------------------------
    def sim_springs(self, state: State) -> dict:
        """``{joint: (k, c)}`` of the joint springs a tip simulation holds: those of the linear
        model (fitted on FRF/modal data), else the stiffness/damping the case declares for its
        nominal flexible joints. A hysteretic or fractional law enters as the viscous damping (and
        stiffness) with the same complex stiffness at the reference frequency (the median measured
        mode): a time simulation needs a causal law of fixed structure."""
        out = {}
        if state.lm is not None:
            sp = state.lm.structure.springs
            S = len(sp)
            w = 2 * np.pi * (self._ref_freq() if self.ftrain else 10.0)
            for i, s in enumerate(sp):
                if s.kind != "joint":
                    continue
                k, v = float(np.exp(state.x[i])), float(np.exp(state.x[S + i]))
                if s.law == "hysteretic":
                    c = v * k / w
                elif s.law == "fractional":
                    c = v * w ** (s.alpha - 1) * np.sin(s.alpha * np.pi / 2)
                    k = k + v * w**s.alpha * np.cos(s.alpha * np.pi / 2)
                else:
                    c = v
                out[s.where] = (k, c)
            return out
        for e in self.nominal_effects:
            if e["effect"] == "joint_flexibility" and "stiffness" in e:
                c = e.get("damping", 1e-3 * e["stiffness"])
                for j, kj, cj in zip(e["joints"], e["stiffness"], c):
                    if kj > 0:
                        out[self.names.index(j)] = (float(kj), float(cj))
        return out

    def simulation_model(self, state: State):
        """The model a tip (output-error) set is simulated with (:func:`._response.simulation_model`);
        rotor inertia from the nominal ``value`` when no torque training set fits it."""
        return R.simulation_model(self.robot, state.tfit, self.sim_springs(state), None if self.ttrain else self.rotor_nominal)

    # --- evaluation ----------------------------------------------------------------------------
    def evaluate(self, state: State, sets="validation") -> dict:
        """Per data set: nrmse [%], per channel [%], mse and effective sample count."""
        tsets = self.tval if sets == "validation" else self.ttrain
        fsets = self.fval if sets == "validation" else self.ftrain
        out = {}
        if sets == "validation" and self.rval:
            model = self.simulation_model(state)
            for s in self.rval:
                e, failed = R.residual(model, s)
                ch = np.sqrt(np.mean(e**2, axis=0)) * 100
                out[s.name] = dict(kind="response", nrmse=float(np.sqrt(np.mean(e**2)) * 100),
                                   channels={c: float(v) for c, v in zip(s.channels, ch)}, neff=e.size / 10.0,
                                   resid=e, failed=failed, samples=len(e))
        for s in tsets:
            pred = T.predict(state.tfit, s)
            e = (pred - s.tau) / s.scale
            ch = np.sqrt(np.mean(e**2, axis=0)) * 100
            out[s.name] = dict(kind="torque", nrmse=float(np.sqrt(np.mean(e**2)) * 100),
                               channels={self.names[j]: float(ch[j]) for j in range(self.n)},
                               neff=e.size / 10.0, resid=e)
        for d in fsets:
            a = d.arrays
            if d.kind == "frf":
                Hm = state.lm.frf(state.x, a["q0"], a["freq"]) if state.lm is not None else np.zeros_like(a["H"])
                Hm = np.where(np.isfinite(Hm), Hm, 0.0)
                err = Hm - a["H"]
                ok = L.frf_entries(a["H"])
                tot = np.sqrt(np.sum(np.abs(err[:, ok]) ** 2) / np.sum(np.abs(a["H"][:, ok]) ** 2)) * 100
                s = L.frf_scale(a["H"])
                ch = {f"H_{'xyz'[i]}{'xyz'[j]}": float(np.sqrt(np.mean(np.abs(err[:, i, j]) ** 2)) / s[i, j] * 100)
                      for i in range(3) for j in range(3) if ok[i, j]}
                out[d.name] = dict(kind="frf", nrmse=float(tot), channels=ch, neff=err[:, ok].size / 4.0, err=err, Hm=Hm)
            else:
                if state.lm is None:
                    ef = np.ones(len(a["freq"]))
                    ez = np.zeros_like(ef)
                    idx, f, z = np.full(len(ef), -1), np.zeros(0), np.zeros(0)
                else:
                    ef, ez, idx, f, z = L.modal_errors(state.lm, state.x, a)
                    # a model without valid modes (non-physical mass matrix) misses every mode
                    ef = np.where(np.isfinite(ef), ef, 1.0)
                    ez = np.where(np.isfinite(ez), ez, 0.0)
                tot = np.sqrt(np.mean(ef**2) + np.mean((L.DAMPING_WEIGHT * ez) ** 2)) * 100
                ch = {f"mode{k + 1}@{a['freq'][k]:.1f}Hz": float(abs(ef[k]) * 100) for k in range(len(ef))}
                out[d.name] = dict(kind="modal", nrmse=float(tot), channels=ch, neff=float(len(ef)), ef=ef, ez=ez,
                                   idx=idx, f_model=f, z_model=z)
        return out


# --- noise floor --------------------------------------------------------------------------------
def _mad_sigma(x):
    x = np.asarray(x).ravel()
    return 1.4826 * np.median(np.abs(x - np.median(x)))


def _mean_of(rep, x) -> float:
    """sqrt(R) when the record ``x`` is the mean of its ``R`` repeats (its noise is that of one
    repeat over sqrt(R)), else 1 (a record of its own)."""
    R = rep.shape[0]
    if R > 1 and np.allclose(rep.mean(axis=0), x, rtol=1e-9, atol=1e-12 * float(np.max(np.abs(x)) or 1.0)):
        return float(np.sqrt(R))
    return 1.0


def noise_floor(problem: Problem, ev: dict, case: Case, sources: dict | None = None) -> dict:
    """NRMSE [%] that noise alone leaves, per validation data set.

    Torque: from ``tau_repeats`` when recorded (over sqrt(R) when ``tau`` is their mean), else the robust (MAD) spread of the residual's
    second difference, ``sigma = MAD(d2 r) / sqrt(6)`` (white noise: var(d2) = 6 sigma^2; the
    smooth model error barely enters, and the median ignores the few jumps at reversals).
    FRF: ``H_repeats`` when recorded (likewise), else the same on the real and imaginary parts of the
    residual along frequency. Modal tables: ``noise.modal_frequency_pct`` of the case (default 1).
    Output-error (tip) sets: ``y_repeats`` when recorded, else per channel the smaller of the
    residual's second-difference estimate and the record's own fourth difference,
    ``MAD(d4 y) / sqrt(70)`` (a nominal simulation that drifts or runs away fast leaves
    high-frequency content in the residual, not in the record; smooth motion barely enters d4).
    ``sources``: optional mapping filled with the estimate used per data set.
    """
    out = {}
    src = {} if sources is None else sources
    by_name = {d.name: d for d in case.datasets}
    for name, r in ev.items():
        d = by_name[name]
        if r["kind"] == "torque":
            s = next(s for s in problem.tval if s.name == name)
            if "tau_repeats" in d.arrays and s.cutoff is None:
                src[name] = "propagated angle noise" if d.kind == "response" else "tau_repeats"
                rep = d.arrays["tau_repeats"]
                sig = rep.std(axis=0, ddof=1).mean(axis=0) / s.scale / _mean_of(rep, d.arrays["tau"])
            elif "tau_repeats" in d.arrays:
                # repeats of raw torques through the same low-pass as the data
                rep = d.arrays["tau_repeats"]
                rf = np.stack([s.lp(r)[::s.processing.get("decimate", 1)] for r in rep])
                sig = rf.std(axis=0, ddof=1).mean(axis=0) / s.scale / _mean_of(rep, d.arrays["tau"])
                src[name] = "tau_repeats (filtered)"
            elif s.noise is not None:
                # angle-only log: what the processing predicts (raw torque spectrum above the motion
                # band through the filter, plus the angle noise propagated through the model)
                sig = s.noise / s.scale
                src[name] = "filtered torque spectrum + propagated angle noise"
            else:
                e = r["resid"]
                d2 = e[2:] - 2 * e[1:-1] + e[:-2]
                sig = np.array([_mad_sigma(d2[:, j]) / np.sqrt(6) for j in range(e.shape[1])])
                src[name] = "residual second difference"
            out[name] = float(np.sqrt(np.mean(sig**2)) * 100)
        elif r["kind"] == "response":
            # output error: white measurement noise on y, the same estimates on the residual
            s = next(s for s in problem.rval if s.name == name)
            if "y_repeats" in d.arrays:
                rep = d.arrays["y_repeats"]
                sig = rep.std(axis=0, ddof=1).mean(axis=0) / s.scale / _mean_of(rep, d.arrays["y"])
                src[name] = "y_repeats"
            else:
                e = r["resid"]
                d2 = e[2:] - 2 * e[1:-1] + e[:-2]
                s2 = np.array([_mad_sigma(d2[:, j]) / np.sqrt(6) for j in range(e.shape[1])])
                y = s.y / s.scale
                d4 = y[4:] - 4 * y[3:-1] + 6 * y[2:-2] - 4 * y[1:-3] + y[:-4]
                s4 = np.array([_mad_sigma(d4[:, j]) / np.sqrt(70) for j in range(y.shape[1])])
                sig = np.minimum(s2, s4)
                src[name] = ("residual second difference" if np.sum(s2**2) <= np.sum(s4**2) else
                             "record fourth difference")
            out[name] = float(np.sqrt(np.mean(sig**2)) * 100)
        elif r["kind"] == "frf":
            a = d.arrays
            ok = L.frf_entries(a["H"])
            scale = L.frf_scale(a["H"])
            if "H_repeats" in a:
                rep = a["H_repeats"]
                # per-entry noise variance of one record (unbiased), summed over frequency and set
                # against the FRF's energy: the measure of the gap itself
                var = np.sum(np.abs(rep - rep.mean(axis=0)) ** 2, axis=0) / max(rep.shape[0] - 1, 1)
                var = var / _mean_of(rep, a["H"]) ** 2
                out[name] = float(np.sqrt(np.sum(var[:, ok]) / np.sum(np.abs(a["H"][:, ok]) ** 2)) * 100)
                src[name] = "H_repeats"
            else:
                src[name] = "residual second difference"
                e = r["err"][:, ok] / scale[ok]
                d2 = e[2:] - 2 * e[1:-1] + e[:-2]
                sig = np.sqrt(_mad_sigma(d2.real) ** 2 + _mad_sigma(d2.imag) ** 2) / np.sqrt(6)
                out[name] = float(sig * 100)
        else:
            out[name] = float(case.noise.get("modal_frequency_pct", 1.0))
            src[name] = "noise.modal_frequency_pct" if "modal_frequency_pct" in case.noise else "default 1 %"
    return out


def _combine(ev, floor):
    names = list(ev)
    g = np.array([ev[k]["nrmse"] for k in names])
    f = np.array([floor[k] for k in names])
    gap = float(np.sqrt(np.mean(g**2)))
    fl = float(np.sqrt(np.mean(f**2)))
    exc = float(np.sqrt(np.mean(np.maximum(g**2 - f**2, 0.0))))
    return gap, fl, exc


def _significant(ev, floor):
    return any(ev[k]["nrmse"] > SIGNIFICANCE * floor[k] + MIN_GAP for k in ev)


def _ic_delta(ev_new, ev_old, p_new):
    """Held-out information criterion change (BIC form): sum_d Neff_d ln(mse_new / mse_old) + p ln(N)."""
    d = 0.0
    ntot = 0.0
    for k in ev_new:
        ne = ev_new[k]["neff"]
        ntot += ne
        d += ne * np.log(max(ev_new[k]["nrmse"], 1e-9) ** 2 / max(ev_old[k]["nrmse"], 1e-9) ** 2)
    return d + p_new * np.log(max(ntot, 2.0))


NESTED = {"stribeck_friction": "coulomb_friction"}  # complex -> the simpler effect it contains
PARSIMONY = 5.0  # [%] a nested simpler effect within this shrink of the richer one ranks first


def _rank(entries) -> list[int]:
    """Order by the held-out shrink, then the criterion; a simpler nested effect at the same place
    that closes nearly as much (within PARSIMONY points of shrink) goes first."""
    # the held-out gap closed decides (rounded to a point, so noise-level differences tie), the
    # information criterion breaks ties
    order = sorted(range(len(entries)), key=lambda i: (-round(entries[i]["shrink"]), -entries[i]["score"]))
    changed = True
    while changed:
        changed = False
        for a in range(len(order)):
            ea = entries[order[a]]
            simple = NESTED.get(ea["effect"])
            if simple is None:
                continue
            for b in range(a + 1, len(order)):
                eb = entries[order[b]]
                if eb["effect"] == simple and eb["joint"] == ea["joint"] and eb["shrink"] >= ea["shrink"] - PARSIMONY:
                    order.insert(a, order.pop(b))
                    changed = True
                    break
            if changed:
                break
    return order


@dataclasses.dataclass
class Step:
    """One forward-selection step: ``cand`` added to the model before it (``ev_before``)."""

    cand: object
    state: object
    ev: dict
    ev_before: dict
    score: float  # held-out information-criterion gain (-_ic_delta against the model before)
    step_shrink: float  # % of the excess before this step that it closed


@dataclasses.dataclass
class Selection:
    """Result of :func:`forward_select`: the steps taken, the final model and why it stopped:
    ``"not significant"`` (nothing to explain), ``"max effects"``, ``"no candidate"``,
    ``"too small"`` (``rejected``, the best next step, closes < MIN_STEP_SHRINK % of the excess or
    does not pay its parameters) or ``"within noise"`` (what remains is not significant)."""

    steps: list
    state: object
    ev: dict
    stop: str
    rejected: Step | None = None


def forward_select(state0, ev0: dict, floor: dict, candidates, refit, *, n_params, max_effects: int,
                   simpler=None, first=None, on_select=None) -> Selection:
    """Forward selection on held-out data, the rules of :func:`diagnose`: each round refits every
    candidate not yet added on top of the current model, takes the one closing the most of the
    current excess gap (rounded to a point, so that noise-level differences tie; the information
    criterion breaks ties), and adds it only when it pays its parameters (held-out BIC) and closes
    at least ``MIN_STEP_SHRINK`` % of the current excess; it stops once the gap is within noise.

    **Arguments:**

    - ``state0``, ``ev0``: the nominal model (opaque to this loop) and its validation evaluation
      (``{name: {"nrmse", "neff", ...}}``); ``floor``: noise floor per validation set.
    - ``candidates``: a list, or ``callable(state, round) -> list`` for a pool that changes with the model.
    - ``refit(state, cand) -> (new_state, ev)``: ``cand`` added to ``state``, refitted on training
      data and evaluated on validation data (the caller caches where it can).
    - ``n_params(cand)``: parameters the candidate adds (the criterion's penalty).
    - ``simpler(rich, simple) -> bool``: optional; a simpler effect nested in a richer one at the
      same place wins when it closes within ``PARSIMONY`` points of it.
    - ``first``: optional ``{cand: (state, ev)}`` of first-round refits already made.
    - ``on_select(step)``: optional callback after each selected step.
    """
    if not _significant(ev0, floor):
        return Selection([], state0, ev0, "not significant")
    steps, state, ev_cur, chosen = [], state0, ev0, []
    while True:
        if len(steps) >= max_effects:
            return Selection(steps, state, ev_cur, "max effects")
        _, _, exc_cur = _combine(ev_cur, floor)
        pool = candidates(state, len(steps)) if callable(candidates) else candidates
        best = None
        for c in pool:
            if c in chosen:
                continue
            st, ev = first[c] if (first is not None and not steps and c in first) else refit(state, c)
            score = -_ic_delta(ev, ev_cur, n_params(c))
            _, _, exc = _combine(ev, floor)
            step_shrink = 100 * (1 - exc / exc_cur) if exc_cur > 0 else 0.0
            key = (round(step_shrink), score)
            if simpler is not None and best is not None:
                if simpler(best[1].cand, c) and step_shrink >= best[1].step_shrink - PARSIMONY:
                    key = (best[0][0], best[0][1] + 1e-9, 1)  # the simpler nested effect wins a near tie
                elif simpler(c, best[1].cand) and best[1].step_shrink >= step_shrink - PARSIMONY:
                    key = (-np.inf, -np.inf)
            if best is None or key > best[0]:
                best = (key, Step(c, st, ev, ev_cur, float(score), float(step_shrink)))
        if best is None:
            return Selection(steps, state, ev_cur, "no candidate")
        step = best[1]
        if step.score <= 0 or step.step_shrink < MIN_STEP_SHRINK:
            return Selection(steps, state, ev_cur, "too small", step)
        steps.append(step)
        chosen.append(step.cand)
        state, ev_cur = step.state, step.ev
        if on_select is not None:
            on_select(step)
        if not _significant(ev_cur, floor):
            return Selection(steps, state, ev_cur, "within noise")


def step_record(added, ev, floor) -> dict:
    """The ``steps`` entry of a diagnosis: the gap after ``added`` (None: nominal)."""
    g, _, e = _combine(ev, floor)
    return dict(added=added, gap=g, excess=e, per_dataset={k: v["nrmse"] for k, v in ev.items()})


def _n_params(c: Candidate, user=None) -> int:
    if user and c in user:
        return user[c].size
    return {"stribeck_friction": 3, "gravity_compensator": 4, "payload": 10, "orthogonal_compliance": 4,
            "link_flexibility": 4, "joint_flexibility": 2, "fractional_damping": 2,
            "backlash": 1 + len(T.BACKLASH_PULSES)}.get(c.effect, 1)


# --- signatures -----------------------------------------------------------------------------------
def signatures(problem: Problem, state: State, cands) -> dict:
    """A cheap score per torque candidate before any refit: the largest |correlation| between the
    training residual and the candidate's columns (sign of velocity for Coulomb, posture harmonics
    for compensators, d tau/dt for a delay, held sign x gravity stiffness for backlash)."""
    out = {}
    if not problem.ttrain:
        return out
    res = [(T.predict(state.tfit, s) - s.tau) / s.scale for s in problem.ttrain]
    for c in cands:
        if c.effect not in TORQUE_EFFECTS:
            continue
        best = 0.0
        for s, r in zip(problem.ttrain, res):
            if c.effect == "sensor_delay":
                cols = (np.gradient(T.predict(state.tfit, s), s.t, axis=0) / s.scale)[:, :, None]
            else:
                h = {"stribeck_friction": T.STRIBECK_VS[1], "backlash": 0.01}.get(c.effect)
                cols = T.term_columns(T.Term(c.effect, c.joint, h), s) / s.scale[None, :, None]
            for k in range(cols.shape[2]):
                v = cols[:, :, k].ravel()
                nv = np.linalg.norm(v)
                if nv > 0:
                    best = max(best, abs(v @ r.ravel()) / (nv * np.linalg.norm(r)))
        out[c] = best
    return out


SIGNATURE_NAMES = {
    "viscous_friction": "correlation with joint velocity", "coulomb_friction": "correlation with sign of velocity",
    "stribeck_friction": "sign of velocity, larger at low speed", "rotor_inertia": "correlation with joint acceleration",
    "gravity_compensator": "posture harmonics of the joint angle", "backlash": "dead zone at reversals (held sign x gravity stiffness)",
    "payload": "tool-mass regressor columns", "sensor_delay": "phase lag: correlation with d tau/dt",
    "joint_flexibility": "extra FRF peak / unmatched mode", "orthogonal_compliance": "extra FRF peak / unmatched mode",
    "link_flexibility": "extra FRF peak / unmatched mode", "hysteretic_damping": "damping ratio flat in frequency",
    "fractional_damping": "damping ratio growing as w^(alpha-1)",
}


# --- where -------------------------------------------------------------------------------------
def where(problem: Problem, ev: dict, floor: dict, case: Case, n_windows: int = 8, n_bands: int = 8) -> list:
    """Localise the validation gap: data set x channel, time windows, frequency bands, postures."""
    out = []
    by_name = {d.name: d for d in case.datasets}
    for name, r in ev.items():
        d = by_name[name]
        for ch, v in r["channels"].items():
            item = dict(dataset=name, channel=ch, nrmse=v, floor=floor[name])
            if r["kind"] != "torque" and "q0" in d.arrays:
                item["posture"] = _posture_dict(problem, d)
            if r["kind"] == "modal":
                k = int(ch[4:ch.index("@")]) - 1
                f = float(d.arrays["freq"][k])
                item["band_hz"] = [f, f]
                item["unmatched"] = bool(abs(r["ef"][k]) > 0.1)
            out.append(item)
        if r["kind"] in ("torque", "response"):
            s = next(s for s in problem.tval + problem.rval if s.name == name)
            chans = problem.names if r["kind"] == "torque" else s.channels
            e = r["resid"]
            edges = np.linspace(0, len(s.t), n_windows + 1).astype(int)
            for j, cn in enumerate(chans):
                for a, b in zip(edges[:-1], edges[1:]):
                    out.append(dict(dataset=name, channel=cn, window_s=[float(s.t[a]), float(s.t[b - 1])],
                                    nrmse=float(np.sqrt(np.mean(e[a:b, j] ** 2)) * 100), floor=floor[name]))
                # residual spectrum: the band holding most of the residual's energy
                fs = 1.0 / np.mean(np.diff(s.t))
                spec = np.abs(np.fft.rfft(e[:, j])) ** 2
                fr = np.fft.rfftfreq(len(e), 1 / fs)
                bands = np.geomspace(max(fr[1], 1e-3), fr[-1], n_bands + 1)
                for lo, hi in zip(bands[:-1], bands[1:]):
                    m = (fr >= lo) & (fr < hi)
                    val = float(np.sqrt(spec[m].sum() / max(spec.sum(), 1e-300)) * r["channels"][cn]) if m.any() else 0.0
                    out.append(dict(dataset=name, channel=cn, band_hz=[float(lo), float(hi)], nrmse=val,
                                    floor=floor[name]))
        if r["kind"] == "frf":
            a = d.arrays
            ok = L.frf_entries(a["H"])
            tot = np.sqrt(np.mean(np.abs(a["H"][:, ok]) ** 2))
            bands = np.geomspace(a["freq"][0], a["freq"][-1] * 1.0001, n_bands + 1)
            for lo, hi in zip(bands[:-1], bands[1:]):
                m = (a["freq"] >= lo) & (a["freq"] < hi)
                if m.any():
                    v = float(np.sqrt(np.mean(np.abs(r["err"][m][:, ok]) ** 2)) / tot * 100)
                    out.append(dict(dataset=name, channel="tool", band_hz=[float(lo), float(hi)], nrmse=v, floor=floor[name],
                                    posture=_posture_dict(problem, d)))
    out += posture_correlation(problem, ev, case)
    out.sort(key=lambda w: -w["nrmse"])
    return out


def _posture_dict(problem, d):
    a = d.arrays
    p = {problem.names[j]: float(np.degrees(a["q0"][j])) for j in range(problem.n)}
    p.update({nm: float(np.degrees(v)) for nm, v in zip(d.extra_joints, a.get("q0_extra", []))})
    return {"q_deg": p}


def posture_correlation(problem, ev, case) -> list:
    """Correlation of the error with posture variables (model joints and joints the model leaves
    out): within torque records (squared residual vs q_j), and across modal/FRF postures (error of
    each mode/entry vs q0)."""
    out = []
    by_name = {d.name: d for d in case.datasets}
    for name, r in ev.items():
        if r["kind"] != "torque":
            continue
        s = next(s for s in problem.tval if s.name == name)
        e2 = r["resid"] ** 2
        vars_ = {problem.names[j]: s.q[:, j] for j in range(problem.n)}
        vars_.update({nm: s.q_extra[:, i] for i, nm in enumerate(s.extra_joints)})
        for j in range(problem.n):
            for vn, v in vars_.items():
                if np.std(v) < 1e-9:
                    continue
                c = float(np.corrcoef(v, e2[:, j])[0, 1])
                out.append(dict(dataset=name, channel=problem.names[j], posture={"variable": vn, "corr": c},
                                nrmse=float(abs(c) * r["channels"][problem.names[j]])))
    # across postures: modal sets with the same number of modes, or FRF sets
    sets = [(n_, r) for n_, r in ev.items() if r["kind"] in ("modal", "frf")]
    if len(sets) >= 3:
        chans = sorted(set.intersection(*[set(_chan_keys(r)) for _, r in sets]))
        for ch in chans:
            errs = np.array([_chan_keys(r)[ch] for _, r in sets])
            ds = [by_name[n_] for n_, _ in sets]
            vars_ = {}
            for j in range(problem.n):
                vars_[problem.names[j]] = np.array([d.arrays["q0"][j] for d in ds])
            extra = set.intersection(*[set(d.extra_joints) for d in ds]) if ds else set()
            for nm in sorted(extra):
                vars_[nm] = np.array([d.arrays["q0_extra"][list(d.extra_joints).index(nm)] for d in ds])
            for vn, v in vars_.items():
                if np.std(v) < 1e-9 or np.std(errs) < 1e-12:
                    continue
                c = float(np.corrcoef(v, errs)[0, 1])
                worst = int(np.argmax(errs))
                out.append(dict(dataset=",".join(n_ for n_, _ in sets), channel=ch,
                                posture={"variable": vn, "corr": c, "worst_at_deg": float(np.degrees(v[worst])),
                                         "worst_dataset": sets[worst][0]},
                                nrmse=float(abs(c) * errs.max())))
    return out


def _chan_keys(r):
    # modal channels are named with their measured frequency; compare across postures by mode number
    if r["kind"] == "modal":
        return {f"mode{k + 1}": abs(float(r["ef"][k])) * 100 for k in range(len(r["ef"]))}
    return {"frf": r["nrmse"]}


# --- the diagnosis -------------------------------------------------------------------------------
@dataclasses.dataclass
class Diagnosis:
    """Everything ``diagnosis.json`` holds, plus the fitted states for plots."""

    result: dict
    problem: Problem
    nominal: State
    final: State
    steps: list


def _entry(problem, c: Candidate, ev, ev0, floor, score, sig=None):
    gap, fl, exc = _combine(ev, floor)
    _, _, exc0 = _combine(ev0, floor)
    shrink = 100.0 * (1 - exc / exc0) if exc0 > 0 else 0.0
    g0 = _combine(ev0, floor)[0]
    e = dict(effect=c.effect, joint=None if c.joint is None or c.effect == "link_flexibility" else problem.names[c.joint],
             link=problem.robot.link_names[c.joint] if c.effect == "link_flexibility" else None,
             score=float(score), gap_after=gap, shrink=float(np.clip(shrink, 0, 100)),
             shrink_raw=float(100 * (1 - gap / g0)) if g0 > 0 else 0.0,
             per_dataset={k: v["nrmse"] for k, v in ev.items()})
    if sig is not None:
        e["signature"] = {"name": SIGNATURE_NAMES[c.effect], "value": float(sig)}
    return e


def diagnose(case, *, candidates=(), max_effects: int | None = None, prune: int = 10, progress=None) -> Diagnosis:
    """Fit the nominal model on the training data, localise the validation gap, test candidate
    effects and select a set by forward selection on held-out data.

    **Arguments:**

    - ``case``: a :class:`jflex.gap.Case` or a path to a case folder / ``case.yaml``.
    - ``candidates``: extra candidate effects, :class:`jflex.gap.EffectCandidate` (any
      :mod:`jflex.effects` effect, a user's own class included), tried beside the built-in ones.
    - ``max_effects``: most effects to add (default: the case's ``options.max_effects``, 3);
      ``prune``: torque candidates refitted per round,
      the best by residual signature (frequency-side candidates are few and all refitted).
    - ``progress``: optional ``callable(str)`` for progress lines.

    **Returns:** a :class:`Diagnosis`; ``.result`` is the mapping written to ``diagnosis.json``.
    """
    t0 = time.perf_counter()
    say = progress or (lambda s: None)
    if not isinstance(case, Case):
        case = load_case(case)
    pb = Problem(case, candidates)
    if max_effects is None:
        max_effects = int(pb.options["max_effects"])
    say(f"nominal fit ({len(pb.ttrain)} torque, {len(pb.ftrain)} frf/modal training sets)")
    nom = pb.nominal_state()
    ev0 = pb.evaluate(nom)
    floor_source = {}
    floor = noise_floor(pb, ev0, case, floor_source)
    gap0, fl, exc0 = _combine(ev0, floor)
    significant = _significant(ev0, floor)
    cands = pb.candidates()
    sig = signatures(pb, nom, cands)
    tc = sorted([c for c in cands if c in sig], key=lambda c: -sig[c])
    keep = tc[:prune] + [c for c in cands if c not in sig]
    say(f"gap {gap0:.2f} % (noise floor {fl:.2f} %), {len(cands)} candidates, {len(keep)} refitted")
    ranking, fitted = [], {}
    failed = _failed_solves("nominal", ev0)
    for c in keep:
        st = pb.add(nom, c)
        ev = pb.evaluate(st)
        failed += _failed_solves(c.label(pb.names), ev)
        score = -_ic_delta(ev, ev0, _n_params(c, pb.user))
        fitted[c] = (st, ev)
        ranking.append(_entry(pb, c, ev, ev0, floor, score, sig.get(c)))
        say(f"  {c.label(pb.names)}: gap {ranking[-1]['gap_after']:.2f} %, shrink {ranking[-1]['shrink']:.0f} %")
    order = _rank(ranking)
    ranking = [ranking[i] for i in order]
    keep = [keep[i] for i in order]
    # forward selection; after the first step the residual changed: the signatures are ranked
    # again so that effects masked by the first (larger) one get their turn
    def pool(state, k):
        if k == 0:
            return keep
        sig_k = signatures(pb, state, cands)
        tc_k = sorted([c for c in cands if c in sig_k], key=lambda c: -sig_k[c])
        return tc_k[:prune] + [c for c in cands if c not in sig_k]

    def refit(state, c):
        st = pb.add(state, c)
        ev = pb.evaluate(st)
        failed.extend(_failed_solves(" + ".join(a.label(pb.names) for a in st.added), ev))
        return st, ev

    def on_select(step):
        say(f"selected {step.cand.label(pb.names)}: gap {_combine(step.ev, floor)[0]:.2f} %")

    sel = forward_select(nom, ev0, floor, pool, refit, n_params=lambda c: _n_params(c, pb.user), max_effects=max_effects if keep else 0,
                         simpler=lambda rich, simple: NESTED.get(rich.effect) == simple.effect and rich.joint == simple.joint,
                         first=fitted, on_select=on_select)
    # an honest 'unexplained': a first effect that closes less than MIN_NAMED_SHRINK % of the
    # excess is not named (the least bad candidate is not a diagnosis); the search stops there
    if sel.steps and sel.steps[0].step_shrink < MIN_NAMED_SHRINK:
        sel = Selection([], nom, ev0, "weak", sel.steps[0])
    selected = []
    for st in sel.steps:
        selected.append(_entry(pb, st.cand, st.ev, ev0, floor, st.score))
        selected[-1]["step_shrink"] = st.step_shrink
    steps = [step_record(None, ev0, floor)] + [step_record(st.cand.label(pb.names), st.ev, floor) for st in sel.steps]
    state, ev_cur = sel.state, sel.ev
    # ambiguity: a known confounded pair whose held-out scores are too close to call
    ambiguous = []
    if len(ranking) >= 2 and significant:
        a, b = ranking[0], ranking[1]
        pair = frozenset((a["effect"], b["effect"]))
        if a["effect"] != b["effect"] and abs(a["shrink"] - b["shrink"]) < 5.0:
            ambiguous.append(dict(effects=[a["effect"], b["effect"]], joints=[a["joint"], b["joint"]],
                                  known_pair=pair in CONFOUNDED, shrink=[a["shrink"], b["shrink"]]))
    gap_after, _, exc_after = _combine(ev_cur, floor)
    shrink_total = float(np.clip(100 * (1 - exc_after / exc0), 0, 100)) if exc0 > 0 else 0.0
    verdict = _verdict(significant, _significant(ev_cur, floor), bool(sel.steps), shrink_total)
    wh = where(pb, ev0, floor, case)
    moves = link_moves(pb.robot, pb.inertia.pi0, nom.tfit.delta, pb.inertia) if pb.inertia is not None else []
    result = dict(
        case=str(case.path), verdict=verdict, stop_reason=_stop_reason(sel, pb.names),
        gap_before=gap0, gap_after=gap_after, noise_floor=fl,
        noise_floor_per_dataset=floor, noise_floor_source=floor_source, excess_before=exc0, excess_after=exc_after,
        shrink=shrink_total, inertia_refit=moves,
        processing={s_.name: s_.processing for s_ in pb.ttrain + pb.tval if s_.processing},
        significant=bool(significant), remaining_significant=bool(_significant(ev_cur, floor)),
        where=wh[:40], ranking=ranking, selected=selected, ambiguous=ambiguous, steps=steps,
        parameters=_parameters(pb, state), nominal_parameters=_parameters(pb, nom),
        unmatched_modes=[w for w in wh if w.get("unmatched")],
        responses_output_error=[s.name for s in pb.rval],
        responses_not_modelled=[d.name for d in pb.responses],
        failed_solves=failed,
        seconds=time.perf_counter() - t0,
        units={"gap": "NRMSE %", "noise_floor": "NRMSE %", "shrink": "% of the excess over noise closed"},
    )
    return Diagnosis(result, pb, nom, state, steps)


def _verdict(significant: bool, remaining: bool, named: bool, shrink: float) -> str:
    """``within_noise`` (no significant gap), ``explained`` (the named effects leave a gap within
    noise or close EXPLAINED_SHRINK % of the excess), ``partly_explained`` (they close at least
    MIN_NAMED_SHRINK %), else ``unexplained``."""
    if not significant:
        return "within_noise"
    if named and (not remaining or shrink >= EXPLAINED_SHRINK):
        return "explained"
    if named and shrink >= MIN_NAMED_SHRINK:
        return "partly_explained"
    return "unexplained"


def _stop_reason(sel: Selection, names) -> str:
    """Why the search stopped, in words (the report's and diagnosis.json's ``stop_reason``)."""
    best = sel.rejected.cand.label(names) if sel.rejected is not None else None
    why = {
        "not significant": "the nominal gap is within the noise floor: nothing to explain",
        "within noise": "what remains is within the noise floor",
        "max effects": "the most effects to add (max_effects) were added",
        "no candidate": "no candidate effect applies to these data",
        "too small": f"the best next candidate ({best}) closes less than {MIN_STEP_SHRINK:.0f} % of the remaining "
                     "excess or does not pay for its parameters on held-out data",
        "weak": f"the best candidate ({best}) closes only {sel.rejected.step_shrink:.0f} % of the excess gap "
                f"(less than {MIN_NAMED_SHRINK:.0f} %): no effect of the library explains the gap"
                if sel.rejected is not None else "",
    }
    return why.get(sel.stop, sel.stop)


def _failed_solves(model: str, ev: dict) -> list:
    """``failed_solves`` entries of one evaluated model: per output-error set whose simulation
    failed or diverged, the samples left non-finite or beyond 1000 % (counted at that cap)."""
    return [dict(model=model, dataset=k, samples=int(v["failed"]), of=int(v["samples"]))
            for k, v in ev.items() if v.get("failed")]


def _parameters(pb: Problem, st: State) -> dict:
    out = {}
    if st.tfit is not None:
        out["torque"] = T.term_parameters(st.tfit, pb.names)
    if st.lm is not None:
        sp = st.lm.structure.springs
        S = len(sp)
        lin = {}
        for i, s in enumerate(sp):
            nm = {"joint": pb.names[s.where], "orth": f"{pb.names[s.where]}_orth_{'ab'[s.axis]}",
                  "link": f"{pb.robot.link_names[s.where]}_bend_{'ab'[s.axis]}"}[s.kind]
            lin[nm] = {"stiffness [N m/rad]": float(np.exp(st.x[i])), "law": s.law,
                       {"viscous": "damping [N m s/rad]", "hysteretic": "loss factor eta",
                        "fractional": f"c [N m s^{s.alpha}/rad]"}[s.law]: float(np.exp(st.x[S + i]))}
        if st.lm.structure.payload:
            lin["payload"] = {"mass [kg]": float(np.exp(st.x[2 * S]))}
        for (a, b), r in zip(st.lm.pairs, st.lm.coupling(st.x)):
            nm = {"orth": f"{pb.names[sp[b].where]}_orth", "link": f"{pb.robot.link_names[sp[b].where]}_bend"}[sp[b].kind]
            lin[nm + "_coupling"] = {"r = k_ab / sqrt(k_a k_b)": float(r)}
        out["linear"] = lin
    return out
