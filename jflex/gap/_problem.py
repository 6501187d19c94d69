"""The diagnosed problem: a case's data prepared once (torque sets with their processing, FRF,
modal and output-error sets), the nominal identification (:meth:`Problem.nominal_state`), the
candidate effects (:meth:`Problem.candidates`), a candidate's refit on the training data
(:meth:`Problem.add`) and the evaluation of a model on the validation data (:meth:`Problem.evaluate`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .case._case import Case
from ._effect_term import EffectCandidate, EffectTerm
from .frequency._kinds import frequency_kinds, law_candidates
from .frequency._inertia import refit_linear_inertia, shifted
from .judge._noise import fits_to_noise
from .response._simulated import BASINS, polish_spring, scan_play, scan_spring
from ._inertia import inertia_prior
from .judge import _degenerate as D
from .frequency import _model as L
from .response import _response as R
from .torque import _set as T
from .torque._scale import dead_channels
from .torque._terms import KINDS, make_term
from .case._schema import Options
from ..effects._registry import CONFOUNDED, BACKLASH, JOINT_FLEXIBILITY, PAYLOAD, ROTOR_INERTIA

TORQUE_EFFECTS = tuple(KINDS)
# the schema's defaults, for a case built without its options (a Case made in code)
DEFAULT_OPTIONS = {k: Options.model_fields[k].default
                   for k in ("inertia_prior", "refit_inertia", "filter_cutoff_hz", "decimate", "max_effects")}


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
    springs: tuple = ()  # ((joint, (k, c, I_m)), ...) fitted through the simulation (:mod:`._simulated`)
    starts: tuple = ()  # ((joint, ((k, c, I_m), ...)), ...) the screening's starts for their identification


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
        self.lin_robot = self.robot  # the robot of the linear (FRF/modal) models: CAD, or as identified
        self.inertia_gain = None  # training BIC gain of the inertial refit (<= 0: CAD kept)
        self.lin_inertia = None  # the frequency side's nominal inertial refit (see _refit_linear_inertia)
        self.refit_nominal = None  # the nominal model with it, when offered
        self._refit_linear = False
        self.names = tuple(self.robot.joint_names)
        self.n = self.robot.nq
        # responses whose channels hold every model joint enter as equation-error (torque) sets
        self.options = dict(DEFAULT_OPTIONS, **(getattr(case, "options", None) or {}))
        # {set: effective samples of its noise}, once the noise floor has measured them
        # (:meth:`count_noise`): the held-out criterion's sample count
        self.noise_dof = {}
        proc = dict(cutoff_hz=self.options["filter_cutoff_hz"], decimate=int(self.options["decimate"]))
        self.ttrain = [T.torque_set(self.robot, d, **proc) for d in case.split("train") if _is_torque(d)]
        self.tval = [T.torque_set(self.robot, d, **proc) for d in case.split("validation") if _is_torque(d)]
        # the nominal identification refits the CAD inertial parameters (prior toward CAD, within
        # its tolerance) unless the case holds them fixed
        self.inertia = (inertia_prior(self.robot, float(self.options["inertia_prior"]))
                        if self.ttrain and self.options["refit_inertia"] else None)
        self.ftrain = [d for d in case.datasets if d.split == "train" and d.kind in ("frf", "modal")]
        self.fval = [d for d in case.datasets if d.split == "validation" and d.kind in ("frf", "modal")]
        # the others are simulated under their applied torques and compared as output error
        self.rval = [R.response_set(self.robot, d, case.tool_frame) for d in case.split("validation") if _is_output_error(d)]
        # training records of that kind fit the candidates only a simulation shows (:mod:`._simulated`)
        self.rtrain = [R.response_set(self.robot, d, case.tool_frame) for d in case.split("train") if _is_output_error(d)]
        # without held-out records of that kind to judge them, they are not used
        self.responses = [] if self.rval else [d for d in case.split("train") if _is_output_error(d)]
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
        self._screen_channels(case)
        # rotor inertia [kg m^2] the case states (nominal rotor_inertia with a value): the motor
        # side of a simulated spring when no torque training set fits it
        self.rotor_nominal = np.zeros(self.n)
        for e in case.nominal_effects:
            if e["effect"] == ROTOR_INERTIA and "value" in e:
                for j, v in zip(e["joints"], e["value"]):
                    self.rotor_nominal[self.names.index(j)] = v

    # --- data without signal, channels left out ------------------------------------------------
    def _screen_channels(self, case: Case) -> None:
        """Channels left out of the gap, and why (:attr:`excluded`, ``{set: {channel: reason}}``):
        those the data layer found dead, stuck or flat (a data set's ``excluded_channels``) and those
        without signal (:mod:`._degenerate`). A left-out training channel weighs nothing in the fits;
        a left-out validation channel enters neither the gap nor the noise floor. A data set without
        any signal is refused (:func:`._degenerate.refuse`)."""
        self.excluded = {}
        self.conditioning = {}
        for d in case.datasets:
            cond = getattr(d, "conditioning", None)
            if cond:
                self.conditioning[d.name] = cond
            for ch in getattr(d, "excluded_channels", ()) or ():
                flags = ((cond or {}).get("channels", {}).get(ch, {}) or {}).get("flags") if isinstance(cond, dict) else None
                self.excluded.setdefault(d.name, {})[str(ch)] = (
                    "left out by the data conditioning: " + (", ".join(map(str, flags)) if flags else "dead, stuck or flat"))
        refused = []
        for train, sets in ((True, self.ttrain), (False, self.tval)):
            for i, s in enumerate(sets):
                raw = next(d for d in case.datasets if d.name == s.name).arrays["tau"]
                bad, why = D.torque_channels(s.name, raw, s.F0, self.names)
                for ch, r in dead_channels(s, self.names).items():
                    if ch not in (self.options.get("keep_channels") or ()):
                        bad.setdefault(ch, r)
                drop = dict(self.excluded.get(s.name, {}))
                for ch, r in bad.items():
                    drop.setdefault(ch, r)
                if why is None and len(drop) >= self.n:
                    why = "every channel is left out (" + "; ".join(f"{c}: {r}" for c, r in drop.items()) + ")"
                if why is not None:
                    refused.append((s.name, why))
                    continue
                if drop:
                    self.excluded[s.name] = drop
                if drop and train:
                    # weight zero in every fit (rows normalised by 1 / scale); the values are held
                    # finite so that a non-finite reading cannot leak through a zero weight
                    out = np.array([nm in drop for nm in self.names])
                    sc = np.where(out, np.inf, s.scale)
                    tau = np.where(out[None, :], 0.0, np.nan_to_num(s.tau, nan=0.0, posinf=0.0, neginf=0.0))
                    sets[i] = dataclasses.replace(s, scale=sc, tau=tau, cache={})
        for d in self.ftrain + self.fval:
            if d.kind == "frf":
                why = D.frf_set(d.arrays["H"])
                if why is not None:
                    refused.append((d.name, why))
        D.refuse(refused)

    def included(self, name: str) -> np.ndarray:
        """(n,) bool: the torque channels of set ``name`` that enter the gap."""
        out = self.excluded.get(name, {})
        return np.array([nm not in out for nm in self.names])

    # --- nominal model -------------------------------------------------------------------------
    def nominal_state(self) -> State:
        terms, delay = [], 0.0
        for e in self.nominal_effects:
            kind = KINDS.get(e["effect"])
            if kind is None:
                continue
            if not kind.per_joint:
                terms.append(kind(None, float(e["value"][0]) if "value" in e else None))
                delay = terms[-1].delay if terms[-1].delay is not None else delay  # a nominal sensor delay's value
                continue
            for j in e["joints"]:
                terms.append(kind(self.names.index(j)))
        tfit = None
        if self.ttrain:
            held = T.fit_terms(tuple(terms), delay, self.ttrain)
            tfit = held
            if self.inertia is not None:
                # twice: the prior's weight is relative to the residual level of the fit itself
                self.inertia.sigma = T.with_inertia_sigma(held, self.ttrain)
                tfit = T.fit_terms(tuple(terms), delay, self.ttrain, self.inertia)
                self.inertia.sigma = T.with_inertia_sigma(tfit, self.ttrain)
                tfit = T.fit_terms(tuple(terms), delay, self.ttrain, self.inertia)
                # the refit must pay for the base parameters it frees (training BIC); CAD that
                # the data cannot fault is kept as it is (a refit to noise would only add noise)
                rows = sum(s.tau.size for s in self.ttrain)
                gain = rows * np.log(max(held.cost, 1e-300) / max(tfit.cost, 1e-300))
                self.inertia_gain = float(gain - T.inertia_rank(self.ttrain) * np.log(rows))
                if self.inertia_gain <= 0:
                    self.inertia = None
                    tfit = held
        lm = x = None
        if self.ftrain or self.fval:
            springs, x0 = [], []
            for e in self.nominal_effects:
                if e["effect"] == JOINT_FLEXIBILITY:
                    for j in e["joints"]:
                        springs.append(L.Site("joint", self.names.index(j)))
                    k = e.get("stiffness", np.full(len(e["joints"]), 1e5))
                    c = e.get("damping", 1e-3 * k)
                    x0.append((np.log(k), np.log(np.maximum(c, 1e-9))))
            # a nominal damping law of jflex.effects (hysteretic, fractional, ...) replaces the viscous
            # one at that joint; its loss starts where the viscous damping's is at the reference frequency
            laws = {}
            for e in self.nominal_effects:
                cls = law_candidates().get(e["effect"])
                if cls is not None:
                    protos = cls.prototypes()
                    for j in e["joints"]:
                        laws[self.names.index(j)] = protos[len(protos) // 2]
            if laws:
                w = 2 * np.pi * self._ref_freq()
                flat = [(i, s) for i, s in enumerate(springs)]
                cs_all = np.concatenate([b for _, b in x0])
                for i, s in flat:
                    if s.where in laws:
                        cs_all[i] = cs_all[i] + np.log(w / np.abs(L.unit_loss(laws[s.where], w)))
                x0 = [(np.concatenate([a for a, _ in x0]), cs_all)]
            springs = [dataclasses.replace(s, law=laws.get(s.where, s.law)) for s in springs]
            ks = np.concatenate([a for a, _ in x0]) if x0 else np.zeros(0)
            cs = np.concatenate([b for _, b in x0]) if x0 else np.zeros(0)
            structure = L.Structure(tuple(springs), payload=False)
            x = np.concatenate([ks, cs])
            if tfit is not None and tfit.delta is not None:
                # the torque data identified the inertial parameters: the linear model uses them
                self.lin_robot = self.robot.replace(inertia=np.asarray(self.robot.inertia) + tfit.delta.reshape(self.n, 10))
            # else the frequency data refit them, with the nominal springs
            self._refit_linear = bool(self.options["refit_inertia"]) and self.lin_robot is self.robot
            lm = self._frequency_model(self.lin_robot, structure)
            if self.ftrain and len(springs):
                x, _ = L.fit_linear(lm, x, self.ftrain)
                if self._refit_linear:
                    self._refit_linear_inertia(tfit, lm, x)
        return State(tfit, lm, x)

    def _refit_linear_inertia(self, tfit, lm, x):
        """The frequency side's nominal identification when no torque data identified the inertial
        parameters (:mod:`._frequency_inertia`): the CAD inertias refitted with the nominal springs,
        offered as :attr:`refit_nominal` when it pays for its parameters on the training data and
        closes at least ``MIN_NAMED_SHRINK`` % of the held-out frequency-side gap (a CAD error is
        most of that gap; a refit that bends the inertias around a missing effect predicts a new
        posture no better, or worse). Without held-out frequency data: when it fits every training
        set to noise. The diagnosis then judges it against the candidate effects on CAD
        (:func:`._diagnose.diagnose`)."""
        from .judge._selection import MIN_NAMED_SHRINK

        prior = inertia_prior(self.robot, float(self.options["inertia_prior"]))
        delta, x2, gain = refit_linear_inertia(lm, x, self.ftrain, prior)
        offered, held_out = False, None
        if gain > 0:
            refit = self._frequency_model(self.robot.replace(inertia=np.asarray(self.robot.inertia) + delta.reshape(self.n, 10)),
                                           lm.structure)
            if self.fval:
                g0, g1 = (np.sqrt(np.mean([v["nrmse"] ** 2 for v in self.evaluate(State(None, m, xm), frequency_only=True).values()]))
                          for m, xm in ((lm, x), (refit, x2)))
                held_out = (float(g0), float(g1))
                offered = g1 <= (1 - MIN_NAMED_SHRINK / 100) * g0
            else:
                offered = fits_to_noise(shifted(lm, delta), x2, self.ftrain, self.case)
            if offered:
                self.refit_nominal = State(tfit, refit, x2)
        self.lin_inertia = dict(prior=prior, delta=delta, gain=gain, offered=offered, used=False, held_out=held_out,
                                reason="")

    # --- candidates ----------------------------------------------------------------------------
    def candidates(self) -> list[Candidate]:
        out = []
        nom = {e for e, _ in self.nominal}
        if self.ttrain:
            for eff, kind in KINDS.items():
                if not kind.per_joint:
                    if eff not in nom:
                        out.append(Candidate(eff, None))
                    continue
                for j in kind.joints(self.n):
                    if (eff, j) in self.nominal or (kind.subsumed_by, j) in self.nominal:
                        continue
                    out.append(Candidate(eff, j))
        if self.ttrain:
            out += list(self.user)
        if self.ftrain:
            flex = {s.where for s in self._nominal_springs()}
            kinds = frequency_kinds()
            for j in range(self.n):
                out += [Candidate(name, j) for name, k in kinds.items() if k.per_joint and k.tried_at(self, j, flex)]
            out += [Candidate(name, None) for name, k in kinds.items() if not k.per_joint and k.tried_at(self, None, flex)]
        if self.rtrain and self.rval:
            flex = {s.where for s in self._nominal_springs()}
            out += [Candidate(JOINT_FLEXIBILITY, j) for j in range(self.n) if j not in flex]
            # play inside a spring: tried at every joint, a no-op until a spring is placed there
            out += [Candidate(BACKLASH, j) for j in range(self.n) if (BACKLASH, j) not in self.nominal]
        return list(dict.fromkeys(out))

    def _nominal_springs(self):
        return [L.Site("joint", self.names.index(j)) for e in self.nominal_effects
                if e["effect"] == JOINT_FLEXIBILITY for j in e["joints"]]

    def changes(self, state: State, cand: Candidate) -> bool:
        """False for a candidate that adds nothing to ``state``: backlash on tip records alone is
        play inside a spring the simulation holds, and there is none at its joint yet (it becomes a
        candidate once a spring is placed there; until then it is neither refitted nor ranked)."""
        if cand.effect != BACKLASH or self.ttrain or not (self.rtrain and self.rval):
            return True
        if self.ftrain and state.lm is not None:
            return False  # FRF/modal data place the springs: no tip-side play on them (see add)
        return cand.joint in self.sim_springs(state)

    def screened_by_simulation(self, state: State, cand: Candidate) -> bool:
        """Whether ``cand`` added to ``state`` is found by simulated screening (:mod:`._simulated`):
        a new compiled simulation each time it is tried on a new base model. (On output-error
        records ``backlash`` is play inside a spring the simulation holds, screened and identified
        with it, :meth:`add`; the torque side's backlash, on torque records, is its own term.)"""
        return cand.effect == JOINT_FLEXIBILITY and bool(self.rtrain) and not (self.ftrain and state.lm is not None)

    # --- refits --------------------------------------------------------------------------------
    def add(self, state: State, cand: Candidate) -> State:
        """Refit with ``cand`` added (warm start from ``state``)."""
        tfit, lm, x = state.tfit, state.lm, state.x
        if cand in self.user and self.ttrain:
            tfit = T.fit_with(tfit.terms, tfit.delay, EffectTerm(self.user[cand], cand.joint), self.ttrain, self.inertia)
        elif cand.effect in KINDS and self.ttrain:
            tfit = T.fit_with(tfit.terms, tfit.delay, make_term(cand.effect, cand.joint), self.ttrain, self.inertia)
        kind = frequency_kinds().get(cand.effect)
        if kind is not None and self.ftrain and lm is not None:
            lm, x = kind.add(self, lm, x, cand.joint)
        springs = state.springs
        if cand.effect == BACKLASH and self.rtrain and self.rval and not (self.ftrain and lm is not None):
            # play inside the spring the simulation holds at the joint (none there yet: nothing to add)
            held = State(tfit, lm, x, state.added, springs)
            sp = self.sim_springs(held)
            if cand.joint in sp:
                # identified before it is judged: the screened play's held-out gap hung on which
                # grid point lay nearest (the motor's start angle and the damping held there), and
                # the identification is the one costly fit either way (a selected spring's is later)
                found = scan_play(self.robot, tfit, sp, self._rotor(), cand.joint, self.rtrain)
                ident = polish_spring(self.robot, tfit, sp, self._rotor(), cand.joint, found, self.rtrain)
                springs = tuple((j, v) for j, v in springs if j != cand.joint) + ((cand.joint, ident),)
                starts = dict(state.starts)
                starts[cand.joint] = (ident,)
                return State(tfit, lm, x, state.added + (cand,), springs, tuple(starts.items()))
            return State(tfit, lm, x, state.added + (cand,), springs, state.starts)
        if self.screened_by_simulation(state, cand):
            # no FRF/modal data place the spring: the output-error training records do
            held = State(tfit, lm, x, state.added, springs)
            found = scan_spring(self.robot, tfit, self.sim_springs(held), self._rotor(), cand.joint, self.rtrain, basins=BASINS)
            springs = tuple((j, v) for j, v in springs if j != cand.joint) + ((cand.joint, found[0]),)
            starts = dict(state.starts)
            starts[cand.joint] = tuple(found)
            return State(tfit, lm, x, state.added + (cand,), springs, tuple(starts.items()))
        return State(tfit, lm, x, state.added + (cand,), springs, state.starts)

    def _frequency_model(self, robot, structure):
        return L.FrequencyModel(robot, structure, self.case.tool_frame)

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
                d = k + v * complex(L.unit_loss(s.law, w))
                k, c = d.real, d.imag / w
                out[s.where] = (k, c)
            return out
        for e in self.nominal_effects:
            if e["effect"] == JOINT_FLEXIBILITY and "stiffness" in e:
                c = e.get("damping", 1e-3 * e["stiffness"])
                for j, kj, cj in zip(e["joints"], e["stiffness"], c):
                    if kj > 0:
                        out[self.names.index(j)] = (float(kj), float(cj))
        out.update(dict(state.springs))
        return out

    def polish(self, state: State, joints) -> State:
        """``state`` with the simulation-screened springs at ``joints`` identified
        (:func:`._simulated.polish_spring`), the others held."""
        springs = dict(state.springs)
        for j in joints:
            held = dataclasses.replace(state, springs=tuple(springs.items()))
            others = {i: v for i, v in self.sim_springs(held).items() if i != j}
            # the screening's starts (the springs held then are the ones held now: a spring is
            # identified as soon as it is selected)
            starts = dict(state.starts).get(j) or scan_spring(self.robot, state.tfit, others, self._rotor(), j, self.rtrain,
                                                            basins=BASINS)
            springs[j] = polish_spring(self.robot, state.tfit, others, self._rotor(), j, list(starts), self.rtrain)
        return dataclasses.replace(state, springs=tuple(springs.items()))

    def _rotor(self):
        """Rotor inertias [kg m^2] the case states (None when torque training data fit them)."""
        return None if self.ttrain else self.rotor_nominal

    def simulation_model(self, state: State):
        """The model a tip (output-error) set is simulated with (:func:`._response.simulation_model`);
        rotor inertia from the nominal ``value`` when no torque training set fits it."""
        return R.simulation_model(self.robot, state.tfit, self.sim_springs(state), self._rotor())

    # --- evaluation ----------------------------------------------------------------------------
    def count_noise(self, details: dict, ev: dict | None = None) -> None:
        """The held-out criterion's sample counts from the noise floor's ``details``
        (:func:`._noise.noise_floor`): per torque validation set the effective samples of its
        noise summed over its channels (their own autocorrelation: coloured or quantised noise,
        and the parallel low-pass, leave far fewer independent samples than rows), at most one in
        NEFF_SPACING rows as before; ``ev`` (an evaluation made before) is updated in place."""
        for s in self.tval:
            d = details.get(s.name) or {}
            dof = d.get("channel_dof")
            if not dof:
                continue
            rows = np.sum(self.included(s.name)) * len(s.t) / NEFF_SPACING
            self.noise_dof[s.name] = float(min(rows, sum(dof.values())))
            if ev is not None and s.name in ev:
                ev[s.name]["neff"] = self.noise_dof[s.name]

    def evaluate(self, state: State, sets="validation", frequency_only: bool = False) -> dict:
        """Per data set: nrmse [%], per channel [%], mse and effective sample count
        (``frequency_only``: the FRF and modal sets alone)."""
        tsets = [] if frequency_only else self.tval if sets == "validation" else self.ttrain
        fsets = self.fval if sets == "validation" else self.ftrain
        out = {}
        if sets == "validation" and self.rval and not frequency_only:
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
            if s.weight is not None:
                e = e * s.weight  # masked samples (a clipping sensor's) carry no residual
            m = self.included(s.name) if sets == "validation" else np.isfinite(s.scale)
            g, ch, w = pooled_gap(e, s.scale, m, s.weight)
            out[s.name] = dict(kind="torque", nrmse=g,
                               channels={self.names[j]: float(ch[j]) for j in range(self.n) if m[j]},
                               weights={self.names[j]: float(w[j]) for j in range(self.n) if m[j]},
                               neff=self.noise_dof.get(s.name, e[:, m].size / NEFF_SPACING), resid=e)
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


NEFF_SPACING = 10.0  # rows per effective sample of a torque set when its noise is not measured


def pooled_gap(e, scale, m, weight=None) -> tuple[float, np.ndarray, np.ndarray]:
    """A torque set's gap [%] from its residual ``e`` (N, n) in units of each joint's torque spread
    ``scale`` (n,), over the channels ``m`` (n,) bool: ``(gap, per-joint NRMSE [%], weights)``.
    The joints are pooled as residual energy over torque-signal energy,
    ``sqrt(sum_j mse_j / sum_j scale_j^2)``: each joint's NRMSE^2 weighs by its share of the signal
    energy, ``scale_j^2 / sum scale^2``, so that a near-idle joint, whose small spread makes any
    error a large NRMSE, cannot outvote a loaded one; left-out channels weigh nothing. With
    ``weight`` (N, n), a channel's mean is over its samples of nonzero weight (masked ones zero in ``e``)."""
    e, scale, m = np.asarray(e, float), np.asarray(scale, float), np.asarray(m, bool)
    rows = e.shape[0] if weight is None else np.maximum(np.count_nonzero(weight, axis=0), 1)
    ch = np.sqrt(np.sum(e**2, axis=0) / rows) * 100
    w = np.where(m, np.where(np.isfinite(scale), scale, 0.0), 0.0) ** 2
    w = w / w.sum() if w.sum() > 0 else w
    return float(np.sqrt(np.sum(np.where(m, w * ch**2, 0.0)))), ch, w


def parameters(pb: Problem, st: State) -> dict:
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
            k, c = float(np.exp(st.x[i])), float(np.exp(st.x[S + i]))
            lin[nm] = {"stiffness [N m/rad]": k, "law": L.law_name(s.law)}
            if isinstance(s.law, L.KelvinVoigt):
                lin[nm]["damping [N m s/rad]"] = c
            else:
                lin[nm][type(s.law).loss] = c / k
                if type(s.law).shape:
                    lin[nm][type(s.law).shape[0]] = float(getattr(s.law, type(s.law).shape[0]))
        if st.lm.structure.payload:
            lin[PAYLOAD] = st.lm.payload_parameters(st.x)
        for (a, b), r in zip(st.lm.pairs, st.lm.coupling(st.x)):
            nm = {"orth": f"{pb.names[sp[b].where]}_orth", "link": f"{pb.robot.link_names[sp[b].where]}_bend"}[sp[b].kind]
            lin[nm + "_coupling"] = {"r = k_ab / sqrt(k_a k_b)": float(r)}
        out["linear"] = lin
    if st.springs:
        out["simulated"] = {pb.names[j]: {"stiffness [N m/rad]": v[0], "damping [N m s/rad]": v[1], "rotor inertia [kg m^2]": v[2],
                                          **({"play [rad]": v[3]} if len(v) > 3 else {})}
                            for j, v in st.springs}
    return out
