"""The selection rules of jflex.gap on a toy problem whose gaps are known in closed form: each
effect removes its own share of the squared excess (independent effects), so the held-out gap of
any set of effects, and hence every shrink and score, follows without a fit."""

import numpy as np
import pytest

from jflex.gap import DECISIVE_SCORE, MIN_NAMED_SHRINK, forward_select, gap_summary

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
    from jflex.gap._selection import stop_reason

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
