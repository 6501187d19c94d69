"""The diagnosis' verdict (:func:`._selection.verdict`) and what overrides it: a gap within the
spread of the CAD inertias' tolerance, a CAD beyond its tolerance, an unknown noise floor, a torque
off in scale, and channels whose floor is their own residual."""

from __future__ import annotations

import dataclasses

import numpy as np

from ._cad import CAD_WIDE_REACH, beyond_tolerance, tolerance_spread
from .judge._noise import NoiseFloor
from .judge._selection import MIN_GAP, is_significant, stop_reason, verdict
from .torque._scale import scale_reason

UNPREDICTED_FACTOR = 3.0  # x the other joints' median floor: a gap no noise level of theirs explains


@dataclasses.dataclass(frozen=True)
class Verdict:
    """The verdict, why the search stopped, the CAD tolerance's spread and a CAD beyond its tolerance."""

    verdict: str
    reason: str
    spread: dict
    cad_far: dict | None


def final_verdict(pb, nom, ev0: dict, floor: NoiseFloor, off_scale, sel, significant: bool, shrink_total: float,
                  gap_after: float, floor_high, remaining: bool, *, upper: dict, factor: dict, cfloor: dict,
                  cfactor: dict) -> Verdict:
    """The verdict and why the search stopped (:func:`verdict`), then what overrides it: a gap
    within the CAD tolerance's spread or a CAD beyond its tolerance (within noise), an unknown
    floor, a torque off in scale, channels whose floor is their own residual."""
    floor_set, floor = floor, floor.per_dataset
    verdict_ = verdict(significant, remaining, bool(sel.steps), shrink_total, gap_after=gap_after, floor_upper=floor_high)
    reason = stop_reason(sel, pb.names)
    failed_floor = floor_set.failed
    spread = tolerance_spread(pb, nom) if verdict_ == "unexplained" else {}
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
        cad_far = beyond_tolerance(pb, nom, floor, upper, factor, cfloor, cfactor)
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
    hidden = unpredicted(ev0, floor_set.details)
    if hidden and verdict_ in ("within_noise", "explained"):
        # a channel's floor that is its own residual cannot clear it: say so rather than let the
        # pooled verdict speak for that joint
        reason = ((f"{reason}; " if reason else "") + "the floors of " + ", ".join(
            f"{c} in {k} (gap {g:.2f} %)" for k, c, g in hidden) + " are their own residual: no function of the "
            "motion predicted any of it, so whether those joints' gaps are noise is unknown")
    return Verdict(verdict_, reason, spread, cad_far)


def unpredicted(ev, details) -> list:
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
