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
import functools
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .case._case import Case, load_case
from ._cad import inertia_report
from .response import _response as R
from .judge._noise import NoiseFloor, noise_floor
from ._problem import CONFOUNDED, Candidate, Problem, State, parameters
from ._result import CandidateResult, Diagnosis, ReportSeries, ResponseTrace, TorqueTrace
from .judge._selection import (FAMILY_ALPHA, SIGNIFICANCE, gap_uncertainty, significance_factor, MIN_GAP, MIN_NAMED_SHRINK, MIN_STEP_SHRINK, NESTED, SWAP_SHRINK, forward_select, gap_summary,
                         ic_delta, decisive, swap_rivals, is_significant, joints_beyond_floor, pooled_upper, rank_entries, step_record,
                         worse_channels)
from .frequency._kinds import frequency_kinds
from .judge._signatures import indistinguishable_from_inertia, n_params, signature_name, signatures
from .torque._scale import scale_reason, torque_scale_suspects
from .judge._where import where
from ._verdict import final_verdict
from ..effects._registry import JOINT_FLEXIBILITY


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
    run = _prepare(case, candidates, prune, progress)
    if max_effects is None:
        max_effects = int(run.pb.options["max_effects"])
    _nominal_fit(run)
    _screen(run)
    fitted = _base_model(run)
    margins = _margins(run.floor, run.ev0)
    ranking, significant, joint_only = _rank(run, fitted, margins)
    sel, swaps = _select(run, fitted, margins, significant, joint_only, max_effects)
    return _assemble(run, margins, ranking, sel, swaps, significant, joint_only, t0)


@dataclasses.dataclass
class _Run:
    """A diagnosis under way: the problem, the nominal model with its evaluation and noise floor,
    the candidates and those refitted (``keep``: in the first round; ``keep_all``: the pool of the
    later rounds), the failed simulations met so far, the springs identified through the simulation
    and each candidate's shrink alone."""

    case: Case
    pb: Problem
    say: object
    prune: int
    nom: State = None
    ev0: dict = None
    floor: NoiseFloor = None
    cands: list = ()
    sig: dict = dataclasses.field(default_factory=dict)
    held: dict = dataclasses.field(default_factory=dict)
    keep: list = ()
    keep_all: list = ()
    off_scale: object = None
    failed: list = dataclasses.field(default_factory=list)
    simulated: dict = dataclasses.field(default_factory=dict)
    alone: dict = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class _Margins:
    """The floors the nominal gap is judged against: per channel (``cfloor``), the upper ends of
    the floors' intervals, the margins of "beyond the floor" per set and channel at one
    family-wise level over ``tests`` tests, and each channel's gap uncertainty (``crel``)."""

    cfloor: dict
    upper: dict
    factor: dict
    cfactor: dict
    tests: int
    crel: dict


def _prepare(case, candidates, prune: int, progress) -> _Run:
    """The case loaded (a path is read) and its data prepared once (:class:`Problem`)."""
    say = progress or (lambda s: None)
    if not isinstance(case, Case):
        case = load_case(case)
    return _Run(case, Problem(case, candidates), say, prune)


def _nominal_fit(run: _Run) -> None:
    """The nominal model fitted on the training data, evaluated on the validation data, and the
    noise floor of each validation set (whose effective samples the held-out criterion counts)."""
    pb = run.pb
    run.say(f"nominal fit ({len(pb.ttrain)} torque, {len(pb.ftrain)} frf/modal training sets)")
    run.nom = pb.nominal_state()
    run.ev0 = pb.evaluate(run.nom)
    run.floor = noise_floor(pb, run.ev0, run.case)
    pb.count_noise(run.floor.details, run.ev0)


def _screen(run: _Run) -> None:
    """The candidates, their residual signatures on the nominal model, those the inertial refit
    holds, and the ones refitted in the first round (the ``prune`` best torque candidates by
    signature, every frequency-side one): none when the whole torque looks off in scale."""
    pb = run.pb
    run.cands = cands = pb.candidates()
    run.sig = sig = signatures(pb, run.nom, cands)
    run.held = indistinguishable_from_inertia(pb, cands)
    tc = sorted([c for c in cands if c in sig], key=lambda c: -sig[c])
    run.keep = tc[:run.prune] + [c for c in cands if c not in sig]
    run.keep_all = list(run.keep)  # a candidate that changes nothing yet (pb.changes) may in a later round
    run.off_scale = torque_scale_suspects(pb, run.nom)
    if run.off_scale:
        # a gain on the whole torque is no effect of the library: whatever absorbed most of it would be named
        run.say(scale_reason(run.off_scale))
        run.keep = run.keep_all = []
    run.failed = _failed_solves("nominal", run.ev0)


