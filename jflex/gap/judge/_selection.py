"""Selection on held-out data: the gap measures (gap, floor, excess), significance, the
information criterion, the ranking of candidates, forward selection, and the verdict. The
rules are public so that experiments with model families of their own select by the same rules
as :func:`jflex.gap.diagnose`."""

from __future__ import annotations

import dataclasses

import numpy as np

from ...effects._registry import NESTED  # complex -> the simpler effect it contains

SIGNIFICANCE = 1.2  # a gap is significant when nrmse > 1.2 x its noise floor (+ MIN_GAP)
MIN_GAP = 0.2  # [%] below this a gap is never significant
MIN_STEP_SHRINK = 10.0  # [%] of the current excess an added effect must close to be selected
MIN_NAMED_SHRINK = 50.0  # [%] of the nominal excess the first effect must close to be named at all
EXPLAINED_SHRINK = 80.0  # [%] of the nominal excess closed in all for the verdict 'explained'
# what remains beyond the noise may still be called 'explained' only when the pooled gap left is at
# most this many times the upper end of the pooled floor's interval: a share closed says nothing of
# the size left over (a real TIAGo log: 80 % closed left 504 % against a floor of 46 %, 36.5-62.2 %)
EXPLAINED_FLOOR_FACTOR = 2.0


# family-wise false-alarm rate of "beyond the floor": the per-joint and per-set tests of a
# diagnosis are corrected together (Bonferroni over all of them), so that a 7-joint arm with two
# validation sets is not 16 chances at a false alarm
FAMILY_ALPHA = 0.05
DOF_SHARE = 0.5  # of a measured effective-sample count the test relies on (see significance_factor)


def significance_factor(dof, tests: int = 1, alpha: float = FAMILY_ALPHA) -> float:
    """The factor on a noise floor that a gap must exceed, besides ``MIN_GAP``, to lie beyond it at
    family-wise false-alarm rate ``alpha`` over ``tests`` tests: the gap's and the floor's mean
    squares each estimate the noise variance from ``dof`` effective samples (the noise's own
    autocorrelation: coloured or quantised samples are not independent), so with no model error
    their ratio follows ``F(dof, dof)``; the factor is the square root of its ``1 - alpha / tests``
    quantile, and at least ``SIGNIFICANCE`` (a floor estimate is biased, not only scattered).
    ``dof`` is itself estimated from one record (:func:`._noise.effective_samples`), which scatters
    by ~30 % on strongly coloured noise; an overestimate loosens the test (at an AR(1) pole of
    0.97 with 7 joints: 12 % false alarms instead of 5 %), so the quantile is taken at DOF_SHARE of
    it (Monte Carlo over AR(1) poles 0.5-0.99: 0.3-4.9 %).
    Without a usable ``dof`` (< 1) nothing can be judged: ``inf``."""
    from scipy.stats import f as fdist

    dof = float(dof) if dof is not None else 0.0
    if not np.isfinite(dof) or dof < 1.0:
        return float("inf")
    d = max(DOF_SHARE * dof, 1.0)
    q = float(fdist.ppf(1.0 - alpha / max(int(tests), 1), d, d))
    return max(SIGNIFICANCE, float(np.sqrt(q)))


def gap_summary(ev, floor):
    names = list(ev)
    g = np.array([ev[k]["nrmse"] for k in names])
    f = np.array([floor[k] for k in names])
    gap = float(np.sqrt(np.mean(g**2)))
    fl = float(np.sqrt(np.mean(f**2)))
    exc = float(np.sqrt(np.mean(np.maximum(g**2 - f**2, 0.0))))
    return gap, fl, exc


def is_significant(ev, floor, upper=None, factor=None):
    """Whether some validation set's gap exceeds its noise floor beyond the margin: ``SIGNIFICANCE``
    x the floor (``factor[set]`` instead when given: :func:`significance_factor`, the margin its
    effective samples and the number of tests call for), or the upper end of the floor's own
    confidence interval (``upper``, ``{set: %}``, when the estimate is uncertain: few periods or
    effective samples) if that is larger, plus ``MIN_GAP``."""
    up, fa = upper or {}, factor or {}
    return any(ev[k]["nrmse"] > max(fa.get(k, SIGNIFICANCE) * floor[k], up.get(k) or 0.0) + MIN_GAP for k in ev)


