"""The selection rules of jflex.gap on a toy problem whose gaps are known in closed form: each
effect removes its own share of the squared excess (independent effects), so the held-out gap of
any set of effects, and hence every shrink and score, follows without a fit."""

import numpy as np
import pytest

from jflex.gap import DECISIVE_SCORE, MIN_NAMED_SHRINK, forward_select, gap_summary, is_significant

FLOOR = {"v": 1.0}


def _problem(shares, neff):
    """``shares``: squared excess each effect explains; what no effect explains stays."""

    def ev(added):
        left = sum(v for k, v in shares.items() if k not in added and not k.startswith("?"))
        left += sum(v for k, v in shares.items() if k.startswith("?"))
        return {"v": {"nrmse": float(np.sqrt(1.0 + left)), "neff": neff}}

    cands = [k for k in shares if not k.startswith("?")]
    refit = lambda state, c: (state + (c,), ev(state + (c,)))
    return (), ev(()), cands, refit


def _select(shares, neff=1000.0):
    s0, ev0, cands, refit = _problem(shares, neff)
    return forward_select(s0, ev0, FLOOR, cands, refit, n_params=lambda c: 1, max_effects=3,
                          min_first_shrink=MIN_NAMED_SHRINK)


def test_two_real_effects_each_partial_are_named_together():
    # a alone closes 1 - sqrt(14/24) = 24 %, b alone 35 %: neither reaches MIN_NAMED_SHRINK alone
    sel = _select({"a": 10.0, "b": 14.0})
    assert [s.cand for s in sel.steps] == ["b", "a"]
    assert sel.steps[0].step_shrink < MIN_NAMED_SHRINK and sel.steps[0].score >= DECISIVE_SCORE
    assert sel.stop == "within noise"
    _, _, exc = gap_summary(sel.ev, FLOOR)
    assert exc == pytest.approx(0.0, abs=1e-12)


def test_partial_effects_with_weak_evidence_are_not_named():
    # the same gaps seen on few held-out samples: the first step is not decisive evidence
    sel = _select({"a": 10.0, "b": 14.0}, neff=20.0)
    assert sel.steps == [] and sel.stop == "weak" and sel.rejected.cand == "b"
    assert sel.rejected.score < DECISIVE_SCORE


def test_a_lone_partial_match_to_an_unknown_effect_is_not_named():
    # x closes 30 % decisively; the rest ("?unknown") no candidate explains: nothing named
    sel = _select({"x": 8.0, "?unknown": 16.0})
    assert sel.steps == [] and sel.stop == "weak" and sel.rejected.cand == "x"
    assert sel.rejected.score >= DECISIVE_SCORE
    assert sel.ev["v"]["nrmse"] == pytest.approx(5.0)
    # the report says what the probation reached: x alone, no decisive partner
    assert sel.together == ((), pytest.approx(100 * (1 - 4.0 / np.sqrt(24.0))))


def test_stop_reason_of_a_failed_probation_names_what_followed():
    from jflex.gap.judge._selection import stop_reason

    class C(str):
        def label(self, names):
            return f"{self}@j"

    s0, ev0, cands, refit = _problem({"x": 8.0, "y": 4.0, "?unknown": 12.0}, 1000.0)
    sel = forward_select(s0, ev0, FLOOR, [C(c) for c in cands], refit, n_params=lambda c: 1, max_effects=3,
                         min_first_shrink=MIN_NAMED_SHRINK)
    # x then y are decisive but together close 1 - sqrt(12/24) = 29 % < 50 %: nothing named
    assert sel.steps == [] and sel.together[0] == ("y",) and sel.together[1] == pytest.approx(100 * (1 - np.sqrt(0.5)))
    msg = stop_reason(sel, ())
    assert "x@j" in msg and "y@j" in msg and "29 %" in msg


def test_a_first_effect_above_the_share_is_named_alone():
    sel = _select({"a": 20.0, "?unknown": 4.0})
    assert [s.cand for s in sel.steps] == ["a"] and sel.steps[0].step_shrink >= MIN_NAMED_SHRINK


def test_on_select_reports_probation_steps_once_accepted():
    s0, ev0, cands, refit = _problem({"a": 10.0, "b": 14.0}, 1000.0)
    seen = []
    forward_select(s0, ev0, FLOOR, cands, refit, n_params=lambda c: 1, max_effects=3,
                   min_first_shrink=MIN_NAMED_SHRINK, on_select=lambda st: seen.append(st.cand))
    assert seen == ["b", "a"]


