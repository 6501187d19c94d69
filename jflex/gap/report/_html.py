"""``report.html``: the diagnosis as one self-contained page an engineer reads at a glance.

Figures are embedded as base64 PNG and the page loads nothing from the network. It says what
was diagnosed (the robot, by name), the verdict and why the search stopped, why each effect was
selected, the payload as a mass and a centre of mass in the tool frame, and, per validation data
set, measured against nominal against final model; each figure is explained once in its caption.
"""

from __future__ import annotations

import base64
import html
import pathlib

import numpy as np

from ..judge._selection import MIN_NAMED_SHRINK, MIN_STEP_SHRINK, vetoed
from ...effects._registry import LINK_FLEXIBILITY, ORTHOGONAL_COMPLIANCE, PAYLOAD

SECTIONS = {
    "summary": "Verdict",
    "data": "The data: channels left out and conditioning",
    "selected": "Selected effects and why",
    "model": "The model: nominal effects and fitted parameters",
    "datasets": "Measured against nominal and final model, per validation data set",
    "waterfall": "The gap as effects are added",
    "where": "Where the nominal model misses",
    "ranking": "Candidate ranking",
    "terms": "How to read the numbers",
}

TERMS = [
    ("gap", "the validation NRMSE [%] of a model on data no fit saw: torques rms(model - measured) / std(measured) "
            "per joint; FRFs sqrt(sum |H_model - H|^2 / sum |H|^2); modal tables the RMS relative frequency error "
            "(plus 0.1 x the damping error)."),
    ("noise floor", "the gap that measurement noise alone would leave, never estimated from a candidate model: from "
                    "repeated records, else the scatter of the torque between the periods of a periodic motion, else "
                    "what a flexible black-box model of the motion cannot predict on held-out samples (an upper "
                    "bound); with its 95 % interval. No model does better. A torque set's gap and floor pool the "
                    "joints: residual energy over torque-signal energy, so a joint weighs by its share of the signal."),
    ("excess", "sqrt(gap^2 - floor^2): the part of the gap a model can close."),
    ("shrink", "the percentage of the nominal model's excess that a model closes (100 % = down to the noise)."),
    ("step shrink", "the percentage of the excess left before a step that the step's effect closes."),
    ("score", "how much an effect lowers the held-out information criterion (BIC form: the change of "
              "N ln(mse) over the validation samples, plus a penalty of ln N per added parameter), with the sign "
              "flipped: positive means the effect predicts held-out data better by more than its parameters cost; "
              "the larger, the stronger the evidence."),
    ("signature", "how well the nominal model's residual correlates with the pattern the effect would produce "
                  "(e.g. the sign of the joint velocity for Coulomb friction), 0 to 1; it chooses which candidates "
                  "are refitted, it does not select."),
]

VERDICTS = {
    "explained": ("the selected effects bring the gap to the noise floor, or close at least 80 % of the excess "
                  "and leave a gap of at most twice the upper end of the noise floor's interval"),
    "partly_explained": "an effect was named but a significant gap remains, larger than twice the noise floor's upper end",
    "unexplained": "no effect of the candidate library closes enough of the gap to be named",
    "within_noise": "the nominal model's gap is already within the noise floor",
    "floor_unknown": "the noise floor could not be estimated, so whether the gap exceeds the noise is unknown",
}


def floor_sentence(r: dict) -> str:
    """How the noise floor was estimated, per validation set, with its 95 % interval; a failed
    estimate said as such."""
    parts = []
    for k, d in (r.get("noise_floor_details") or {}).items():
        if d.get("failed"):
            parts.append(f"{k}: estimate failed ({d.get('reason')}), the floor is unknown")
        elif d.get("low") is not None and d.get("high") is not None and d["high"] > d["low"]:
            parts.append(f"{k}: {d['floor']:.2f} % (95 % interval {d['low']:.2f}-{d['high']:.2f} %) from {d.get('method')}")
        else:
            parts.append(f"{k}: {d['floor']:.2f} % from {d.get('method')}")
    out = ("Noise floor per validation set: " + "; ".join(parts) + ".") if parts else ""
    t = r.get("test")
    if t and parts:
        fac = [f"{k}: {v:.2f} x" for k, v in (t.get("factor") or {}).items() if np.isfinite(v)]
        cf = [v for d in (t.get("channel_factor") or {}).values() for v in d.values() if np.isfinite(v)]
        out += (f" A gap is beyond its floor when it exceeds a margin x the floor + {t['min_gap']:g} %, the margin set "
                f"for a false-alarm rate of {100 * t['family_alpha']:g} % over all {t['tests']} sets and joints tested "
                "together (from the effective samples of each one's noise)"
                + (f": {', '.join(fac)} pooled" if fac else "")
                + (f", {min(cf):.2f}-{max(cf):.2f} x per joint" if cf else "") + ".")
    return out