WORSE_MIN = 0.1  # [%] a channel's change below this is never "worse", whatever its floor
WORSE_Z = 3.0  # standard errors of a joint's own gap by which a named effect may make it worse


def gap_uncertainty(dof) -> float:
    """Relative standard error of an NRMSE estimated from ``dof`` effective samples of its noise
    (``sd(g) / g = 1 / sqrt(2 dof)``), times WORSE_Z: the share of a joint's gap by which a model
    may change it before the change is beyond what the data can tell."""
    dof = float(dof) if dof is not None else 0.0
    return float(WORSE_Z / np.sqrt(2.0 * dof)) if np.isfinite(dof) and dof >= 1.0 else float("inf")


def worse_channels(ev_new, ev_old, channel_floor=None, channel_rel=None) -> list:
    """The torque channels (joints) that a model evaluated as ``ev_new`` predicts worse than the
    model before it (``ev_old``) by more than their own noise: ``after > before + allowed`` with
    ``allowed`` the channel's noise floor [%] (``channel_floor[set][channel]``, else the set's),
    or, when ``channel_rel[set][channel]`` is given (:func:`gap_uncertainty`), the uncertainty of
    the joint's own gap, ``before x channel_rel``, where that is smaller (a joint made 1.9 x worse
    by a fit is not saved by a floor as large as its gap); at least WORSE_MIN. An effect that helps
    the gap pooled over the joints but makes a joint worse beyond its noise stands in for
    something else there: it is not accepted.
    Returns ``[dict(dataset, channel, before, after, floor)]`` (``floor``: the change allowed)."""
    out = []
    cf, cr = channel_floor or {}, channel_rel or {}
    for k, ch, before, after in _channel_changes(ev_new, ev_old):
        fl = float(cf.get(k, {}).get(ch, 0.0))
        rel = cr.get(k, {}).get(ch)
        if rel is not None and np.isfinite(rel):
            fl = min(fl, before * rel) if fl > 0 else before * rel
        fl = max(fl, WORSE_MIN)
        if after > before + fl:
            out.append(dict(dataset=k, channel=ch, before=before, after=after, floor=fl))
    return out


def _channel_changes(ev_new, ev_old):
    """``(set, channel, before, after)`` [%] of every torque channel evaluated in both."""
    for k, r in ev_new.items():
        if r.get("kind") != "torque" or k not in ev_old:
            continue
        for ch, after in r["channels"].items():
            before = ev_old[k]["channels"].get(ch)
            if before is not None:
                yield k, ch, float(before), float(after)


def resolved_channels(ev_new, ev_old, channel_floor=None, channel_factor=None) -> list:
    """The torque channels (joints) that a model evaluated as ``ev_new`` brings from beyond their
    own noise (``before > SIGNIFICANCE x floor + MIN_GAP``) to within it (``after <= floor``), with
    ``floor`` the channel's floor [%] (``channel_floor[set][channel]``). A gap confined to one
    joint carries little of the pooled torque energy (a wrist joint of an industrial arm: 0.3 %),
    so the pooled shrink alone can leave it unnamed. ``channel_factor``: ``{set: {channel: x}}``,
    the margin of "beyond" per channel (:func:`significance_factor`; default ``SIGNIFICANCE``).
    Returns ``[dict(dataset, channel, before, after, floor)]``."""
    out = []
    cf, fa = channel_floor or {}, channel_factor or {}
    for k, ch, before, after in _channel_changes(ev_new, ev_old):
        fl = cf.get(k, {}).get(ch)
        if _beyond(before, fl, fa.get(k, {}).get(ch, SIGNIFICANCE)) and after <= fl:
            out.append(dict(dataset=k, channel=ch, before=before, after=after, floor=float(fl)))
    return out