def test_a_large_gap_left_over_is_not_explained_whatever_share_closed():
    from jflex.gap import EXPLAINED_FLOOR_FACTOR, verdict

    # a real TIAGo log: 80 % of the excess closed, 504 % left against a floor of 46 % whose 95 %
    # interval is 36.5-62.2 %: ten times the floor left over is no explanation
    assert verdict(True, True, True, 80.5, gap_after=504.0, floor_upper=62.2) == "partly_explained"
    # the same share closed leaving a gap inside twice the floor's upper end is
    assert verdict(True, True, True, 80.5, gap_after=EXPLAINED_FLOOR_FACTOR * 62.2 - 0.1, floor_upper=62.2) == "explained"
    # a small gap left but too little of the excess closed stays partly explained
    assert verdict(True, True, True, 60.0, gap_after=60.0, floor_upper=62.2) == "partly_explained"
    # what remains within noise is explained whatever the sizes
    assert verdict(True, False, True, 30.0, gap_after=504.0, floor_upper=62.2) == "explained"
    # without the sizes a significant remainder is never explained
    assert verdict(True, True, True, 99.0) == "partly_explained"
    assert verdict(True, True, False, 99.0, gap_after=1.0, floor_upper=62.2) == "unexplained"


def test_pooled_upper_end_of_the_floor():
    from jflex.gap import pooled_upper

    # RMS over the sets of each set's upper end, its floor where no interval is known
    floor = {"a": 1.0, "b": 2.0, "c": 3.0}
    assert pooled_upper(floor, {"a": 1.5, "b": None}) == pytest.approx(np.sqrt((1.5**2 + 2.0**2 + 3.0**2) / 3))


def _two_joint_problem(small_after):
    """A heavy joint whose gap no candidate closes and a light one (1e-5 of the torque energy)
    whose 12 % gap the candidate ``drive`` brings to ``small_after``; ``other`` closes a little of
    the pooled gap. Pooled as the diagnosis pools: sqrt(sum_j w_j nrmse_j^2)."""
    w = {"big": 1.0 - 1e-5, "small": 1e-5}
    gaps = {(): {"big": 1.10, "small": 12.0}, ("drive",): {"big": 1.10, "small": small_after},
            ("other",): {"big": 1.06, "small": 12.0}}

    def ev(added):
        ch = gaps[tuple(sorted(added))] if tuple(sorted(added)) in gaps else gaps[()]
        pooled = float(np.sqrt(sum(w[c] * v**2 for c, v in ch.items())))
        return {"v": {"kind": "torque", "nrmse": pooled, "channels": dict(ch), "neff": 600.0}}

    refit = lambda state, c: (state + (c,), ev(state + (c,)))
    return ev, refit


def test_a_gap_on_a_light_joint_is_named_on_that_joints_evidence():
    # the pooled gap barely moves (the light joint weighs nothing in it), so the pooled criterion is
    # no evidence; the joint's own (12 % -> 0.4 %, within its 4 % floor) is
    floor, cfloor = {"v": 0.37}, {"v": {"big": 0.40, "small": 4.0}}
    for small_after, named in ((0.4, ["drive"]), (6.0, [])):
        ev, refit = _two_joint_problem(small_after)
        sel = forward_select((), ev(()), floor, ["drive", "other"], refit, n_params=lambda c: 3, max_effects=3,
                             min_first_shrink=MIN_NAMED_SHRINK, channel_floor=cfloor)
        assert [s.cand for s in sel.steps] == named, small_after


def test_a_joint_beyond_its_floor_under_a_pooled_gap_within_noise():
    from jflex.gap.judge._selection import joints_beyond_floor

    # the pooled gap (1.10 %) is within its floor (1.0 %: 1.2 x 1.0 + 0.2 = 1.4), the light joint's
    # 12 % is three times its own 4 % floor
    floor, cfloor = {"v": 1.0}, {"v": {"big": 1.0, "small": 4.0}}
    ev, refit = _two_joint_problem(0.4)
    assert not is_significant(ev(()), floor)
    assert joints_beyond_floor(ev(()), cfloor) == [("v", "small")]
    for small_after, named, stop in ((0.4, ["drive"], "within noise"), (6.0, [], "joint")):
        ev, refit = _two_joint_problem(small_after)
        sel = forward_select((), ev(()), floor, ["drive", "other"], refit, n_params=lambda c: 3, max_effects=3,
                             min_first_shrink=MIN_NAMED_SHRINK, channel_floor=cfloor, significant=True,
                             joint_only=True)
        assert [s.cand for s in sel.steps] == named and sel.stop == stop, small_after
    # without joint_only, a pooled gap within noise names nothing
    sel = forward_select((), ev(()), floor, ["drive", "other"], refit, n_params=lambda c: 3, max_effects=3,
                         min_first_shrink=MIN_NAMED_SHRINK, channel_floor=cfloor)
    assert sel.steps == [] and sel.stop == "not significant"


