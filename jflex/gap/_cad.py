"""The CAD inertias as the diagnosis judges them: the gap spread their tolerance gives on data that
cannot identify them, a nominal refit held at its tolerance tried with a wider one, and how far the
nominal identification moved each link from CAD."""

from __future__ import annotations

import dataclasses

import numpy as np

from ._inertia import PARAM_NAMES, PARAM_UNITS, inertia_prior, link_moves
from ._problem import Problem, State
from .frequency._inertia import cad_spread
from .judge._selection import gap_summary, is_significant, joints_beyond_floor
from .response._response import cad_spread as cad_spread_response


def tolerance_spread(pb: Problem, nom: State) -> dict:
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



CAD_WIDE_REACH = 4.0  # x the prior's scale: the box a nominal refit held at its tolerance is tried with (2 x the usual)


def beyond_tolerance(pb: Problem, nom: State, floor, upper, factor, cfloor, cfactor) -> dict | None:
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
    d = np.asarray(st.tfit.delta, float).reshape(-1, 10)
    far = prior.beyond(st.tfit.delta).reshape(-1, 10)
    links = []
    for i in np.flatnonzero(far.any(axis=1)):
        p0 = prior.pi0.reshape(-1, 10)[i]
        links.append(dict(link=pb.robot.link_names[i], parameters=[
            f"{PARAM_NAMES[k]} {d[i, k]:+.4g} {PARAM_UNITS[k]}" + (f" ({100 * d[i, k] / p0[k]:+.0f} %)" if k == 0 and p0[k] else "")
            for k in np.flatnonzero(far[i])]))
    return dict(gap=gap_summary(ev, floor)[0], links=links) if links else None


def inertia_report(pb: Problem, nom: State):
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