def data_notes(r: dict) -> list[str]:
    """Sentences on the data: the channels left out of the gap and why, and what the data
    conditioning did to each record beyond :func:`conditioning_table` (a merge of several files,
    a time window, a conditioning the table does not know)."""
    out = []
    for k, chans in (r.get("excluded_channels") or {}).items():
        out.append(f"Left out of the gap in '{k}': " + "; ".join(f"{c} ({w})" for c, w in chans.items()) + ".")
    for k, cond in (r.get("conditioning") or {}).items():
        if isinstance(cond, dict) and cond:
            tab = _tabulated(cond)
            rest = {a: b for a, b in cond.items() if not (tab and a in _TABULATED and _TABULATED[a](b))}
            if "merge" in rest and isinstance(rest["merge"], dict):
                m = rest.pop("merge")
                out.append(f"'{k}' merged from {', '.join(map(str, m.get('files', [])))}: {m.get('merged', '')}.")
            for w in rest.pop("warnings", None) or ():
                out.append(f"Warning ('{k}'): {w}")
            if "window_s" in rest:
                w = rest.pop("window_s")
                a, b = (list(w) + [None, None])[:2]
                out.append(f"'{k}' cut to the window from {a or 0:g} s to "
                           + ("the end of the record." if b is None else f"{b:g} s."))
            if rest:
                out.append(f"Conditioning of '{k}': " + "; ".join(f"{a}: {_short(b)}" for a, b in rest.items()) + ".")
        elif cond:
            out.append(f"Conditioning of '{k}': {_short(cond)}.")
    return out


# the conditioning report's parts that conditioning_table shows (a record's dict holding its
# "sampling" and "channels" dicts is tabulated; anything else stays a sentence)
_TABULATED = {"sampling": lambda v: isinstance(v, dict), "channels": lambda v: isinstance(v, dict),
              "spikes": lambda v: isinstance(v, dict), "excluded": lambda v: isinstance(v, (list, tuple)),
              "derivatives": lambda v: isinstance(v, str)}
_DERIVATIVES = {"given": "velocities and accelerations given", "none": "from the angles",
                "velocity": "velocities given; accelerations from them, filtered"}
CONDITIONING_HEAD = ("record", "rate [Hz]", "time stamps", "torque channels", "spikes", "derivatives", "low-pass [Hz]")


def _tabulated(cond) -> bool:
    return isinstance(cond, dict) and isinstance(cond.get("sampling"), dict) and isinstance(cond.get("channels"), dict)


def _stamps(s: dict) -> str:
    j = float(s.get("jitter_pct", 0.0))
    parts = [f"jitter {j:.2g} %" if j >= 0.01 else "uniform"]
    for key, words in (("dropped_samples", "dropped"), ("repeated_stamps", "repeated stamps"),
                       ("repeated_rows", "stale rows")):
        if s.get(key):
            parts.append(f"{s[key]} {words}")
    if s.get("resampled"):
        parts.append(f"resampled ({s.get('samples_in', '?')} -> {s.get('samples_out', '?')} samples)"
                     if "samples_in" in s else "resampled")
    gaps = [g for g in s.get("gaps") or () if isinstance(g, dict)]
    if gaps:
        parts.append(f"{len(gaps)} gap(s) bridged (longest {max(g.get('length_s', 0.0) for g in gaps):.3g} s)")
    cut = s.get("split_from")
    if isinstance(cut, dict):  # a stretch of a log cut at gaps too long to bridge (jflex.gap.load_case)
        n = sum(1 for g in cut.get("gaps") or () if isinstance(g, dict) and g.get("action") == "split")
        a, b = (list(cut.get("span_s") or ()) + [float("nan")] * 2)[:2]
        parts.append(f"stretch {cut.get('stretch')} of {cut.get('stretches')} of '{cut.get('record')}' "
                     f"({a:.6g} to {b:.6g} s), cut at {n} gap(s)")
    return ", ".join(parts)