def test_a_joint_resolved_at_the_pooled_gaps_expense_is_not_named():
    # the candidate brings the light joint within its floor but grows the pooled excess by half:
    # it stands in for something else
    floor, cfloor = {"v": 1.0}, {"v": {"big": 1.0, "small": 4.0}}
    w = {"big": 1.0 - 1e-5, "small": 1e-5}
    gaps = {(): {"big": 1.10, "small": 12.0}, ("offset",): {"big": 1.30, "small": 0.4}}

    def ev(added):
        ch = gaps[tuple(added)]
        return {"v": {"kind": "torque", "nrmse": float(np.sqrt(sum(w[c] * v**2 for c, v in ch.items()))),
                      "channels": dict(ch), "neff": 600.0}}

    sel = forward_select((), ev(()), floor, ["offset"], lambda st, c: (st + (c,), ev(st + (c,))), n_params=lambda c: 1,
                         max_effects=3, min_first_shrink=MIN_NAMED_SHRINK, channel_floor=cfloor, significant=True,
                         joint_only=True)
    assert sel.steps == [] and sel.stop == "joint"


def _table_problem(left):
    """Gaps from a table: ``left[frozenset(effects)]`` is the squared excess those effects leave."""

    def ev(added):
        return {"v": {"nrmse": float(np.sqrt(1.0 + left[frozenset(added)])), "neff": 1000.0}}

    refit = lambda state, c: (state + (c,), ev(state + (c,)))  # noqa: E731
    return ev, refit


@pytest.mark.parametrize("shape_left, swapped, both_left", [(0.0, True, 0.3), (0.28, False, 0.3), (0.0, False, 0.0)])
def test_a_rival_that_closes_what_the_selected_effect_left_takes_its_place(shape_left, swapped, both_left):
    # alone, an offset closes a little more than the spring that is really there (its constant
    # part); beside the rotor inertia also selected, the spring closes what the offset leaves (its
    # shape): it takes the offset's place, unless the gain is below MIN_STEP_SHRINK of the excess,
    # or no excess is left to close (both leave none: the selection stands)
    from jflex.gap.judge._selection import MIN_STEP_SHRINK, swap_rivals

    F = frozenset
    left = {F(): 40.0, F({"offset"}): 13.0, F({"spring"}): 13.5, F({"rotor"}): 30.0,
            F({"offset", "rotor"}): both_left, F({"spring", "rotor"}): shape_left, F({"offset", "spring"}): 12.0,
            F({"offset", "spring", "rotor"}): 0.0}
    ev, refit = _table_problem(left)
    sel = forward_select((), ev(()), FLOOR, ["offset", "spring", "rotor"], refit, n_params=lambda c: 1,
                         max_effects=3, min_first_shrink=MIN_NAMED_SHRINK)
    assert [s.cand for s in sel.steps] == ["offset", "rotor"] and sel.stop == "within noise"
    new, swaps = swap_rivals(sel, ev(()), FLOOR, lambda c: {"offset": ["spring"]}.get(c, []), refit,
                             n_params=lambda c: 1)
    _, _, exc_before = gap_summary(sel.ev, FLOOR)
    if swapped:
        assert [s.cand for s in new.steps] == ["spring", "rotor"] and new.state == ("spring", "rotor")
        assert swaps == [("offset", "spring", pytest.approx(exc_before), pytest.approx(0.0))]
        # each rebuilt step knows the model it was added to and what it closed of that model's excess
        assert new.steps[1].state_before == ("spring",)
        assert new.steps[0].step_shrink == pytest.approx(100 * (1 - np.sqrt(13.5) / np.sqrt(40.0)))
    else:
        assert exc_before == 0 or 100 * (1 - np.sqrt(shape_left) / exc_before) < MIN_STEP_SHRINK
        assert new is sel and swaps == []


