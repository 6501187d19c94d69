"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, how far it
shrinks once that effect is added and refitted, judged on held-out validation data.

The gap of a validation data set is its NRMSE [%]: torques the residual energy over the
torque-signal energy pooled over the joints, ``sqrt(sum_j mse_j / sum_j std(tau_j)^2)`` (each
joint's own NRMSE ``rms(tau_model - tau) / std(tau)`` weighs by its share of the signal, so that a
near-idle joint cannot outvote a loaded one; channels without signal, or left out by the data
conditioning, do not enter); FRFs ``sqrt(sum |H_model - H|^2 / sum |H|^2)`` per entry; modal tables
the RMS relative frequency error (unmatched measured modes included through their nearest model
mode) plus ``0.1 x`` the relative damping error; output-error responses (channels lacking some
joint, e.g. tip coordinates, simulated under their applied torques from rest at ``q0``,
:mod:`._response`) ``rms(y_model - y) / scale`` per channel. The noise floor is the NRMSE that
measurement noise alone would leave (:func:`._noise.noise_floor`: repeated records, the scatter
between the periods of a periodic motion, else a black-box model's held-out error; never a
candidate's residual), with its confidence interval; the *excess* gap
``sqrt(max(nrmse^2 - floor^2, 0))`` is what a model can close: ``shrink`` is the percentage of
the excess closed. An effect that makes some joint worse beyond that joint's own floor, or whose
fit is implausible, is never named.
"""


from __future__ import annotations

import dataclasses
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .case._case import Case, load_case
from .frequency._inertia import cad_spread
from ._inertia import inertia_prior, link_moves
from .response._response import cad_spread as cad_spread_response
from .judge._noise import noise_floor
from ._problem import CONFOUNDED, Candidate, Problem, State, parameters
from .judge._selection import (FAMILY_ALPHA, SIGNIFICANCE, gap_uncertainty, significance_factor, MIN_GAP, MIN_NAMED_SHRINK, MIN_STEP_SHRINK, NESTED, SWAP_SHRINK, forward_select, gap_summary,
                         ic_delta, decisive, swap_rivals, is_significant, joints_beyond_floor, pooled_upper, rank_entries, step_record, stop_reason, verdict, vetoed,
                         worse_channels)
from .frequency._kinds import frequency_kinds
from .judge._signatures import indistinguishable_from_inertia, n_params, signature_name, signatures
from .torque._scale import scale_reason, torque_scale_suspects
from .judge._where import where

@dataclasses.dataclass
class Diagnosis:
    """Everything ``diagnosis.json`` holds, plus the fitted states for plots."""

    result: dict
    problem: Problem
    nominal: State
    final: State
    steps: list


UNPREDICTED_FACTOR = 3.0  # x the other joints' median floor: a gap no noise level of theirs explains


def _unpredicted(ev, details) -> list:
    """``(set, channel, gap %)`` of the channels whose black-box floor predicted none of their
    residual while their gap is over UNPREDICTED_FACTOR x the median floor of the set's other
    channels (relative to their own torque: a noise level the sensors share)."""
    out = []
    for k, d in details.items():
        bad = set(d.get("unpredicted", ()))
        others = [v for c, v in (d.get("channels") or {}).items() if c not in bad]
        if not bad or not others:
            continue
        for c in sorted(bad):
            g = ev.get(k, {}).get("channels", {}).get(c)
            if g is not None and g > UNPREDICTED_FACTOR * float(np.median(others)) + MIN_GAP:
                out.append((k, c, float(g)))
    return out


def _entry(problem, c: Candidate, ev, ev0, floor, score, sig=None, channel_floor=None, state=None, channel_rel=None):
    gap, fl, exc = gap_summary(ev, floor)
    _, _, exc0 = gap_summary(ev0, floor)
    shrink = 100.0 * (1 - exc / exc0) if exc0 > 0 else 0.0
    g0 = gap_summary(ev0, floor)[0]
    on_link = getattr(frequency_kinds().get(c.effect), "on_link", False)
    e = dict(effect=c.effect, joint=None if c.joint is None or on_link else problem.names[c.joint],
             link=problem.robot.link_names[c.joint] if on_link else None,
             score=float(score), gap_after=gap, shrink=float(np.clip(shrink, 0, 100)),
             shrink_raw=float(100 * (1 - gap / g0)) if g0 > 0 else 0.0,
             per_dataset={k: v["nrmse"] for k, v in ev.items()},
             per_channel={k: dict(v["channels"]) for k, v in ev.items()},
             worse_channels=worse_channels(ev, ev0, channel_floor, channel_rel))
    why = _implausible(problem, c, state)
    if why:
        e["implausible"] = why
    if sig is not None:
        e["signature"] = {"name": _torque_signature(signature_name(c.effect)), "value": float(sig)}
    return e


def _torque_signature(text: str) -> str:
    """A signature's description as the torque residual shows it (a signature value is computed on
    torque data only): a kind described on both sides ("extra FRF peak ...; in torques, ...") keeps
    its torque side."""
    key = "in torques, "
    return text[text.index(key) + len(key):] if key in text else text


def _implausible(problem, cand, state):
    """Why a candidate's fit in ``state`` is implausible (values no machine has), else None
    (:func:`._torque_terms.implausible`, where the torque terms carry plausible ranges)."""
    from .torque import _terms as TT

    f = getattr(TT, "implausible", None)
    if f is None or state is None or not problem.ttrain:
        return None
    return f(problem, cand, state) or None


def _channel_floors(details) -> dict:
    return {k: dict(v.get("channels", {})) for k, v in details.items()}


def _factors(details, ev) -> tuple[dict, dict, int]:
    """The margins of "beyond the floor" (:func:`._selection.significance_factor`) per set and per
    torque channel, at one family-wise level over all the tests a diagnosis makes on the nominal
    gap (every validation set pooled, and every torque channel), and that number of tests."""
    tests = len(ev) + sum(len(v.get("channel_dof") or {}) for v in details.values())
    factor = {k: significance_factor(v["dof"], tests) for k, v in details.items() if v.get("dof") is not None}
    cfactor = {k: {c: significance_factor(d, tests) for c, d in (v.get("channel_dof") or {}).items()}
               for k, v in details.items()}
    return factor, cfactor, tests


def _upper(details) -> dict:
    return {k: v["high"] for k, v in details.items() if v.get("high") is not None}


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
    floor_source, floor_details = {}, {}
    floor = noise_floor(pb, ev0, case, floor_source, floor_details)
    pb.count_noise(floor_details, ev0)
    cands = pb.candidates()
    sig = signatures(pb, nom, cands)
    held = indistinguishable_from_inertia(pb, cands)
    tc = sorted([c for c in cands if c in sig], key=lambda c: -sig[c])
    keep = tc[:prune] + [c for c in cands if c not in sig]
    keep_all = list(keep)  # a candidate that changes nothing yet (pb.changes) may in a later round
    off_scale = torque_scale_suspects(pb, nom)
    if off_scale:
        # a gain on the whole torque is no effect of the library: whatever absorbed most of it would be named
        say(scale_reason(off_scale))
        keep = keep_all = []
    failed = _failed_solves("nominal", ev0)

    def first_round(base):
        def one(c):
            st = pb.add(base, c)
            return st, pb.evaluate(st)

        todo = [c for c in keep if pb.changes(base, c)]
        # simulated screenings side by side: one traces its program (Python) while another's
        # compiles and runs (XLA, outside the interpreter lock); each is independent of the others
        par = [c for c in todo if pb.screened_by_simulation(base, c)]
        done = {}
        if len(par) > 1:
            with ThreadPoolExecutor(min(len(par), SCREEN_THREADS)) as ex:
                done = dict(zip(par, ex.map(one, par)))
        out = {}
        for c in todo:
            st, ev = done[c] if c in done else one(c)
            failed.extend(_failed_solves(c.label(pb.names), ev))
            out[c] = (st, ev)
        return out

    fitted = None
    if pb.refit_nominal is not None:
        nom, ev0, floor, floor_source, floor_details, fitted = _choose_base(pb, case, nom, ev0, floor, floor_source,
                                                                            floor_details, first_round)
        if fitted is not None and not fitted:
            keep = []
    say(f"gap {gap_summary(ev0, floor)[0]:.2f} % (noise floor {gap_summary(ev0, floor)[1]:.2f} %), "
        f"{len(cands)} candidates, {sum(pb.changes(nom, c) for c in keep)} refitted")
    ranking = []
    if fitted is None:
        fitted = first_round(nom)
    keep = [c for c in keep if c in fitted]
    # (the floor is never bounded by a candidate's held-out gap: that would count the model error
    # the candidate does not hold as noise)
    cfloor, upper = _channel_floors(floor_details), _upper(floor_details)
    factor, cfactor, tests = _factors(floor_details, ev0)
    crel = {k: {c: gap_uncertainty(d) for c, d in (v.get("channel_dof") or {}).items()} for k, v in floor_details.items()}
    gap0, fl, exc0 = gap_summary(ev0, floor)
    for c in keep:
        st, ev = fitted[c]
        score = -ic_delta(ev, ev0, n_params(c, pb.user, bool(pb.ttrain), pb))
        ranking.append(_entry(pb, c, ev, ev0, floor, score, sig.get(c), cfloor, st, crel))
        say(f"  {c.label(pb.names)}: gap {ranking[-1]['gap_after']:.2f} %, shrink {ranking[-1]['shrink']:.0f} %")
    significant = is_significant(ev0, floor, upper, factor) or decisive(ranking)
    # a gap confined to a light joint (a wrist's: 1e-6 of the torque energy) never shows pooled:
    # the joint beyond its own floor is a gap of its own, which only an effect resolving that joint
    # on its own evidence may explain
    joint_only = not significant and bool(joints_beyond_floor(ev0, cfloor, cfactor))
    order = rank_entries(ranking)
    ranking = [ranking[i] for i in order]
    keep = [keep[i] for i in order]
    alone = {c: e["shrink"] for c, e in zip(keep, ranking)}

    # forward selection; after the first step the residual changed: the signatures are ranked
    # again so that effects masked by the first (larger) one get their turn
    def pool(state, k):
        if k == 0:
            return keep
        # a candidate found by simulated screening costs a new compiled simulation on each new
        # base model (~20 s on 2 cores): tried again only when alone it closed RESCREEN_SHRINK % of the gap
        keep_k = [c for c in keep_all if pb.changes(state, c)
                  and not (pb.screened_by_simulation(state, c) and alone.get(c, 100.0) < RESCREEN_SHRINK)]
        sig_k = signatures(pb, state, cands)
        tc_k = sorted([c for c in cands if c in sig_k], key=lambda c: -sig_k[c])
        # frequency-side candidates have no signature: the later rounds refit the ``prune`` that did
        # best alone (all of them each round cost a 6-joint FRF case 230 s)
        return tc_k[:prune] + [c for c in dict.fromkeys(keep + keep_k) if c not in sig_k and c in keep_k][:prune]

    def refit(state, c):
        st = pb.add(state, c)
        ev = pb.evaluate(st)
        failed.extend(_failed_solves(" + ".join(a.label(pb.names) for a in st.added), ev))
        return st, ev

    def on_select(step):
        say(f"selected {step.cand.label(pb.names)}: gap {gap_summary(step.ev, floor)[0]:.2f} %")

    simulated = {}

    def refine(step):
        # a spring screened by simulation is identified (output error through jflex.simulate) once it
        # is selected, before the next round builds on it: one costly fit per selected spring
        j = step.cand.joint
        # (play inside a spring is identified before it is judged: Problem.add)
        if step.cand.effect != "joint_flexibility" or j not in dict(step.state.springs):
            return step.state, step.ev
        say(f"identifying the spring at {pb.names[j]} through the simulation")
        st = pb.polish(step.state, [j])
        ev = pb.evaluate(st)
        simulated[pb.names[j]] = dict(gap_screened=gap_summary(step.ev, floor)[0], gap_identified=gap_summary(ev, floor)[0])
        return st, ev

    sel = forward_select(nom, ev0, floor, pool, refit, refine=refine, n_params=lambda c: n_params(c, pb.user, bool(pb.ttrain), pb), max_effects=max_effects if keep else 0,
                         simpler=lambda rich, simple: NESTED.get(rich.effect) == simple.effect and rich.joint == simple.joint,
                         first=fitted, on_select=on_select, significant=significant or joint_only, joint_only=joint_only,
                         channel_floor=cfloor, upper=upper, implausible=lambda c, st: _implausible(pb, c, st),
                         factor=factor, channel_factor=cfactor, channel_rel=crel,
                         # an honest 'unexplained': a first effect closing less than MIN_NAMED_SHRINK % of
                         # the excess is not named (the least bad candidate is not a diagnosis), unless it
                         # supplies a measured mode the model lacked (a missing degree of freedom)
                         min_first_shrink=lambda st: (MIN_STEP_SHRINK if supplies_missing_mode(ev0, st.ev)
                                                      else MIN_NAMED_SHRINK))
    swaps = []
    if sel.steps and not any(st.cand.effect == "joint_flexibility" or pb.screened_by_simulation(nom, st.cand)
                             for st in sel.steps):
        # a rival that alone closed nearly as much may hold the data's shape beside the other
        # effects (rebuilt with plain refits: a spring identified through the simulation is not)
        def richer(k, c):
            return NESTED.get(k.effect) == c.effect and k.joint == c.joint

        def rivals(c):
            # the richer law containing a selected one is tried beside the others (alone, the
            # parsimony rule judged the pair); a simpler one never replaces the richer
            nested = [k for k in keep if richer(k, c)]
            return nested + [k for k in keep if k != c and k.joint == c.joint and k.effect != c.effect
                             and NESTED.get(k.effect) != c.effect and NESTED.get(c.effect) != k.effect
                             and k.effect != "joint_flexibility" and not pb.screened_by_simulation(nom, k)
                             and abs(alone.get(k, -1e9) - alone.get(c, 1e9)) < SWAP_SHRINK][:2]

        sel, swaps = swap_rivals(sel, ev0, floor, rivals, refit,
                                 n_params=lambda c: n_params(c, pb.user, bool(pb.ttrain), pb),
                                 channel_floor=cfloor, implausible=lambda c, st: _implausible(pb, c, st), richer=richer,
                                 channel_rel=crel)
        for old_c, new_c, e0, e1 in swaps:
            say(f"{new_c.label(pb.names)} takes the place of {old_c.label(pb.names)}: excess {e0:.2f} -> {e1:.2f} %")
    selected = []
    for st in sel.steps:
        selected.append(_entry(pb, st.cand, st.ev, ev0, floor, st.score, None, cfloor, st.state, crel))
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
    gap_after, _, exc_after = gap_summary(ev_cur, floor)
    shrink_total = float(np.clip(100 * (1 - exc_after / exc0), 0, 100)) if exc0 > 0 else 0.0
    floor_high = pooled_upper(floor, upper)
    remaining = is_significant(ev_cur, floor, upper, factor) or (joint_only and bool(joints_beyond_floor(ev_cur, cfloor, cfactor)))
    significant = significant or joint_only
    verdict_ = verdict(significant, remaining, bool(sel.steps), shrink_total,
                       gap_after=gap_after, floor_upper=floor_high)
    reason = stop_reason(sel, pb.names)
    failed_floor = {k: v["reason"] for k, v in floor_details.items() if v.get("failed")}
    spread = _cad_spread(pb, nom) if verdict_ == "unexplained" else {}
    if spread and not is_significant(ev0, {k: float(np.hypot(f, spread.get(k, 0.0))) for k, f in floor.items()},
                                     factor=factor):
        # nothing explains the gap, and the CAD tolerance alone spreads the model that far on data
        # that cannot identify the inertias: no alarm (a claim of an unmodelled effect would be unfounded)
        verdict_ = "within_noise"
        reason = ("no candidate explains the gap, and it is within the spread that the CAD inertias' tolerance "
                  "gives on these data (" + ", ".join(f"{k}: {v:.2f} %" for k, v in spread.items()) +
                  "), which cannot identify the inertias: the data do not fault the nominal model")
    cad_far = None
    if verdict_ == "unexplained" and not off_scale and not failed_floor:
        cad_far = _cad_beyond_tolerance(pb, nom, floor, upper, factor, cfloor, cfactor)
        if cad_far is not None:
            # a nominal refit held at its CAD tolerance is no unmodelled effect: with the
            # tolerance widened the nominal model alone is within noise
            verdict_ = "within_noise"
            reason = ("no candidate explains the gap, and the nominal model's inertial refit stopped at its CAD "
                      f"tolerance; with {CAD_WIDE_REACH / 2:g} x that tolerance it leaves {cad_far['gap']:.2f} % "
                      "(within noise): the CAD is further off than its tolerance (" + "; ".join(
                          f"{x['link']}: {', '.join(x['parameters'])}" for x in cad_far["links"]) +
                      "), no unmodelled effect is needed")
    if failed_floor:
        # a gap cannot be judged against a noise level nobody knows: no confident verdict
        verdict_ = "floor_unknown"
        reason = ("the noise floor could not be estimated (" + "; ".join(f"{k}: {v}" for k, v in failed_floor.items()) +
                  "): the gap is reported against no floor, and whether it exceeds the noise is unknown"
                  + (f"; {reason}" if reason else ""))
    if off_scale:
        reason = scale_reason(off_scale) + (f"; {reason}" if failed_floor else "")
    hidden = _unpredicted(ev0, floor_details)
    if hidden and verdict_ in ("within_noise", "explained"):
        # a channel's floor that is its own residual cannot clear it: say so rather than let the
        # pooled verdict speak for that joint
        reason = ((f"{reason}; " if reason else "") + "the floors of " + ", ".join(
            f"{c} in {k} (gap {g:.2f} %)" for k, c, g in hidden) + " are their own residual: no function of the "
            "motion predicted any of it, so whether those joints' gaps are noise is unknown")
    wh = where(pb, ev0, floor, case, channel_floor=cfloor)
    moves, inertia_note = _inertia_report(pb, nom)
    result = dict(
        case=str(case.path), verdict=verdict_, stop_reason=reason, cad_spread=spread, torque_scale_suspects=off_scale,
        gap_before=gap0, gap_after=gap_after, noise_floor=fl, noise_floor_upper=floor_high,
        noise_floor_per_dataset=floor, noise_floor_source=floor_source, noise_floor_details=floor_details,
        noise_floor_failed=failed_floor, excess_before=exc0, excess_after=exc_after,
        gap_weighting=GAP_WEIGHTING,
        channel_gaps=dict(before={k: dict(v["channels"]) for k, v in ev0.items()},
                          after={k: dict(v["channels"]) for k, v in ev_cur.items()},
                          weights={k: dict(v["weights"]) for k, v in ev0.items() if "weights" in v}),
        excluded_channels={k: dict(v) for k, v in pb.excluded.items()}, conditioning=_jsonable(pb.conditioning),
        vetoed=[dict(round=r_, candidate=c_.label(pb.names), reason=w_) for r_, c_, w_ in sel.vetoed],
        shrink=shrink_total, inertia_refit=moves, inertia=inertia_note, cad_beyond_tolerance=cad_far,
        # candidates whose torques are a change of the refitted inertias on these motions: the refit's
        # tolerance, not the data, splits them from a CAD error
        confounded_with_inertia_refit=[dict(effect=c.effect, joint=None if c.joint is None else pb.names[c.joint],
                                    relative_residual=float(v)) for c, v in held.items()],

        processing={s_.name: s_.processing for s_ in pb.ttrain + pb.tval if s_.processing},
        significant=bool(significant), remaining_significant=bool(remaining),
        joints_beyond_floor=[dict(dataset=k, channel=c) for k, c in joints_beyond_floor(ev0, cfloor, cfactor)],
        test=dict(family_alpha=FAMILY_ALPHA, tests=tests, min_gap=MIN_GAP, factor=factor, channel_factor=cfactor,
                  rule="a gap lies beyond its floor when it exceeds factor x the floor + min_gap [%]: factor is the "
                       "square root of the F(dof, dof) quantile at 1 - family_alpha / tests (dof: the noise's effective "
                       f"samples), at least {SIGNIFICANCE:g}; one family-wise level over every set and joint tested"),
        where=wh[:40], ranking=ranking, selected=selected, ambiguous=ambiguous, steps=steps,
        swapped=[dict(replaced=a.label(pb.names), by=b.label(pb.names), excess_before=e0, excess_after=e1)
                 for a, b, e0, e1 in swaps],
        parameters=parameters(pb, state), nominal_parameters=parameters(pb, nom),
        unmatched_modes=[w for w in wh if w.get("unmatched")],
        responses_output_error=[s.name for s in pb.rval],
        responses_fitted=[s.name for s in pb.rtrain], simulated_refit=simulated,
        responses_not_modelled=[d.name for d in pb.responses],
        failed_solves=failed,
        seconds=time.perf_counter() - t0,
        units={"gap": "NRMSE %", "noise_floor": "NRMSE %", "shrink": "% of the excess over noise closed"},
    )
    return Diagnosis(result, pb, nom, state, steps)


GAP_WEIGHTING = ("torque sets: residual energy over torque-signal energy pooled over the joints, "
                 "sqrt(sum_j mse_j / sum_j std(tau_j)^2): each joint's NRMSE^2 weighs by its share of the signal "
                 "energy; channels left out of the gap excluded")


def _jsonable(x):
    """``x`` with numpy values as plain Python (the data layer's conditioning records)."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return x


SCREEN_THREADS = 3  # simulated screenings run side by side in the first round (3 tip springs on 2 cores: 60 s one
# at a time, 47 s two at once; later, with smaller programs, 52 s two at once, 46 s three: one traces while others compile)

# [%] of the nominal excess a simulation-screened candidate (a tip-side spring) must close alone, in
# the first round, to be screened again on the later rounds' models (independent case 38: the
# springs at joints 1 and 2 closed 1 % and 0 %; their second screening cost 47 s of 198 s)
RESCREEN_SHRINK = 5.0


def _cad_spread(pb: Problem, nom: State) -> dict:
    """Per modal validation table, the gap spread of the CAD inertias' tolerance
    (:func:`._frequency_inertia.cad_spread`), when nothing identified the inertias: no torque data,
    and a refit on the frequency training data did not pay for its parameters; per output-error
    validation set (tool positions) when no torque or frequency data are given
    (:func:`._response.cad_spread`). Else empty."""
    if not pb.ttrain and not pb.ftrain and pb.rval:
        return cad_spread_response(pb.robot, nom.tfit, pb.sim_springs(nom), pb._rotor(), pb.rval,
                                   inertia_prior(pb.robot, float(pb.options["inertia_prior"])))
    li = pb.lin_inertia
    if pb.ttrain or li is None or li["used"] or li["gain"] > 0 or nom.lm is None:
        return {}
    return cad_spread(nom.lm, nom.x, pb.fval, li["prior"])


def _choose_base(pb: Problem, case, nom, ev0, floor, floor_source, floor_details, first_round):
    """The nominal model the candidates build on, when the frequency data offered a refit of the CAD
    inertias (:meth:`Problem._refit_linear_inertia`): the refit and a candidate effect on CAD both
    change the model, so they are judged alike, on held-out data. Refitted, the nominal model within
    noise is the diagnosis (nothing left to explain). Else the candidates are refitted on CAD first:
    when one of them predicts the held-out data better than the refit does, the gap is that effect
    (the refit had bent the inertias around it) and CAD stays; else the refit is the nominal model
    and the candidates are refitted on it. Returns ``(nominal, ev0, floor, floor_source, fitted)``;
    ``fitted`` is None when the candidates are still to be refitted, ``{}`` when none are."""
    li = pb.lin_inertia
    alt = pb.refit_nominal
    ev_alt = pb.evaluate(alt)
    src_alt, det_alt = {}, {}
    floor_alt = noise_floor(pb, ev_alt, case, src_alt, det_alt)

    def freq_gap(ev):
        v = [e["nrmse"] ** 2 for e in ev.values() if e["kind"] in ("frf", "modal")]
        return float(np.sqrt(np.mean(v))) if v else np.inf

    pb.count_noise(det_alt)
    if not is_significant(ev_alt, floor_alt, _upper(det_alt), _factors(det_alt, ev_alt)[0]):
        li.update(used=True, reason="the refitted nominal model is within noise on the held-out data")
        return alt, ev_alt, floor_alt, src_alt, det_alt, {}
    fitted = first_round(nom)
    best = min(fitted, key=lambda c: freq_gap(fitted[c][1]), default=None)
    if best is not None and freq_gap(fitted[best][1]) < freq_gap(ev_alt):
        li.update(used=False, reason=(f"CAD kept: {best.label(pb.names)} on CAD predicts the held-out data better "
                                      f"({freq_gap(fitted[best][1]):.2f} %) than the inertial refit ({freq_gap(ev_alt):.2f} %)"))
        return nom, ev0, floor, floor_source, floor_details, fitted
    li.update(used=True, reason=(f"no candidate on CAD predicts the held-out data better than the inertial refit "
                                 f"({freq_gap(ev_alt):.2f} %)"))
    return alt, ev_alt, floor_alt, src_alt, det_alt, None


CAD_WIDE_REACH = 4.0  # x the prior's scale: the box a nominal refit held at its tolerance is tried with (2 x the usual)


def _cad_beyond_tolerance(pb: Problem, nom: State, floor, upper, factor, cfloor, cfactor) -> dict | None:
    """When the torque nominal refit stopped at its CAD tolerance (some inertial parameter at the
    box's edge) and nothing else was named: the refit again within CAD_WIDE_REACH x the prior's
    scale. If that nominal model alone leaves the held-out gap within noise (pooled and per joint),
    ``{gap, links: [{link, parameters}]}`` (the parameters past the usual box, with their change
    from CAD); else None. Tried last, after the candidates: a payload the tolerance held back is a
    candidate's to name, not the CAD's."""
    prior = pb.inertia
    if prior is None or nom.tfit is None or nom.tfit.delta is None or pb.ftrain or pb.fval or pb.rval:
        return None
    if not np.any(np.abs(np.abs(nom.tfit.delta) - prior.reach * prior.scale) <= 1e-6 * prior.scale):
        return None
    # (nominal_state updates the copy's noise level, or drops it when the refit does not pay:
    # the problem's own prior is put back untouched)
    saved = (pb.inertia, pb.inertia_gain)
    pb.inertia = dataclasses.replace(prior, reach=CAD_WIDE_REACH)
    try:
        st = pb.nominal_state()
        ev = pb.evaluate(st) if pb.inertia is not None else None
    finally:
        pb.inertia, pb.inertia_gain = saved
    if ev is None or is_significant(ev, floor, upper, factor) or joints_beyond_floor(ev, cfloor, cfactor):
        return None
    from ._inertia import PARAM_NAMES, PARAM_UNITS

    d = np.asarray(st.tfit.delta, float).reshape(-1, 10)
    far = prior.beyond(st.tfit.delta).reshape(-1, 10)
    links = []
    for i in np.flatnonzero(far.any(axis=1)):
        p0 = prior.pi0.reshape(-1, 10)[i]
        links.append(dict(link=pb.robot.link_names[i], parameters=[
            f"{PARAM_NAMES[k]} {d[i, k]:+.4g} {PARAM_UNITS[k]}" + (f" ({100 * d[i, k] / p0[k]:+.0f} %)" if k == 0 and p0[k] else "")
            for k in np.flatnonzero(far[i])]))
    return dict(gap=gap_summary(ev, floor)[0], links=links) if links else None


def _inertia_report(pb: Problem, nom: State):
    """How far the nominal identification moved each link from CAD, and on which data."""
    if pb.inertia is not None:
        return (link_moves(pb.robot, pb.inertia.pi0, nom.tfit.delta, pb.inertia),
                f"refitted on the torque data (training information gain {pb.inertia_gain:.0f} over the base parameters' cost)")
    if pb.inertia_gain is not None:
        return [], f"CAD kept: a refit does not pay for its base parameters on the training data (gain {pb.inertia_gain:.0f})"
    if pb.lin_inertia is not None:
        li = pb.lin_inertia
        ho = li["held_out"]
        ho_txt = f"; held-out frequency-side gap {ho[0]:.2f} -> {ho[1]:.2f} %" if ho else ""
        if li["used"]:
            return (link_moves(pb.robot, li["prior"].pi0, li["delta"], li["prior"]),
                    f"refitted on the FRF/modal training data with the nominal springs (training information gain "
                    f"{li['gain']:.0f} over its parameters' cost{ho_txt}): {li['reason']}")
        if li["gain"] <= 0:
            return [], f"CAD kept: a refit on the FRF/modal data does not pay for its parameters (gain {li['gain']:.0f})"
        if li["offered"]:
            return [], li["reason"] + ho_txt
        return [], ("CAD kept: refitted on the FRF/modal training data, the inertias did not close half of the held-out "
                    f"gap{ho_txt} (a CAD error would; bending them around an effect the model lacks does not)")
    return [], "not refitted (no training data that identify it, or the case holds it: options.refit_inertia)"


UNMATCHED = 0.1  # a measured mode more than 10 % from every model mode is one the model lacks


def supplies_missing_mode(ev0: dict, ev: dict) -> bool:
    """Whether a model evaluated as ``ev`` matches (within UNMATCHED) a measured mode of some modal
    validation set that the nominal model ``ev0`` left unmatched: structural evidence of a missing
    degree of freedom, beyond what the gap's shrink measures."""
    for k, r0 in ev0.items():
        if r0["kind"] == "modal" and k in ev:
            e0, e1 = np.abs(np.asarray(r0["ef"])), np.abs(np.asarray(ev[k]["ef"]))
            if np.any((e0 > UNMATCHED) & (e1 <= UNMATCHED)):
                return True
    return False


def _failed_solves(model: str, ev: dict) -> list:
    """``failed_solves`` entries of one evaluated model: per output-error set whose simulation
    failed or diverged, the samples left non-finite or beyond 1000 % (counted at that cap)."""
    return [dict(model=model, dataset=k, samples=int(v["failed"]), of=int(v["samples"]))
            for k, v in ev.items() if v.get("failed")]