def _first_round(run: _Run, base: State) -> dict:
    """``{candidate: (state, evaluation)}``: each first-round candidate that changes ``base``
    added to it, refitted and evaluated."""
    pb = run.pb
    one = functools.partial(_add_one, pb, base)
    todo = [c for c in run.keep if pb.changes(base, c)]
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
        run.failed.extend(_failed_solves(c.label(pb.names), ev))
        out[c] = (st, ev)
    return out


def _add_one(pb: Problem, base: State, c: Candidate):
    st = pb.add(base, c)
    return st, pb.evaluate(st)


def _base_model(run: _Run) -> dict:
    """The nominal model the candidates build on (:func:`_choose_base`, when the frequency data
    offered an inertial refit) and the first round's refits on it."""
    pb = run.pb
    fitted = None
    if pb.refit_nominal is not None:
        run.nom, run.ev0, run.floor, fitted = _choose_base(pb, run.case, run.nom, run.ev0, run.floor,
                                                           functools.partial(_first_round, run))
        if fitted is not None and not fitted:
            run.keep = []
    fl = run.floor.per_dataset
    run.say(f"gap {gap_summary(run.ev0, fl)[0]:.2f} % (noise floor {gap_summary(run.ev0, fl)[1]:.2f} %), "
            f"{len(run.cands)} candidates, {sum(pb.changes(run.nom, c) for c in run.keep)} refitted")
    if fitted is None:
        fitted = _first_round(run, run.nom)
    run.keep = [c for c in run.keep if c in fitted]
    return fitted


def _margins(floor: NoiseFloor, ev0: dict) -> _Margins:
    """The floors and margins the gaps are judged against (:class:`_Margins`)."""
    # (the floor is never bounded by a candidate's held-out gap: that would count the model error
    # the candidate does not hold as noise)
    det = floor.details
    factor, cfactor, tests = _factors(det, ev0)
    crel = {k: {c: gap_uncertainty(d) for c, d in (v.get("channel_dof") or {}).items()} for k, v in det.items()}
    return _Margins(floor.channel_floors(), floor.upper(), factor, cfactor, tests, crel)


def _rank(run: _Run, fitted: dict, mg: _Margins) -> tuple[list, bool, bool]:
    """Each first-round candidate alone on the nominal model, ranked (:func:`rank_entries`;
    ``run.keep`` follows that order), whether the nominal gap is significant, and whether only
    some joint's gap is (a gap confined to a joint beyond its own floor)."""
    pb, ev0, floor = run.pb, run.ev0, run.floor.per_dataset
    ranking = []
    for c in run.keep:
        st, ev = fitted[c]
        score = -ic_delta(ev, ev0, n_params(c, pb.user, bool(pb.ttrain), pb))
        ranking.append(_entry(pb, c, ev, ev0, floor, score, run.sig.get(c), mg.cfloor, st, mg.crel))
        run.say(f"  {c.label(pb.names)}: gap {ranking[-1].gap_after:.2f} %, shrink {ranking[-1].shrink:.0f} %")
    plain = [e.as_dict() for e in ranking]
    significant = is_significant(ev0, floor, mg.upper, mg.factor) or decisive(plain)
    # a gap confined to a light joint (a wrist's: 1e-6 of the torque energy) never shows pooled:
    # the joint beyond its own floor is a gap of its own, which only an effect resolving that joint
    # on its own evidence may explain
    joint_only = not significant and bool(joints_beyond_floor(ev0, mg.cfloor, mg.cfactor))
    order = rank_entries(plain)
    ranking = [ranking[i] for i in order]
    run.keep = [run.keep[i] for i in order]
    run.alone = {c: e.shrink for c, e in zip(run.keep, ranking)}
    return ranking, significant, joint_only