def _channel_flags(cond: dict) -> str:
    bad = []
    for j, q in cond["channels"].items():
        flags = [f for f in (q or {}).get("flags", []) if f != "spikes"]
        if flags:
            how = "kept by the user" if q.get("kept_by_user") else "left out" if j in cond.get("excluded", ()) else "kept"
            bad.append(f"{j}: {', '.join(f.replace('_', ' ') for f in flags)} ({how})")
    return "; ".join(bad) if bad else f"all {len(cond['channels'])} pass"


def conditioning_table(r: dict) -> list[tuple]:
    """One row per record the data layer conditioned (:data:`CONDITIONING_HEAD`): its rate, what
    was found in its stamps and done about it, the torque channels flagged (dead, stuck, flat,
    saturated, few levels) and whether they were left out, spikes, where the derivatives came from,
    and the low-pass cutoff the record's own spectrum gave (with the method)."""
    rows = []
    proc = r.get("processing") or {}
    for k, cond in (r.get("conditioning") or {}).items():
        if not _tabulated(cond):
            continue
        s = cond["sampling"]
        spikes = "; ".join(f"{j}: {v.get('count')} ({v.get('action')})" for j, v in (cond.get("spikes") or {}).items()) or "-"
        p = proc.get(k) or {}
        der = p.get("derivatives") or _DERIVATIVES.get(cond.get("derivatives"), str(cond.get("derivatives", "-")))
        cut = p.get("cutoff_hz")
        lowpass = "-" if cut is None else f"{cut:.3g} ({str(p.get('cutoff_method', '?')).replace('_', ' ')})"
        rows.append((k, f"{s.get('rate_hz', float('nan')):.4g}", _stamps(s), _channel_flags(cond), spikes, der, lowpass))
    return rows


def _short(x, n=160) -> str:
    t = str(x)
    return t if len(t) <= n else t[:n - 3] + "..."


def _e(x) -> str:
    return html.escape(str(x))


def _num(x, nd=2) -> str:
    if isinstance(x, str):  # a law's name among the numbers
        return _e(x)
    return "-" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.{nd}f}"


def _table(head, rows, cls="") -> str:
    h = "".join(f"<th>{_e(c)}</th>" for c in head)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f'<table class="{cls}"><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>'


def _figure(out: pathlib.Path, fig: dict) -> str:
    data = base64.b64encode((out / fig["file"]).read_bytes()).decode("ascii")
    return (f'<figure><img alt="{_e(fig["file"])}" src="data:image/png;base64,{data}">'
            f'<figcaption><b>{_e(fig["file"])}</b>: {_e(fig["caption"])}</figcaption></figure>')


def where_label(entry) -> str:
    e = entry
    return f"{e['effect']}@{e['joint']}" if e.get("joint") else (f"{e['effect']}@{e['link']}" if e.get("link") else e["effect"])


def bound_words(m: dict) -> str:
    """The 'at tolerance bound' cell of a link: which parameters reached it, and by how much."""
    if not m.get("at_tolerance_bound"):
        return "no"
    b = m.get("bound_parameters")
    return "yes: " + ", ".join(b) if b else "yes"


def placed(effect: str, where) -> str:
    """An effect and where it sits, in words (an effect of no joint, e.g. a sensor's delay, alone)."""
    return effect if where in (None, "", "None") else f"{effect} at {where}"


def significance_words(significant: bool) -> str:
    return "significant (above the noise floor)" if significant else "not significant (within the noise floor)"