# held-out information-criterion gain (BIC form, :func:`ic_delta`) at which the validation data
# themselves decide that a candidate's effect is there, whatever the floor estimate says: a gap
# just inside SIGNIFICANCE x floor + MIN_GAP that one effect closes to the floor with this much
# evidence is not noise (the independent Panda Stribeck case: 1.06 % against 0.75 %, score 466;
# the null cases of the independent bench reach 53 at most)
DECISIVE_SCORE = 200.0


def decisive(ranking) -> bool:
    """Whether a first-round candidate (ranking entries with ``score`` and ``shrink``) is decisive
    evidence of a gap: score >= DECISIVE_SCORE and it closes at least MIN_NAMED_SHRINK % of it
    (entries vetoed, ``worse_channels`` or ``implausible`` set, are no evidence)."""
    return any(e["score"] >= DECISIVE_SCORE and e["shrink"] >= MIN_NAMED_SHRINK and not vetoed(e) for e in ranking)


def vetoed(entry) -> str | None:
    """Why a ranking entry may not be named (None when it may): its fit is implausible (a value
    no machine has, ``entry["implausible"]``), or it makes a joint worse beyond that joint's noise
    (``entry["worse_channels"]``, :func:`worse_channels`)."""
    if entry.get("implausible"):
        return f"implausible fit: {entry['implausible']}"
    w = entry.get("worse_channels")
    if w:
        return "makes " + ", ".join(f"{x['channel']} worse ({x['before']:.2f} -> {x['after']:.2f} %, allowed "
                                    f"{x['floor']:.2f} %)" for x in w)
    return None


def channel_score(ev_new, ev_old, p_new) -> float:
    """Held-out information-criterion gain (BIC form, flipped as a ranking's ``score``) over the
    torque channels with each joint weighed alike: sum_c Neff_c ln(nrmse_old_c^2 / nrmse_new_c^2)
    - p ln(N), ``Neff_c`` the set's effective samples shared equally among its channels. The pooled
    gap weighs a joint by its share of the torque energy, so a gap confined to a light wrist joint
    (0.0006 % of a UR5's torque energy) is no evidence there however well an effect closes it;
    this criterion is the evidence of :func:`resolved_channels`."""
    d = 0.0
    ntot = 0.0
    for k, _, before, after in _channel_changes(ev_new, ev_old):
        ne = ev_new[k]["neff"] / max(len(ev_new[k]["channels"]), 1)
        ntot += ne
        d += ne * np.log(max(after, 1e-9) ** 2 / max(before, 1e-9) ** 2)
    return float(-(d + p_new * np.log(max(ntot, 2.0))))


def ic_delta(ev_new, ev_old, p_new):
    """Held-out information criterion change (BIC form): sum_d Neff_d ln(mse_new / mse_old) + p ln(N)."""
    d = 0.0
    ntot = 0.0
    for k in ev_new:
        ne = ev_new[k]["neff"]
        ntot += ne
        d += ne * np.log(max(ev_new[k]["nrmse"], 1e-9) ** 2 / max(ev_old[k]["nrmse"], 1e-9) ** 2)
    return d + p_new * np.log(max(ntot, 2.0))


PARSIMONY = 5.0  # [%] a nested simpler effect within this shrink of the richer one ranks first


def simpler_holds(shrink_simple, score_simple, shrink_rich, score_rich) -> bool:
    """Whether a simpler nested effect wins over the richer one at the same place: it closes
    nearly as much of the excess (within PARSIMONY points) and the richer one's held-out criterion
    is not better by DECISIVE_SCORE. The shrink is capped at the floor: with a floor above the
    noise (an upper bound) both close 100 % though the richer one's held-out gap may be half the
    simpler's; the criterion (each channel's effective sample count, so coloured noise does not
    count as evidence) still tells them apart."""
    return shrink_simple >= shrink_rich - PARSIMONY and score_rich - score_simple < DECISIVE_SCORE