def _pool(run: _Run, state: State, k: int) -> list:
    """The candidates of round ``k`` of the forward selection: after the first step the residual
    changed, so the signatures are ranked again and effects masked by the first (larger) one get
    their turn."""
    pb, keep, prune = run.pb, run.keep, run.prune
    if k == 0:
        return keep
    # a candidate found by simulated screening costs a new compiled simulation on each new
    # base model (~20 s on 2 cores): tried again only when alone it closed RESCREEN_SHRINK % of the gap
    keep_k = [c for c in run.keep_all if pb.changes(state, c)
              and not (pb.screened_by_simulation(state, c) and run.alone.get(c, 100.0) < RESCREEN_SHRINK)]
    sig_k = signatures(pb, state, run.cands)
    tc_k = sorted([c for c in run.cands if c in sig_k], key=lambda c: -sig_k[c])
    # frequency-side candidates have no signature: the later rounds refit the ``prune`` that did
    # best alone (all of them each round cost a 6-joint FRF case 230 s)
    return tc_k[:prune] + [c for c in dict.fromkeys(keep + keep_k) if c not in sig_k and c in keep_k][:prune]


def _refit(run: _Run, state: State, c: Candidate):
    """``c`` added to ``state``, refitted and evaluated; a failed simulation is recorded."""
    pb = run.pb
    st = pb.add(state, c)
    ev = pb.evaluate(st)
    run.failed.extend(_failed_solves(" + ".join(a.label(pb.names) for a in st.added), ev))
    return st, ev


def _refine(run: _Run, step):
    """A selected spring screened by simulation identified (output error through
    :mod:`jflex.simulate`) before the next round builds on it: one costly fit per selected spring."""
    pb, floor = run.pb, run.floor.per_dataset
    j = step.cand.joint
    # (play inside a spring is identified before it is judged: Problem.add)
    if step.cand.effect != JOINT_FLEXIBILITY or j not in dict(step.state.springs):
        return step.state, step.ev
    run.say(f"identifying the spring at {pb.names[j]} through the simulation")
    st = pb.polish(step.state, [j])
    ev = pb.evaluate(st)
    run.simulated[pb.names[j]] = dict(gap_screened=gap_summary(step.ev, floor)[0], gap_identified=gap_summary(ev, floor)[0])
    return st, ev


def _on_select(run: _Run, step) -> None:
    run.say(f"selected {step.cand.label(run.pb.names)}: gap {gap_summary(step.ev, run.floor.per_dataset)[0]:.2f} %")


def _n_params(pb: Problem, c: Candidate) -> int:
    return n_params(c, pb.user, bool(pb.ttrain), pb)


def _simpler(rich: Candidate, simple: Candidate) -> bool:
    return NESTED.get(rich.effect) == simple.effect and rich.joint == simple.joint


def _min_first_shrink(ev0: dict, st) -> float:
    # an honest 'unexplained': a first effect closing less than MIN_NAMED_SHRINK % of the excess is
    # not named (the least bad candidate is not a diagnosis), unless it supplies a measured mode
    # the model lacked (a missing degree of freedom)
    return MIN_STEP_SHRINK if supplies_missing_mode(ev0, st.ev) else MIN_NAMED_SHRINK


def _select(run: _Run, fitted: dict, mg: _Margins, significant: bool, joint_only: bool, max_effects: int):
    """Forward selection on held-out data (:func:`forward_select`), then each selected effect
    tried against its rivals (:func:`_swap`). Returns the selection and the swaps made."""
    pb, ev0 = run.pb, run.ev0
    implausible = functools.partial(_implausible, pb)
    sel = forward_select(run.nom, ev0, run.floor.per_dataset, functools.partial(_pool, run),
                         functools.partial(_refit, run), refine=functools.partial(_refine, run),
                         n_params=functools.partial(_n_params, pb), max_effects=max_effects if run.keep else 0,
                         simpler=_simpler, first=fitted, on_select=functools.partial(_on_select, run),
                         significant=significant or joint_only, joint_only=joint_only,
                         channel_floor=mg.cfloor, upper=mg.upper, implausible=implausible,
                         factor=mg.factor, channel_factor=mg.cfactor, channel_rel=mg.crel,
                         min_first_shrink=functools.partial(_min_first_shrink, ev0))
    return _swap(run, sel, mg)


def _richer(k: Candidate, c: Candidate) -> bool:
    return NESTED.get(k.effect) == c.effect and k.joint == c.joint