def payload_summary(params: dict, robot, tool_frame) -> dict | None:
    """The fitted payload as mass [kg] and centre of mass [m] in the tool frame (or the last link's
    frame when the case names no tool frame on it); None when no payload was fitted."""
    if PAYLOAD in params.get("torque", {}):
        p = params["torque"][PAYLOAD]
        m = float(p["m [kg]"])
        mc = np.array([p["m cx [kg m]"], p["m cy [kg m]"], p["m cz [kg m]"]], dtype=float)
        why = _nonphysical(m, mc, p)
        if why:
            return dict(mass_kg=m, com_m=None, frame=None, side="torque data (10 inertial parameters fitted)",
                        nonphysical=why)
        c_link = mc / m
        last = robot.nq - 1
        frame = f"last link frame ({robot.link_names[last]})"
        c = c_link
        if tool_frame is not None:
            body, k = robot.frame_index(tool_frame)
            if body == last:
                R = np.asarray(robot.frame_R[k]) if k >= 0 else np.eye(3)
                pos = np.asarray(robot.frame_p[k]) if k >= 0 else np.zeros(3)
                c, frame = R.T @ (c_link - pos), f"tool frame '{tool_frame}'"
        return dict(mass_kg=m, com_m=c.tolist(), frame=frame, side="torque data (10 inertial parameters fitted)")
    if PAYLOAD in params.get("linear", {}):
        p = params["linear"][PAYLOAD]
        m = float(p["mass [kg]"])
        com = [float(v) for v in p.get("com (tool frame) [m]", (0.0, 0.0, 0.0))]
        what = {1: "a point mass at the tool frame's origin", 4: "a point mass: its mass and centre of mass"}.get(
            int(p.get("parameters", 1)), "a rigid body: its mass, centre of mass and rotational inertia")
        return dict(mass_kg=m, com_m=com, frame=f"tool frame '{tool_frame}'", side=f"FRF/modal data ({what})")
    return None


def _nonphysical(m: float, mc, p: dict) -> str | None:
    """Why fitted payload parameters describe no rigid body (None when they do): a mass that is not
    positive, or an inertia about the centre of mass that is not positive semi-definite or breaks
    the triangle inequality."""
    if not np.isfinite(m) or m <= 1e-9:
        return f"mass {m:.3g} kg (not positive)"
    keys = ("Ixx [kg m^2]", "Ixy [kg m^2]", "Iyy [kg m^2]", "Ixz [kg m^2]", "Iyz [kg m^2]", "Izz [kg m^2]")
    if not all(k in p for k in keys):
        return None
    xx, xy, yy, xz, yz, zz = (float(p[k]) for k in keys)
    I_o = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    c = np.asarray(mc, float) / m
    I_c = I_o - m * (c @ c * np.eye(3) - np.outer(c, c))
    ev = np.linalg.eigvalsh(I_c)
    tol = 1e-9 * max(float(np.max(np.abs(ev))), 1e-12)
    if ev[0] < -tol or ev[2] > ev[0] + ev[1] + tol:
        return ("rotational inertia about its centre of mass with principal moments "
                + ", ".join(f"{v:.3g}" for v in ev) + " kg m^2 (no rigid body has these)")
    return None


def payload_line(pl: dict) -> str:
    if pl.get("nonphysical"):
        return (f"payload fitted on {pl['side']} is non-physical: {pl['nonphysical']}; it is not a load the "
                "robot carries (the payload columns stand in for another model error)")
    c = 1e3 * np.asarray(pl["com_m"])
    return (f"payload {pl['mass_kg']:.3f} kg, centre of mass at ({c[0]:.1f}, {c[1]:.1f}, {c[2]:.1f}) mm "
            f"in the {pl['frame']}, fitted on {pl['side']}")


def _group_label(side: str, key: str) -> str:
    """The effect a parameter group belongs to, in the candidates' ``effect@where`` form (the
    frequency side keys its springs by joint, ``<joint>_orth`` and ``<link>_bend``)."""
    if side != "linear" or "@" in key or key == PAYLOAD:
        return key
    for suffix, effect in (("_orth_coupling", "coupling of orthogonal_compliance"), ("_bend_coupling", "coupling of link_flexibility"),
                           ("_orth", ORTHOGONAL_COMPLIANCE), ("_bend", LINK_FLEXIBILITY)):
        if key.endswith(suffix):
            return f"{effect}@{key[: -len(suffix)]}"
    return f"joint_flexibility@{key}"