def rank_entries(entries) -> list[int]:
    """Order by the held-out shrink, then the criterion; a simpler nested effect at the same place
    that closes nearly as much (:func:`simpler_holds`) goes first."""
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
                if eb["effect"] == simple and eb["joint"] == ea["joint"] and simpler_holds(eb["shrink"], eb["score"], ea["shrink"], ea["score"]):
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
    score: float  # held-out information-criterion gain (-ic_delta against the model before)
    step_shrink: float  # % of the excess before this step that it closed
    state_before: object = None  # the model it was added to


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
    together: tuple | None = None  # a failed probation: (the candidates taken after the first, % of the excess all closed)
    vetoed: list = dataclasses.field(default_factory=list)  # (round, candidate, why) never taken: see :func:`vetoed`


def forward_select(state0, ev0: dict, floor: dict, candidates, refit, *, n_params, max_effects: int,
                   simpler=None, first=None, on_select=None, min_first_shrink=0.0,
                   significant: bool | None = None, refine=None, channel_floor: dict | None = None,
                   upper: dict | None = None, implausible=None, joint_only: bool = False,
                   factor: dict | None = None, channel_factor: dict | None = None,
                   channel_rel: dict | None = None) -> Selection:
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
      same place wins when it closes within ``PARSIMONY`` points of it and the richer one is not
      decisively better on the held-out criterion (:func:`simpler_holds`).
    - ``first``: optional ``{cand: (state, ev)}`` of first-round refits already made.
    - ``on_select(step)``: optional callback after each selected step.
    - ``min_first_shrink``: the first effect must close at least this % of the excess to be taken
      (stop reason ``"weak"``): below it, nothing is named. A number, or ``callable(step) ->
      number`` (e.g. lower for an effect that supplies a measured mode the model lacked). A first
      effect below it whose held-out score is still :data:`DECISIVE_SCORE` is kept on probation:
      the search goes on with decisive steps only, and the effects are named if together they
      close that share (two real effects that each explain part of one gap), else none is.
    - ``significant``: whether the nominal gap is significant (default: :func:`is_significant`),
      e.g. also when a candidate is :func:`decisive` evidence.
    - ``refine(step) -> (state, ev)``: optional; the taken step's model refined (e.g. a costly
      identification done only for what was selected) before the next round builds on it.
    - ``channel_floor``: ``{set: {channel: floor %}}``; a candidate that makes some joint worse by
      more than that joint's floor, or than its own gap's uncertainty (``channel_rel``,
      :func:`gap_uncertainty`) where smaller (:func:`worse_channels`), is never taken.
    - ``upper``: ``{set: %}``, the upper ends of the floors' confidence intervals; ``factor``:
      ``{set: x}`` and ``channel_factor``: ``{set: {channel: x}}``, the margins of "beyond the
      floor" (:func:`is_significant`, :func:`joints_beyond_floor`, :func:`significance_factor`).
    - ``implausible(cand, state) -> str | None``: optional; a candidate whose fit it calls
      implausible is never taken.
    Candidates passed over for either reason are listed in ``Selection.vetoed``.
    - ``joint_only``: the pooled gap is within noise but some joint lies beyond its own floor
      (:func:`joints_beyond_floor`; pass ``significant`` true with it): from the first step on,
      only a candidate that resolves a joint on its own evidence (below) may be taken (stop
      reason ``"joint"`` when none does).

    Beside the pooled rules, a candidate is taken on the evidence of one joint: when it is decisive
    (held-out score >= ``DECISIVE_SCORE``, pooled or over the joints weighed alike,
    :func:`channel_score`), makes no joint worse, does not grow the pooled excess by
    ``MIN_STEP_SHRINK`` % or more, and brings some joint from beyond
    its own floor to within it (:func:`resolved_channels`), it is named even if it closes less than
    ``min_first_shrink`` / ``MIN_STEP_SHRINK`` of the pooled excess, or the pooled gap is already
    within noise (a coupled wrist drive seen on the wrist joints alone).
    """
    sig_ = lambda ev: is_significant(ev, floor, upper, factor)
    vetoes = []
    if not (sig_(ev0) if significant is None else significant):
        return _with(vetoes, Selection([], state0, ev0, "not significant"))
    _, _, exc0 = gap_summary(ev0, floor)
    S = _Search(state0, ev0, floor, exc0, vetoes, state=state0, ev=ev0)
    need_of = min_first_shrink if callable(min_first_shrink) else (lambda step: min_first_shrink)
    while True:
        if len(S.steps) >= max_effects:
            return S.end("max effects")
        _, _, exc_cur = gap_summary(S.ev, floor)
        pool = candidates(S.state, len(S.steps)) if callable(candidates) else candidates
        best, local = _round(S, pool, exc_cur, refit, first=first, n_params=n_params, simpler=simpler,
                             implausible=implausible, channel_floor=channel_floor, channel_rel=channel_rel,
                             channel_factor=channel_factor)
        if best is None:
            return S.end("no candidate")
        stop, step, on_joint = _pick(S, best, local, sig_, joint_only, need_of)
        if stop is not None:
            return stop
        if refine is not None:
            st_r, ev_r = refine(step)
            step = dataclasses.replace(step, state=st_r, ev=ev_r)
        S.steps.append(step)
        S.chosen.append(step.cand)
        S.state, S.ev = step.state, step.ev
        new = [step]
        if S.weak:
            _, _, exc = gap_summary(S.ev, floor)
            if 100 * (1 - exc / exc0) < S.weak[1]:
                if not sig_(S.ev):
                    return _with(vetoes, S.probation("within noise"))
                continue
            S.weak, new = None, S.steps
        for st_ in new if on_select is not None else ():
            on_select(st_)
        if not sig_(S.ev) and not joints_beyond_floor(S.ev, channel_floor, channel_factor):
            return _with(vetoes, Selection(S.steps, S.state, S.ev, "within noise"))


@dataclasses.dataclass
class _Search:
    """A forward selection under way (:func:`forward_select`): the nominal model, its excess
    ``exc0``, the vetoes so far, the steps taken, the current model and a decisive first effect on
    probation (``weak``: its step and the share of the excess it had to close)."""

    state0: object
    ev0: dict
    floor: dict
    exc0: float
    vetoes: list
    steps: list = dataclasses.field(default_factory=list)
    state: object = None
    ev: dict = None
    chosen: list = dataclasses.field(default_factory=list)
    weak: tuple | None = None

    def probation(self, stop: str) -> Selection:
        """The end of a search with a first effect on probation: the effects taken since it must
        close the share together, else none is named (two real effects each closing part of one gap
        are named; a lone partial match to an effect outside the library is not)."""
        _, _, exc = gap_summary(self.ev, self.floor)
        closed = 100 * (1 - exc / self.exc0)
        if closed >= self.weak[1]:
            return _with(self.vetoes, Selection(self.steps, self.state, self.ev, stop))
        return _with(self.vetoes, Selection([], self.state0, self.ev0, "weak", self.weak[0],
                                            (tuple(st_.cand for st_ in self.steps[1:]), float(closed))))

    def end(self, stop: str, rejected=None) -> Selection:
        """The search stopped for ``stop`` (on probation: :meth:`probation`)."""
        if self.weak:
            return _with(self.vetoes, self.probation(stop))
        return _with(self.vetoes, Selection(self.steps, self.state, self.ev, stop, rejected))


def _round(S: _Search, pool, exc_cur: float, refit, *, first, n_params, simpler, implausible, channel_floor,
           channel_rel, channel_factor):
    """One round of :func:`forward_select`: each candidate of ``pool`` not yet chosen refitted on the
    current model (the first round's from ``first``) and scored. Returns the best step (by the shrink
    rounded to a point, then the score; a simpler nested effect wins a near tie) and the best decisive
    step resolving some joint on its own evidence (or None); vetoes go to ``S.vetoes``."""
    best = None
    local = None  # the best decisive candidate that resolves some joint on its own (see forward_select)
    for c in pool:
        if c in S.chosen:
            continue
        st, ev = first[c] if (first is not None and not S.steps and c in first) else refit(S.state, c)
        why = implausible(c, st) if implausible is not None else None
        why = f"implausible fit: {why}" if why else vetoed(dict(worse_channels=worse_channels(ev, S.ev, channel_floor,
                                                                                            channel_rel)))
        if why:
            S.vetoes.append((len(S.steps), c, why))
            continue
        score = -ic_delta(ev, S.ev, n_params(c))
        _, _, exc = gap_summary(ev, S.floor)
        step_shrink = 100 * (1 - exc / exc_cur) if exc_cur > 0 else 0.0
        key = (round(step_shrink), score)
        if simpler is not None and best is not None:
            if simpler(best[1].cand, c) and simpler_holds(step_shrink, score, best[1].step_shrink, best[1].score):
                key = (best[0][0], best[0][1] + 1e-9, 1)  # the simpler nested effect wins a near tie
            elif simpler(c, best[1].cand) and simpler_holds(best[1].step_shrink, best[1].score, step_shrink, score):
                key = (-np.inf, -np.inf)
        if best is None or key > best[0]:
            best = (key, Step(c, st, ev, S.ev, float(score), float(step_shrink), S.state))
        # (one that makes the pooled gap worse by a step's share stands in for something else:
        # an offset at a Panda's joint 2 "resolved" joint 3 while the pooled excess grew 52 %)
        if resolved_channels(ev, S.ev, channel_floor, channel_factor) and step_shrink > -MIN_STEP_SHRINK:
            jscore = max(score, channel_score(ev, S.ev, n_params(c)))
            if jscore >= DECISIVE_SCORE and (local is None or jscore > local[0]):
                local = (jscore, Step(c, st, ev, S.ev, float(score), float(step_shrink), S.state))
    return (None if best is None else best[1]), (None if local is None else local[1])


def _pick(S: _Search, step: Step, local: Step | None, sig_, joint_only: bool, need_of):
    """Whether the round's best ``step`` (or ``local``, resolving a joint on its own) is taken: ``(selection,
    None, False)`` when the search stops, else ``(None, step, on_joint)``; ``S.weak`` set on probation."""
    steps = S.steps
    on_joint = False
    if (steps and not sig_(S.ev)) or (not steps and joint_only):
        # the pooled gap is within noise but a joint is not: only a candidate that resolves a
        # joint on its own evidence may still be taken
        if local is None:
            if not steps:
                return _with(S.vetoes, Selection(steps, S.state, S.ev, "joint", step)), None, False
            return S.end("within noise"), None, False
        step, on_joint = local, True
    elif local is not None and (step.score <= 0 or step.step_shrink < MIN_STEP_SHRINK
                              or (not steps and step.step_shrink < need_of(step))):
        step, on_joint = local, True
    if S.weak and step.score < DECISIVE_SCORE:
        return _with(S.vetoes, S.probation("too small")), None, False
    if not on_joint and (step.score <= 0 or step.step_shrink < MIN_STEP_SHRINK):
        return _with(S.vetoes, Selection(steps, S.state, S.ev, "too small", step)), None, False
    need = need_of(step)
    if not steps and step.step_shrink < need and not on_joint:
        if step.score < DECISIVE_SCORE:
            return _with(S.vetoes, Selection(steps, S.state, S.ev, "weak", step)), None, False
        S.weak = (step, need)
    return None, step, on_joint


SWAP_SHRINK = 5.0  # [%] alone, an effect at the same place within this of a selected one is its rival


def swap_rivals(sel: Selection, ev0: dict, floor: dict, rivals, refit, *, n_params, channel_floor=None,
                implausible=None, richer=None, channel_rel=None) -> tuple[Selection, list]:
    """Each selected effect is tried against its rivals (``rivals(cand) -> list``: effects at the
    same place that alone closed nearly as much) inside the final model: the model is rebuilt from
    the nominal one with the rival in the effect's place and the other effects as selected, and
    the rival takes the place when the final excess falls by at least ``MIN_STEP_SHRINK`` % with no
    joint made worse beyond its floor and a plausible fit. Alone, two effects can close the same
    share (a constant offset and a spring over a small range of a joint's angle); beside the
    others, the one that holds the data's shape closes what the other leaves. Returns the
    selection (steps rebuilt in order) and ``[(replaced, by, excess before, excess after)]``.

    ``richer(alt, cand) -> bool`` (optional): ``alt`` contains ``cand`` (Stribeck friction contains
    Coulomb friction). Such a rival takes the place when, beside the others, its held-out criterion
    beats the selection's by DECISIVE_SCORE: a richer law that alone was too close to call (the
    parsimony rule kept the simpler) may be clear once the other effects are in."""
    swaps = []
    for i in range(len(sel.steps)):
        cands = [st.cand for st in sel.steps]
        _, _, exc_cur = gap_summary(sel.ev, floor)
        alts = rivals(cands[i])
        nested = [] if richer is None else [a for a in alts if richer(a, cands[i])]
        if exc_cur <= 0 and not nested:  # nothing left to close: the selection stands
            continue
        best = None
        for alt in alts:
            if alt in cands:
                continue
            chain, state, ev, ok = [], None, None, True
            for k, c in enumerate(cands[:i] + [alt] + cands[i + 1:]):
                prev_state, prev_ev = (chain[-1].state, chain[-1].ev) if chain else (sel.steps[0].state_before, ev0)
                state, ev = refit(prev_state, c)
                if implausible is not None and implausible(c, state):
                    ok = False
                    break
                _, _, e_prev = gap_summary(prev_ev, floor)
                _, _, e_new = gap_summary(ev, floor)
                chain.append(Step(c, state, ev, prev_ev, float(-ic_delta(ev, prev_ev, n_params(c))),
                                  float(100 * (1 - e_new / e_prev)) if e_prev > 0 else 0.0, prev_state))
            if not ok or worse_channels(ev, sel.ev, channel_floor, channel_rel):
                continue
            _, _, exc = gap_summary(ev, floor)
            if alt in nested:
                closes = -ic_delta(ev, sel.ev, n_params(alt) - n_params(cands[i])) >= DECISIVE_SCORE
            else:
                closes = exc < (1 - MIN_STEP_SHRINK / 100) * exc_cur
            if closes and (best is None or exc < best[0]):
                best = (exc, alt, chain)
        if best is not None:
            swaps.append((cands[i], best[1], exc_cur, best[0]))
            sel = dataclasses.replace(sel, steps=best[2], state=best[2][-1].state, ev=best[2][-1].ev)
    return sel, swaps


def _beyond(gap, floor, factor=SIGNIFICANCE) -> bool:
    """Whether a channel's gap [%] lies beyond its own floor [%] (``factor`` x it + ``MIN_GAP``;
    a channel without a floor never does)."""
    return floor is not None and floor > 0 and gap > factor * floor + MIN_GAP


def joints_beyond_floor(ev, channel_floor, channel_factor=None) -> list:
    """``(set, channel)`` of every torque channel whose gap lies beyond its own floor
    (``channel_floor[set][channel]`` [%], :func:`_beyond`, with the margin ``channel_factor[set][channel]``,
    default ``SIGNIFICANCE``). While one does, the pooled gap within noise does not end the search
    (only a candidate that resolves such a joint can still be taken, :func:`resolved_channels`)."""
    cf, fa = channel_floor or {}, channel_factor or {}
    return [(k, ch) for k, r in ev.items() if r.get("kind") == "torque"
            for ch, v in r["channels"].items() if _beyond(v, cf.get(k, {}).get(ch), fa.get(k, {}).get(ch, SIGNIFICANCE))]


def _with(vetoes, sel: Selection) -> Selection:
    sel.vetoed = list(vetoes)
    return sel


def step_record(added, ev, floor) -> dict:
    """The ``steps`` entry of a diagnosis: the gap after ``added`` (None: nominal)."""
    g, _, e = gap_summary(ev, floor)
    return dict(added=added, gap=g, excess=e, per_dataset={k: v["nrmse"] for k, v in ev.items()},
                per_channel={k: dict(v["channels"]) for k, v in ev.items()})


def verdict(significant: bool, remaining: bool, named: bool, shrink: float, floor_known: bool = True, *,
            gap_after: float | None = None, floor_upper: float | None = None) -> str:
    """``within_noise`` (no significant gap); ``explained`` (the named effects leave a gap within
    noise, ``remaining`` false, or close EXPLAINED_SHRINK % of the excess and leave a pooled gap
    ``gap_after`` of at most EXPLAINED_FLOOR_FACTOR x ``floor_upper``, the upper end of the pooled
    floor's interval [%]); ``partly_explained`` (an effect was named: it closed at least
    MIN_NAMED_SHRINK %, or supplied a measured mode the model lacked, but a gap beyond that remains),
    else ``unexplained``; ``floor_unknown`` when the noise floor could not be estimated
    (``floor_known`` false: no gap can be judged against the noise). Without ``gap_after`` and
    ``floor_upper`` a remaining significant gap is never ``explained``."""
    if not floor_known:
        return "floor_unknown"
    if not significant:
        return "within_noise"
    if named and not remaining:
        return "explained"
    if named and shrink >= EXPLAINED_SHRINK and remaining_small(gap_after, floor_upper):
        return "explained"
    if named:
        return "partly_explained"
    return "unexplained"


def remaining_small(gap_after: float | None, floor_upper: float | None) -> bool:
    """Whether the pooled gap left (``gap_after`` [%]) is small in absolute terms: at most
    EXPLAINED_FLOOR_FACTOR x the upper end of the pooled floor's interval (``floor_upper`` [%])."""
    if gap_after is None or floor_upper is None or not np.isfinite(floor_upper) or floor_upper <= 0:
        return False
    return gap_after <= EXPLAINED_FLOOR_FACTOR * floor_upper