def _rivals(run: _Run, c: Candidate) -> list:
    """The rivals of a selected ``c``: the richer law containing it, tried beside the others
    (alone, the parsimony rule judged the pair; a simpler one never replaces the richer), and at
    most two other effects at its place that alone closed nearly as much."""
    pb, keep, alone = run.pb, run.keep, run.alone
    nested = [k for k in keep if _richer(k, c)]
    return nested + [k for k in keep if k != c and k.joint == c.joint and k.effect != c.effect
                     and NESTED.get(k.effect) != c.effect and NESTED.get(c.effect) != k.effect
                     and k.effect != JOINT_FLEXIBILITY and not pb.screened_by_simulation(run.nom, k)
                     and abs(alone.get(k, -1e9) - alone.get(c, 1e9)) < SWAP_SHRINK][:2]


def _swap(run: _Run, sel, mg: _Margins):
    """A rival that alone closed nearly as much as a selected effect may hold the data's shape
    beside the other effects (:func:`swap_rivals`; not with a spring or a simulation-screened
    effect selected: the model is rebuilt with plain refits, and a spring identified through the
    simulation is not). Returns the selection and the swaps made."""
    pb = run.pb
    swaps = []
    if sel.steps and not any(st.cand.effect == JOINT_FLEXIBILITY or pb.screened_by_simulation(run.nom, st.cand)
                             for st in sel.steps):
        sel, swaps = swap_rivals(sel, run.ev0, run.floor.per_dataset, functools.partial(_rivals, run),
                                 functools.partial(_refit, run), n_params=functools.partial(_n_params, pb),
                                 channel_floor=mg.cfloor, implausible=functools.partial(_implausible, pb),
                                 richer=_richer, channel_rel=mg.crel)
        for old_c, new_c, e0, e1 in swaps:
            run.say(f"{new_c.label(pb.names)} takes the place of {old_c.label(pb.names)}: excess {e0:.2f} -> {e1:.2f} %")
    return sel, swaps


def _ambiguous(ranking: list, significant: bool) -> list:
    """A known confounded pair whose held-out scores are too close to call."""
    ambiguous = []
    if len(ranking) >= 2 and significant:
        a, b = ranking[0], ranking[1]
        pair = frozenset((a.effect, b.effect))
        if a.effect != b.effect and abs(a.shrink - b.shrink) < 5.0:
            ambiguous.append(dict(effects=[a.effect, b.effect], joints=[a.joint, b.joint],
                                  known_pair=pair in CONFOUNDED, shrink=[a.shrink, b.shrink]))
    return ambiguous