def why_selected(i: int, s: dict, ranking: list) -> str:
    """One sentence: why step ``i`` (0-based) added effect ``s``."""
    rank = next((k + 1 for k, r in enumerate(ranking) if where_label(r) == where_label(s)), None)
    first = i == 0
    rule = (f"at least {MIN_STEP_SHRINK:.0f} % of the excess left before it"
            + (f", and the first effect at least {MIN_NAMED_SHRINK:.0f} % of the nominal excess" if first else ""))
    where = (f"ranked {rank} of {len(ranking)} when each candidate was added alone to the nominal model"
             if rank is not None else
             "not among the candidates refitted in the first round: after the effects before it were added, the "
             "residual was ranked again by signature and it came first")
    if not first and rank is not None and rank > 1:
        where += ("; alone it closed little because a larger effect masked it, so its turn came once that "
                  "effect was in the model")
    return (f"It closed {s.get('step_shrink', s['shrink']):.0f} % of the excess left before it (rule: {rule}) and its "
            f"score is {s['score']:.1f} (it pays for its parameters on held-out data); {where}.")


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1200px;margin:1.5em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{font-size:1.6em;margin-bottom:.2em} h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.8em}
table{border-collapse:collapse;margin:.6em 0;font-size:.92em} th,td{border:1px solid #ccc;padding:.25em .55em;
text-align:left;vertical-align:top} th{background:#f3f3f3} td.n{text-align:right}
figure{margin:1em 0} img{max-width:100%;border:1px solid #ddd} figcaption{font-size:.9em;color:#444;max-width:1000px}
.verdict{font-size:1.15em;padding:.6em .8em;background:#f5f8ff;border-left:4px solid #3b6fd8}
.tag{font-size:.8em;padding:0 .35em;border-radius:3px;background:#eee;color:#555}
.tag.nominal{background:#e4eefc;color:#234} .tag.added{background:#e5f5e5;color:#1d5a1d}
dl dt{font-weight:600} dl dd{margin:0 0 .5em 1.2em}
"""


def page(r: dict, out: pathlib.Path, figures: list[dict], *, robot_name: str, nominal_effects, payload,
         modal_tables: dict, set_gaps: dict) -> str:
    """The HTML page. ``figures``: dicts ``file``, ``caption``, ``section`` (a key of
    :data:`SECTIONS`) and ``dataset`` (or None); ``modal_tables``: dataset -> rows of
    (mode, measured f, zeta, nominal f, final f); ``set_gaps``: dataset -> (kind, nominal, final, floor, source)."""
    H = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>Gap diagnosis: {_e(robot_name)}</title>"
         f"<style>{_CSS}</style></head><body>",
         f"<h1>Gap diagnosis of {_e(robot_name)}</h1><p>Case <code>{_e(r['case'])}</code>; "
         f"diagnosis took {r['seconds']:.1f} s. Terms are defined at the <a href='#terms'>end of the page</a>.</p>"]
    _page_summary(H, r, payload)
    _page_selected(H, r)
    _page_model(H, r, nominal_effects, payload)
    _page_datasets(H, r, out, figures, modal_tables, set_gaps)
    _page_where(H, r, out, figures)
    _page_ranking(H, r, out, figures)
    _sec(H, "terms")
    H.append("<dl>" + "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in TERMS) + "</dl>")
    H.append("</body></html>")
    return "\n".join(H)


def _sec(H: list, key: str) -> None:
    H.append(f"<h2 id='{key}'>{_e(SECTIONS[key])}</h2>")


def _figs(H: list, out: pathlib.Path, figures: list[dict], section: str, dataset=None) -> None:
    for f in figures:
        if f["section"] == section and f.get("dataset") == dataset:
            H.append(_figure(out, f))


def _page_summary(H: list, r: dict, payload) -> None:
    """The verdict, the gap and its floor, the data left out, the candidates never named."""
    _sec(H, "summary")
    v = r.get("verdict", "")
    H.append(f"<p class='verdict'><b>{_e(v.replace('_', ' '))}</b>: {_e(VERDICTS.get(v, ''))}. "
             f"The search stopped because {_e(r.get('stop_reason', ''))}.</p>")
    H.append(f"<p>{_e(floor_sentence(r))}</p>")
    H.append(f"<p>Validation gap <b>{r['gap_before']:.2f} %</b> with the nominal model, <b>{r['gap_after']:.2f} %</b> "
             f"with the final one; noise floor {r['noise_floor']:.2f} %. The nominal gap is "
             f"{significance_words(r['significant'])}; the selected effects closed <b>{r['shrink']:.0f} %</b> "
             f"of its excess over the noise, and what remains is {'still' if r['remaining_significant'] else 'not'} "
             "significant.</p>")
    if payload:
        H.append(f"<p><b>{_e(payload_line(payload)).capitalize()}.</b></p>")
    notes, ctab = data_notes(r), conditioning_table(r)
    if notes or ctab:
        _sec(H, "data")
        if ctab:
            H.append(_table(CONDITIONING_HEAD, [[_e(c) for c in row] for row in ctab]))
        if notes:
            H.append("<ul>" + "".join(f"<li>{_e(x)}</li>" for x in notes) + "</ul>")
    if r.get("vetoed"):
        H.append("<p>Candidates never named: " + "; ".join(
            f"{_e(v['candidate'])} ({_e(v['reason'])})" for v in r["vetoed"][:10]) + ".</p>")


def _page_selected(H: list, r: dict) -> None:
    """The selected effects and the ambiguous pairs."""
    _sec(H, "selected")
    if r["selected"]:
        rows = []
        for i, s in enumerate(r["selected"]):
            rows.append([str(i + 1), _e(where_label(s)), _num(s["gap_after"]), f"{s.get('step_shrink', s['shrink']):.0f}",
                         f"{s['shrink']:.0f}", _num(s["score"], 1), _e(why_selected(i, s, r["ranking"]))])
        H.append(_table(["step", "effect", "gap after [%] (cumulative)", "step shrink [%]", "shrink [%] (cumulative)",
                         "score", "why it was selected"], rows))
    else:
        H.append("<p>No effect was selected: " + _e(r.get("stop_reason", "")) + ".</p>")
    if r.get("ambiguous"):
        for a in r["ambiguous"]:
            H.append(f"<p><b>Ambiguous:</b> {_e(placed(a['effects'][0], a['joints'][0]))} and "
                     f"{_e(placed(a['effects'][1], a['joints'][1]))} close {a['shrink'][0]:.0f} % and {a['shrink'][1]:.0f} % of the excess"
                     f"{' (a known confounded pair)' if a['known_pair'] else ''}: more data sets or postures are needed "
                     "to tell them apart.</p>")


def _page_model(H: list, r: dict, nominal_effects, payload) -> None:
    """The nominal and final models' parameters and the inertial refit."""
    _sec(H, "model")
    listed = ", ".join(f"{n['effect']} ({', '.join(n.get('joints') or ()) or 'all joints'})" for n in nominal_effects)
    H.append("<p>Effects marked <span class='tag nominal'>nominal</span> are part of the nominal model: case.yaml's "
             f"<code>nominal_effects</code> ({_e(listed or 'none')}) and, on FRF/modal data, the joint springs. They "
             "are refitted on the training data and never candidates. Effects marked <span class='tag added'>added</span> "
             "were selected by the diagnosis.</p>")
    rows = []
    nominal_p, final_p = r.get("nominal_parameters", {}), r.get("parameters", {})
    for side in sorted(set(nominal_p) | set(final_p)):
        groups = list(dict.fromkeys(list(nominal_p.get(side, {})) + list(final_p.get(side, {}))))
        for g in groups:
            # what the nominal model already holds is nominal (case.yaml's nominal_effects, the joint springs
            # of the frequency side); everything else the diagnosis added
            tag = ("<span class='tag nominal'>nominal</span>" if g in nominal_p.get(side, {})
                   else "<span class='tag added'>added</span>")
            before, after = nominal_p.get(side, {}).get(g, {}), final_p.get(side, {}).get(g, {})
            if g == PAYLOAD and payload:
                rows.append([f"{_e(g)} {tag}", "mass, centre of mass", "-", _e(payload_line(payload))])
                continue
            for k in dict.fromkeys(list(before) + list(after)):
                rows.append([f"{_e(_group_label(side, g))} {tag}", _e(k), _num(before.get(k), 4) if k in before else "-",
                             _num(after.get(k), 4) if k in after else "-"])
    if rows:
        H.append(_table(["effect", "parameter", "nominal model", "final model"], rows))
    moves = r.get("inertia_refit") or []
    if moves:
        H.append("<p>The nominal inertias were refitted on the training data, pulled toward CAD within its tolerance: "
                 f"{_e(r.get('inertia', ''))}. A link at its tolerance bound moved further than a CAD error does: "
                 "a payload or a wrong part is the first place to look.</p>")
        H.append(_table(["link", "mass CAD [kg]", "mass fitted [kg]", "change [%]", "COM shift [mm]", "at tolerance bound"],
                        [[_e(m["link"]), _num(m["mass_cad_kg"], 3), _num(m["mass_kg"], 3),
                          "-" if m["mass_change_pct"] is None else f"{m['mass_change_pct']:+.1f}",
                          _num(1e3 * m["com_shift_m"], 1), _e(bound_words(m))] for m in moves]))


def _page_datasets(H: list, r: dict, out: pathlib.Path, figures: list[dict], modal_tables: dict, set_gaps: dict) -> None:
    """Each validation set's gaps, modal table and figures, then the waterfall of the gap."""
    _sec(H, "datasets")
    for name, (kind, g0, g1, fl, src) in set_gaps.items():
        H.append(f"<h3>{_e(name)} ({_e(kind)})</h3><p>gap {g0:.2f} % nominal, {g1:.2f} % final; noise floor "
                 f"{fl:.2f} % ({_e(src or 'estimated')}).</p>")
        if name in modal_tables:
            H.append(_table(["mode", "measured f [Hz]", "measured zeta", "nominal f [Hz]", "nominal error [%]",
                             "final f [Hz]", "final error [%]"], modal_tables[name]))
            H.append("<p>Each measured mode is matched one-to-one to the nearest model mode in relative frequency; a "
                     "measured mode with no model mode within 10 % is one the model lacks.</p>")
        _figs(H, out, figures, "datasets", name)

    _sec(H, "waterfall")
    _figs(H, out, figures, "waterfall")
    H.append(_table(["step", "validation gap [%]", "excess over noise [%]"],
                    [[_e(s["added"] or "nominal"), _num(s["gap"]), _num(s["excess"])] for s in r["steps"]]))


def _page_where(H: list, r: dict, out: pathlib.Path, figures: list[dict]) -> None:
    """Where the nominal model's validation error lies."""
    _sec(H, "where")
    wh = r.get("where", [])[:20]
    cols = [("data set", "dataset"), ("channel", "channel"), ("window [s]", "window_s"), ("band [Hz]", "band_hz"),
            ("posture", "posture")]
    cols = [c for c in cols if any(w.get(c[1]) is not None for w in wh)]  # only the columns some row fills
    if wh:
        H.append("<p>The nominal model's validation error cut into pieces (per channel, time window, frequency band or "
                 "posture), largest first: where to look before any effect is added.</p>")
        H.append(_table([c[0] for c in cols] + ["NRMSE [%]"], [[_where_cell(w, c[1], cols) for c in cols] + [_num(w["nrmse"])] for w in wh]))
    _figs(H, out, figures, "where")


def _where_cell(w, key, cols):
    """One cell of the table of where the gap lies (``cols``: the columns shown, (title, key))."""
    x = w.get(key)
    if x is None:
        # a row that cuts nothing finer than its channel is the whole record
        whole = key == cols[2][1] if len(cols) > 2 else False
        return "whole set" if whole and all(w.get(k) is None for k in ("window_s", "band_hz", "posture")) else ""
    if key == "window_s":
        return "%.1f-%.1f" % tuple(x)
    if key == "band_hz":
        return "%.2f-%.2f" % tuple(x)
    if key == "posture" and isinstance(x, dict):
        if "variable" in x:
            return f"correlates with {_e(x['variable'])} ({x['corr']:.2f})"
        return _e(", ".join(f"{k}={v:.0f}" for k, v in x["q_deg"].items()) + " deg")
    return _e(x)


def _page_ranking(H: list, r: dict, out: pathlib.Path, figures: list[dict]) -> None:
    """The candidates ranked alone, and the other figures."""
    _sec(H, "ranking")
    H.append("<p>Each candidate added alone to the nominal model, refitted on the training data and scored on the "
             "validation data, best first (by shrink, then score). Candidates are chosen for refitting by their "
             "signature; the selection then adds effects one at a time (see above).</p>")
    sel = {where_label(s) for s in r["selected"]}
    rows = []
    for i, s in enumerate(r["ranking"][:15]):
        sg = s.get("signature")
        why = vetoed(s)
        rows.append([str(i + 1), _e(where_label(s)) + (" <span class='tag added'>selected</span>" if where_label(s) in sel else "")
                     + (f" <span class='tag'>never named: {_e(why)}</span>" if why else ""),
                     _num(s["gap_after"]), f"{s['shrink']:.0f}", _num(s["score"], 1),
                     "" if sg is None else f"{_e(sg['name'])}: {sg['value']:.2f}"])
    H.append(_table(["#", "effect", "gap after [%]", "shrink [%]", "score", "signature"], rows))
    _figs(H, out, figures, "other")