def pooled_upper(floor: dict, upper: dict | None) -> float:
    """The upper end of the pooled floor's interval [%]: the sets' upper ends (their floor where
    no interval is known) pooled as :func:`gap_summary` pools the floors."""
    up = upper or {}
    f = np.array([max(float(up.get(k) or 0.0), float(floor[k])) for k in floor])
    return float(np.sqrt(np.mean(f**2))) if len(f) else float("nan")


def stop_reason(sel: Selection, names) -> str:
    """Why the search stopped, in words (the report's and diagnosis.json's ``stop_reason``)."""
    best = sel.rejected.cand.label(names) if sel.rejected is not None else None
    why = {
        "not significant": "the nominal gap is within the noise floor: nothing to explain",
        "joint": "the gap pooled over the joints is within the noise floor but some joint's is beyond its own "
                 "floor, and no candidate brings that joint within it on its own evidence"
                 + (f" (the best pooled candidate: {best})" if best else ""),
        "within noise": "what remains is within the noise floor",
        "max effects": "the most effects to add (max_effects) were added",
        "no candidate": "no candidate effect applies to these data",
        "too small": f"the best next candidate ({best}) closes less than {MIN_STEP_SHRINK:.0f} % of the remaining "
                     "excess or does not pay for its parameters on held-out data",
        "weak": f"the best candidate ({best}) closes only {sel.rejected.step_shrink:.0f} % of the excess gap "
                + (f"alone and {sel.together[1]:.0f} % with the decisive effects that followed it "
                   f"({', '.join(c.label(names) for c in sel.together[0]) or 'none'}) "
                   if sel.together is not None else "")
                + f"(less than {MIN_NAMED_SHRINK:.0f} %): no effect of the library explains the gap"
                if sel.rejected is not None else "",
    }
    return why.get(sel.stop, sel.stop)