def _assemble(run: _Run, mg: _Margins, ranking: list, sel, swaps, significant: bool, joint_only: bool,
              t0: float) -> Diagnosis:
    """The selected effects' records, the gap after them, the verdict (:func:`_judge`), where the
    gap lies, and the :class:`Diagnosis` with the arrays its report draws."""
    pb, nom, ev0, floor = run.pb, run.nom, run.ev0, run.floor.per_dataset
    selected = [dataclasses.replace(_entry(pb, st.cand, st.ev, ev0, floor, st.score, None, mg.cfloor, st.state, mg.crel),
                                    step_shrink=st.step_shrink) for st in sel.steps]
    steps = [step_record(None, ev0, floor)] + [step_record(st.cand.label(pb.names), st.ev, floor) for st in sel.steps]
    state, ev_cur = sel.state, sel.ev
    ambiguous = _ambiguous(ranking, significant)
    gap0, fl, exc0 = gap_summary(ev0, floor)
    gap_after, _, exc_after = gap_summary(ev_cur, floor)
    shrink_total = float(np.clip(100 * (1 - exc_after / exc0), 0, 100)) if exc0 > 0 else 0.0
    floor_high = pooled_upper(floor, mg.upper)
    remaining = (is_significant(ev_cur, floor, mg.upper, mg.factor)
                 or (joint_only and bool(joints_beyond_floor(ev_cur, mg.cfloor, mg.cfactor))))
    significant = significant or joint_only
    v = final_verdict(pb, nom, ev0, run.floor, run.off_scale, sel, significant, shrink_total, gap_after, floor_high,
                      remaining, upper=mg.upper, factor=mg.factor, cfloor=mg.cfloor, cfactor=mg.cfactor)
    wh = where(pb, ev0, floor, run.case, channel_floor=mg.cfloor)
    moves, inertia_note = inertia_report(pb, nom)
    return Diagnosis(
        case=str(run.case.path), verdict=v.verdict, stop_reason=v.reason, cad_spread=v.spread,
        torque_scale_suspects=run.off_scale, gap_before=gap0, gap_after=gap_after, noise_floor=fl,
        noise_floor_upper=floor_high, floor=run.floor, excess_before=exc0, excess_after=exc_after,
        channel_gaps=dict(before={k: dict(e["channels"]) for k, e in ev0.items()},
                          after={k: dict(e["channels"]) for k, e in ev_cur.items()},
                          weights={k: dict(e["weights"]) for k, e in ev0.items() if "weights" in e}),
        excluded_channels={k: dict(e) for k, e in pb.excluded.items()}, conditioning=_jsonable(pb.conditioning),
        vetoed=[dict(round=r_, candidate=c_.label(pb.names), reason=w_) for r_, c_, w_ in sel.vetoed],
        shrink=shrink_total, inertia_refit=moves, inertia=inertia_note, cad_beyond_tolerance=v.cad_far,
        # candidates whose torques are a change of the refitted inertias on these motions: the refit's
        # tolerance, not the data, splits them from a CAD error
        confounded_with_inertia_refit=[dict(effect=c.effect, joint=None if c.joint is None else pb.names[c.joint],
                                            relative_residual=float(x)) for c, x in run.held.items()],
        processing={s_.name: s_.processing for s_ in pb.ttrain + pb.tval if s_.processing},
        significant=bool(significant), remaining_significant=bool(remaining),
        joints_beyond_floor=[dict(dataset=k, channel=c) for k, c in joints_beyond_floor(ev0, mg.cfloor, mg.cfactor)],
        test=_test_record(mg), where=wh[:40], ranking=tuple(ranking), selected=tuple(selected), ambiguous=ambiguous,
        steps=steps, swapped=[dict(replaced=a.label(pb.names), by=b.label(pb.names), excess_before=e0, excess_after=e1)
                              for a, b, e0, e1 in swaps],
        parameters=parameters(pb, state), nominal_parameters=parameters(pb, nom),
        unmatched_modes=[w for w in wh if w.get("unmatched")],
        responses_output_error=[s.name for s in pb.rval],
        responses_fitted=[s.name for s in pb.rtrain], simulated_refit=run.simulated,
        responses_not_modelled=[d.name for d in pb.responses],
        failed_solves=run.failed,
        seconds=time.perf_counter() - t0,
        loaded=run.case, problem=pb, nominal=nom, final=state, series=_report_series(pb, nom, ev0, state, ev_cur))


def _test_record(mg: _Margins) -> dict:
    """How "beyond the floor" was tested: the family-wise level, the number of tests, the margins."""
    return dict(family_alpha=FAMILY_ALPHA, tests=mg.tests, min_gap=MIN_GAP, factor=mg.factor, channel_factor=mg.cfactor,
                rule="a gap lies beyond its floor when it exceeds factor x the floor + min_gap [%]: factor is the "
                     "square root of the F(dof, dof) quantile at 1 - family_alpha / tests (dof: the noise's effective "
                     f"samples), at least {SIGNIFICANCE:g}; one family-wise level over every set and joint tested")


def _report_series(pb: Problem, nom: State, ev0: dict, final: State, evf: dict) -> ReportSeries:
    """What the report draws beyond diagnosis.json (:class:`ReportSeries`): the nominal and final
    models' evaluations, the validation sets, and each output-error set simulated by both models
    (a failed simulation is recorded, never raised: a figure must never lose the diagnosis)."""
    torque = tuple(TorqueTrace(s.name, s.t, s.tau, s.scale, getattr(s, "cutoff", None)) for s in pb.tval)
    series = ReportSeries(tuple(pb.names), ev0, evf, torque, tuple(pb.fval))
    if not pb.rval:
        return series
    try:
        models = [pb.simulation_model(nom), pb.simulation_model(final)]
        responses = tuple(ResponseTrace(s.name, s.t, s.y, tuple(s.channels), *(R.predict(m, s) for m in models))
                          for s in pb.rval)
    except Exception as exc:  # noqa: BLE001
        return dataclasses.replace(series, error=f"{type(exc).__name__}: {exc}")
    return dataclasses.replace(series, responses=responses)