@pytest.mark.parametrize("rich_gap, neff, rich_named", [(1.0, 1000.0, True), (1.75, 1000.0, False), (1.0, 20.0, False)])
def test_a_richer_nested_effect_is_named_when_the_held_out_criterion_says_so(rich_gap, neff, rich_named):
    # The floor (2.0) is an upper bound twice the noise: the simpler effect (held-out gap 1.8) and
    # the richer one that contains it (rich_gap) both close 100 % of the excess. The simpler one
    # wins unless the richer one's held-out criterion is decisively better (many samples and a
    # clearly lower gap); a near tie or thin evidence keeps the simpler name.
    from jflex.gap.judge._selection import rank_entries, simpler_holds

    floor = {"v": 2.0}
    gaps = {(): 4.0, ("simple",): 1.8, ("rich",): rich_gap}
    ev = lambda added: {"v": {"nrmse": gaps[tuple(added)], "neff": neff}}
    refit = lambda state, c: ((c,), ev((c,)))
    sel = forward_select((), ev(()), floor, ["simple", "rich"], refit, n_params=lambda c: 1 if c == "simple" else 3,
                         max_effects=1, simpler=lambda rich, simple: (rich, simple) == ("rich", "simple"),
                         min_first_shrink=MIN_NAMED_SHRINK)
    assert [s.cand for s in sel.steps] == (["rich"] if rich_named else ["simple"])
    assert all(s.step_shrink == pytest.approx(100.0) for s in sel.steps)
    # the first-round ranking follows the same rule
    entries = [dict(effect=e, joint="j", shrink=100.0, score=-1000.0) for e in ("stribeck_friction", "coulomb_friction")]
    scores = {e: float(neff * np.log(16.0 / g**2) - p * np.log(neff)) for e, g, p in
              (("coulomb_friction", 1.8, 1), ("stribeck_friction", rich_gap, 3))}
    for e in entries:
        e["score"] = scores[e["effect"]]
    first = entries[rank_entries(entries)[0]]["effect"]
    assert first == ("stribeck_friction" if rich_named else "coulomb_friction")
    assert simpler_holds(100.0, scores["coulomb_friction"], 100.0, scores["stribeck_friction"]) is (not rich_named)


@pytest.mark.parametrize("rich_left, floor, swapped", [(0.0, 1.0, True), (0.0, 1.5, True), (0.9, 1.0, False)])
def test_a_richer_nested_law_takes_the_place_of_the_simpler_beside_the_others(rich_left, floor, swapped):
    # alone, Stribeck friction is too close to Coulomb friction to call (the simpler is named);
    # beside the sensor delay also selected, the richer law's held-out criterion is decisively
    # better (rich_left 0) and it takes the place, also when the floor (1.5, an upper bound above
    # the noise) leaves no excess to close; barely better (0.9), it does not
    from jflex.gap.judge._selection import swap_rivals

    F = frozenset
    left = {F(): 40.0, F({"coulomb"}): 13.0, F({"stribeck"}): 12.9, F({"delay"}): 27.0, F({"coulomb", "stribeck"}): 12.9,
            F({"coulomb", "delay"}): 1.0, F({"stribeck", "delay"}): rich_left}
    ev, refit = _table_problem(left)
    fl = {"v": floor}
    n_params = {"coulomb": 1, "stribeck": 3, "delay": 1}.get
    simpler = lambda rich, simple: (rich, simple) == ("stribeck", "coulomb")  # noqa: E731
    sel = forward_select((), ev(()), fl, ["coulomb", "stribeck", "delay"], refit, n_params=n_params, max_effects=2,
                         simpler=simpler, min_first_shrink=MIN_NAMED_SHRINK)
    assert [s.cand for s in sel.steps] == ["coulomb", "delay"]
    rivals = lambda c: ["stribeck"] if c == "coulomb" else []  # noqa: E731
    new, swaps = swap_rivals(sel, ev(()), fl, rivals, refit, n_params=n_params, richer=simpler)
    if swapped:
        assert [s.cand for s in new.steps] == ["stribeck", "delay"] and swaps[0][:2] == ("coulomb", "stribeck")
    else:
        assert new is sel and swaps == []
    if floor > 1.0:
        # no excess left: without the nesting declared, the selection stands
        plain, none = swap_rivals(sel, ev(()), fl, rivals, refit, n_params=n_params)
        assert plain is sel and none == []