def _entry(problem, c: Candidate, ev, ev0, floor, score, sig=None, channel_floor=None, state=None,
           channel_rel=None) -> CandidateResult:
    """Candidate ``c`` evaluated as ``ev`` against the nominal evaluation ``ev0``."""
    gap, fl, exc = gap_summary(ev, floor)
    _, _, exc0 = gap_summary(ev0, floor)
    shrink = 100.0 * (1 - exc / exc0) if exc0 > 0 else 0.0
    g0 = gap_summary(ev0, floor)[0]
    on_link = getattr(frequency_kinds().get(c.effect), "on_link", False)
    return CandidateResult(
        effect=c.effect, joint=None if c.joint is None or on_link else problem.names[c.joint],
        link=problem.robot.link_names[c.joint] if on_link else None,
        score=float(score), gap_after=gap, shrink=float(np.clip(shrink, 0, 100)),
        shrink_raw=float(100 * (1 - gap / g0)) if g0 > 0 else 0.0,
        per_dataset={k: v["nrmse"] for k, v in ev.items()},
        per_channel={k: dict(v["channels"]) for k, v in ev.items()},
        worse_channels=worse_channels(ev, ev0, channel_floor, channel_rel),
        implausible=_implausible(problem, c, state) or None,
        signature=None if sig is None else {"name": _torque_signature(signature_name(c.effect)), "value": float(sig)})


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


def _factors(details, ev) -> tuple[dict, dict, int]:
    """The margins of "beyond the floor" (:func:`._selection.significance_factor`) per set and per
    torque channel, at one family-wise level over all the tests a diagnosis makes on the nominal
    gap (every validation set pooled, and every torque channel), and that number of tests."""
    tests = len(ev) + sum(len(v.get("channel_dof") or {}) for v in details.values())
    factor = {k: significance_factor(v["dof"], tests) for k, v in details.items() if v.get("dof") is not None}
    cfactor = {k: {c: significance_factor(d, tests) for c, d in (v.get("channel_dof") or {}).items()}
               for k, v in details.items()}
    return factor, cfactor, tests


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
# the first round, to be screened again on the later rounds' models (on a 3-joint arm the
# springs at joints 1 and 2 closed 1 % and 0 %; their second screening cost 47 s of 198 s)
RESCREEN_SHRINK = 5.0


def _choose_base(pb: Problem, case, nom, ev0, floor: NoiseFloor, first_round):
    """The nominal model the candidates build on, when the frequency data offered a refit of the CAD
    inertias (:meth:`Problem._refit_linear_inertia`): the refit and a candidate effect on CAD both
    change the model, so they are judged alike, on held-out data. Refitted, the nominal model within
    noise is the diagnosis (nothing left to explain). Else the candidates are refitted on CAD first:
    when one of them predicts the held-out data better than the refit does, the gap is that effect
    (the refit had bent the inertias around it) and CAD stays; else the refit is the nominal model
    and the candidates are refitted on it. Returns ``(nominal, ev0, floor, fitted)``; ``fitted`` is
    None when the candidates are still to be refitted, ``{}`` when none are."""
    li = pb.lin_inertia
    alt = pb.refit_nominal
    ev_alt = pb.evaluate(alt)
    floor_alt = noise_floor(pb, ev_alt, case)
    pb.count_noise(floor_alt.details)
    if not is_significant(ev_alt, floor_alt.per_dataset, floor_alt.upper(), _factors(floor_alt.details, ev_alt)[0]):
        li.update(used=True, reason="the refitted nominal model is within noise on the held-out data")
        return alt, ev_alt, floor_alt, {}
    fitted = first_round(nom)
    best = min(fitted, key=lambda c: _frequency_gap(fitted[c][1]), default=None)
    if best is not None and _frequency_gap(fitted[best][1]) < _frequency_gap(ev_alt):
        li.update(used=False, reason=(f"CAD kept: {best.label(pb.names)} on CAD predicts the held-out data better "
                                      f"({_frequency_gap(fitted[best][1]):.2f} %) than the inertial refit "
                                      f"({_frequency_gap(ev_alt):.2f} %)"))
        return nom, ev0, floor, fitted
    li.update(used=True, reason=(f"no candidate on CAD predicts the held-out data better than the inertial refit "
                                 f"({_frequency_gap(ev_alt):.2f} %)"))
    return alt, ev_alt, floor_alt, None


def _frequency_gap(ev) -> float:
    """The pooled gap [%] of the FRF and modal validation sets of an evaluation (inf without any)."""
    v = [e["nrmse"] ** 2 for e in ev.values() if e["kind"] in ("frf", "modal")]
    return float(np.sqrt(np.mean(v))) if v else np.inf


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
