"""diagnosis.json, report.md, report.html and the plots of one diagnosis run."""

from __future__ import annotations

import pathlib

import numpy as np

from ..._runs import write_results
from . import _figures as FG
from . import _html
from ..judge._selection import vetoed
from ...effects._registry import PAYLOAD


def robot_name(case) -> str:
    """The diagnosed robot's name: the robot YAML's ``name``, a URDF's ``<robot name>``, else the
    robot entry of case.yaml (a config name such as ``panda``, or the file's stem)."""
    import re

    from ..._config import load_yaml

    try:
        spec = load_yaml(case.path)["robot"]
        spec = str(spec["file"] if isinstance(spec, dict) else spec)  # a reduced robot: {file, joints, lock}
    except Exception:  # a name is a courtesy: never lose the report over it
        return "the robot"
    f = pathlib.Path(spec) if pathlib.Path(spec).is_absolute() else case.path.parent / spec
    try:
        if f.suffix in (".yaml", ".yml") and f.is_file():
            return str(load_yaml(f).get("name") or f.stem)
        if f.suffix == ".urdf" and f.is_file():
            m = re.search(r"<robot[^>]*\sname\s*=\s*[\"']([^\"']+)", f.read_text(errors="replace"))
            return m.group(1) if m else f.stem
    except Exception:
        return f.stem
    return pathlib.Path(spec).stem


def _fig(files, name, caption, section="other", dataset=None):
    files.append(dict(file=name, caption=caption, section=section, dataset=dataset))


def _plots(diag, out: pathlib.Path, robot: str) -> list[dict]:
    """Every figure of the report: dicts ``file``, ``caption``, ``section``, ``dataset``; drawn from
    the diagnosis' stored series (:class:`jflex.gap._result.ReportSeries`: the nominal and final
    models' evaluations on the validation sets, the sets themselves)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    S, r = diag.series, diag.result
    ev0, evf = S.nominal, S.final
    files = []
    # measured vs nominal vs final, per validation set
    for s in S.torque:
        if s.name in ev0 and s.name in evf:
            taus = [s.tau + ev[s.name]["resid"] * s.scale for ev in (ev0, evf)]
            name, cap = FG.torque_traces(plt, out, robot, s, S.names, *taus, (ev0[s.name]["nrmse"], evf[s.name]["nrmse"]))
            _fig(files, name, cap, "datasets", s.name)
    for d in S.frequency:
        if d.kind == "frf" and d.name in ev0 and d.name in evf:
            name, cap = FG.frf_bode(plt, out, robot, d, ev0[d.name]["Hm"], evf[d.name]["Hm"],
                                    (ev0[d.name]["nrmse"], evf[d.name]["nrmse"]))
            _fig(files, name, cap, "datasets", d.name)
    # residual heat map over time x channel (first torque validation set)
    tv = [k for k, v in ev0.items() if v["kind"] == "torque"]
    if tv:
        s = next(s for s in S.torque if s.name == tv[0])
        e = ev0[tv[0]]["resid"]
        nw = 40
        edges = np.linspace(0, len(s.t), nw + 1).astype(int)
        Z = np.array([[np.sqrt(np.mean(e[a:b, j] ** 2)) * 100 for a, b in zip(edges[:-1], edges[1:])] for j in range(S.n)])
        fig, ax = plt.subplots(figsize=(8, 2 + 0.4 * S.n))
        im = ax.imshow(Z, aspect="auto", origin="lower", extent=[s.t[0], s.t[-1], -0.5, S.n - 0.5], cmap="magma")
        ax.set_yticks(range(S.n), S.names)
        ax.set_xlabel("time [s]")
        ax.set_title(f"{robot}: nominal model's torque error over time, set '{tv[0]}'")
        fig.colorbar(im, ax=ax, label="windowed NRMSE [%]")
        fig.tight_layout()
        fig.savefig(out / "heat_time_channel.png", dpi=110)
        plt.close(fig)
        _fig(files, "heat_time_channel.png", f"The nominal model's torque error on the validation set '{tv[0]}' per joint "
             "(rows) and time window (columns): the RMS error in the window over the joint's torque variation [%]. "
             "A bright row is a joint the model misses; a bright column a part of the motion.", "where")
    # frequency x posture heat map (FRF band errors) and FRF overlays
    fr = [d for d in S.frequency if d.kind == "frf"]
    md = [d for d in S.frequency if d.kind == "modal"]
    if fr:
        bands = np.geomspace(fr[0].arrays["freq"][0], fr[0].arrays["freq"][-1] * 1.0001, 25)
        Z = []
        for d in fr:
            a = d.arrays
            err = ev0[d.name]["err"]
            tot = np.sqrt(np.mean(np.abs(a["H"]) ** 2))
            Z.append([np.sqrt(np.mean(np.abs(err[(a["freq"] >= lo) & (a["freq"] < hi)]) ** 2)) / tot * 100
                      if np.any((a["freq"] >= lo) & (a["freq"] < hi)) else np.nan for lo, hi in zip(bands[:-1], bands[1:])])
        fig, ax = plt.subplots(figsize=(8, 1.5 + 0.5 * len(fr)))
        im = ax.pcolormesh(bands, np.arange(len(fr) + 1) - 0.5, np.array(Z), cmap="magma")
        ax.set_xscale("log")
        ax.set_yticks(range(len(fr)), [d.name for d in fr])
        ax.set_xlabel("frequency [Hz]")
        ax.set_title(f"{robot}: nominal model's FRF error per frequency band and posture")
        fig.colorbar(im, ax=ax, label="RMS error / RMS |H| [%]")
        fig.tight_layout()
        fig.savefig(out / "heat_freq_posture.png", dpi=110)
        plt.close(fig)
        _fig(files, "heat_freq_posture.png", "The nominal model's FRF error per frequency band (columns, log-spaced) "
             "and validation FRF set (rows, one per posture): the RMS error in the band over the set's RMS |H| [%]. "
             "A bright column is a resonance the model places wrong at every posture; a bright cell one posture.", "where")
    if md:
        K = max(len(d.arrays["freq"]) for d in md)
        Z = np.full((len(md), K), np.nan)
        for i, d in enumerate(md):
            ef = ev0[d.name]["ef"]
            Z[i, : len(ef)] = np.abs(ef) * 100
        fig, ax = plt.subplots(figsize=(6, 1.5 + 0.5 * len(md)))
        im = ax.imshow(Z, aspect="auto", origin="lower", cmap="magma")
        ax.set_yticks(range(len(md)), [d.name for d in md])
        ax.set_xticks(range(K), [f"mode {k + 1}" for k in range(K)])
        ax.set_title(f"{robot}: nominal model's natural-frequency error per mode and posture")
        fig.colorbar(im, ax=ax, label="|f_model - f_measured| / f_measured [%]")
        fig.tight_layout()
        fig.savefig(out / "heat_mode_posture.png", dpi=110)
        plt.close(fig)
        _fig(files, "heat_mode_posture.png", "The nominal model's relative natural-frequency error per measured mode "
             "(columns) and validation modal set (rows, one per posture) [%]; each measured mode is matched to the "
             "nearest model mode.", "where")
    for name, cap, dataset in _response_plots(diag, out, plt, robot):
        _fig(files, name, cap, "datasets", dataset)
    name, cap = FG.waterfall(plt, out, robot, r["steps"], r["noise_floor"])
    _fig(files, name, cap, "waterfall")
    return files


def _response_plots(diag, out: pathlib.Path, plt, robot: str) -> list[tuple[str, str, str]]:
    """One figure per output-error (tip) set: measured, nominal and final simulated channels over
    time (left) and both residuals (right), one row per channel (the simulations the diagnosis stored)."""
    from ..response import _response as R

    files = []
    for s in diag.series.responses:
        preds = [("nominal", s.nominal), ("final", s.final)]
        k = len(s.channels)
        fig, axs = plt.subplots(k, 2, figsize=(11, 2.2 * k + 0.6), squeeze=False, sharex=True)
        for i, ch in enumerate(s.channels):
            unit = "m" if ch in R.TIP_CHANNELS else "rad"
            ax, ax2 = axs[i]
            ax.plot(s.t, s.y[:, i], "k", lw=1.2, label="measured")
            for (lab, y), st in zip(preds, ("C0--", "C3")):
                ax.plot(s.t, y[:, i], st, lw=1.0, label=lab)
                ax2.plot(s.t, y[:, i] - s.y[:, i], st, lw=1.0, label=f"{lab} - measured")
            ax.set_ylabel(f"{ch} [{unit}]")
            ax2.set_ylabel(f"residual [{unit}]")
            ax2.axhline(0.0, color="k", lw=0.5)
            if i == 0:
                ax.legend(fontsize=8)
                ax2.legend(fontsize=8)
        axs[-1, 0].set_xlabel("time [s]")
        axs[-1, 1].set_xlabel("time [s]")
        fig.suptitle(f"{robot}: response set '{s.name}', simulated from rest at q0 under the recorded torques")
        fig.tight_layout()
        name = f"response_{FG.safe_name(s.name)}.png"
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        files.append((name, f"The response set '{s.name}' (output error): the model simulated from rest at the set's "
                      "q0 under its recorded torques, measured (black), nominal (blue, dashed) and final (red) per "
                      "channel (left) and each model's residual (right).", s.name))
    return files


def _fmt(x, nd=2):
    return "-" if x is None else (f"{x:.{nd}f}" if isinstance(x, float) else str(x))


def markdown(r: dict, plots, *, robot: str | None = None, payload: dict | None = None, prismatic=()) -> str:
    """report.md: the summary, the selected effects and their rivals, the candidates ranked alone,
    where the gap lies, the fitted parameters and the plots (file names ``plots``)."""
    L = _md_summary(r, robot, payload) + _md_selected(r) + _md_ranking(r) + _md_model(r, plots, payload, prismatic)
    L += ["", "## Plots", ""] + [f"![{p}]({p})" for p in plots]
    L.append(f"\n_Diagnosis took {r['seconds']:.1f} s._")
    return "\n".join(L) + "\n"


def _md_summary(r: dict, robot, payload) -> list[str]:
    """The gap, the noise floor, the data left out, the verdict and the inertial refit."""
    L = [f"# Gap diagnosis{' of ' + robot if robot else ''}: {r['case']}", "",
         "The same report with its figures and the terms explained: [report.html](report.html).", ""]
    L.append(f"**Validation gap:** {r['gap_before']:.2f} % NRMSE before, {r['gap_after']:.2f} % after; noise floor "
             f"{r['noise_floor']:.2f} %. The nominal gap is **{_html.significance_words(r['significant'])}**; the excess "
             f"over noise closed: **{r['shrink']:.0f} %**; what remains is {'still' if r['remaining_significant'] else 'not'} "
             "significant.")
    L.append("")
    fs = _html.floor_sentence(r)
    if fs:
        L += [fs, ""]
    notes, ctab = _html.data_notes(r), _html.conditioning_table(r)
    if notes or ctab:
        L += ["## The data: channels left out and conditioning", ""]
        if ctab:
            L += ["| " + " | ".join(_html.CONDITIONING_HEAD) + " |", "|" + "---|" * len(_html.CONDITIONING_HEAD)]
            L += ["| " + " | ".join(str(c).replace("|", "/") for c in row) + " |" for row in ctab] + [""]
        L += [f"- {x}" for x in notes] + ([""] if notes else [])
    verdict = r.get("verdict")
    if verdict:
        L.append(f"**Verdict: {verdict.replace('_', ' ')}.** {r.get('stop_reason', '')}.")
        L.append("")
    moves = r.get("inertia_refit") or []
    if moves:
        L += ["## Nominal identification: how far the CAD inertias moved", "",
              "The nominal model's inertial parameters were refitted on the training data (torque data with the nominal "
              "friction, else FRF/modal data with the nominal springs), pulled toward CAD and kept within its tolerance. A link that reached the tolerance bound "
              "moved further than a CAD error does (a payload, a wrong part): the first place to look.", "",
              "| link | mass CAD [kg] | mass fitted [kg] | change [%] | COM shift [mm] | at tolerance bound |",
              "|---|---|---|---|---|---|"]
        for m in moves:
            ch = "-" if m["mass_change_pct"] is None else f"{m['mass_change_pct']:+.1f}"
            L.append(f"| {m['link']} | {m['mass_cad_kg']:.3f} | {m['mass_kg']:.3f} | {ch} | {1e3 * m['com_shift_m']:.1f} | "
                     f"{_html.bound_words(m)} |")
        L.append("")
    if payload:
        L += [f"**{_html.payload_line(payload).capitalize()}.**", ""]
    return L


def _md_selected(r: dict) -> list[str]:
    """The selected effects, those confounded with the inertial refit, ambiguous pairs and rivals."""
    L = []
    L.append("## Selected effects (in order added)")
    if r["selected"]:
        L += ["| effect | joint / link | gap after [%] | shrink [%] | score |", "|---|---|---|---|---|"]
        for s in r["selected"]:
            L.append(f"| {s['effect']} | {s['joint'] or s.get('link') or '-'} | {s['gap_after']:.2f} | {s['shrink']:.0f} | {s['score']:.1f} |")
    else:
        L.append("None: " + ("the gap is within the noise floor." if not r["significant"] else "no candidate closed enough of the gap on held-out data."))
    if r.get("confounded_with_inertia_refit"):
        L += ["", "## Confounded with the inertial refit", "",
              "On these motions these candidates are the same torques as a change of the links' inertial "
              "parameters (their columns lie in the span of the refitted ones: a rotor's inertia regroups with "
              "its link's, a payload is the last link's). The refit holds them as far as the CAD tolerance lets it, "
              "and only what lies beyond that tolerance can be named; holding the inertias fixed "
              "(`options.refit_inertia: false`, when the CAD is trusted) gives the data to the candidates:", ""]
        L += [f"- {h['effect']}" + (f" at {h['joint']}" if h["joint"] else "") for h in r["confounded_with_inertia_refit"]]
        both = [h for h in r["confounded_with_inertia_refit"]
                if any(s["effect"] == h["effect"] and s.get("joint") == h["joint"] for s in r["selected"])]
        for h in both:
            at = f" at {h['joint']}" if h["joint"] else ""
            L += ["", f"{h['effect'].capitalize()}{at} is both confounded with the refit and selected: the refit "
                  f"absorbed the part of it the CAD tolerance allows (a few per cent of each link's mass), and the "
                  f"selection named {h['effect']}{at} for what lay beyond that tolerance; its fitted value is that "
                  "excess over the refitted inertias, not the whole effect."]
    if r["ambiguous"]:
        L += ["", "## Ambiguous", ""]
        for a in r["ambiguous"]:
            L.append(f"- {_html.placed(a['effects'][0], a['joints'][0])} vs {_html.placed(a['effects'][1], a['joints'][1])}: shrink "
                     f"{a['shrink'][0]:.0f} % vs {a['shrink'][1]:.0f} %{' (a known confounded pair)' if a['known_pair'] else ''}; "
                     "more data sets or postures are needed to separate them.")
    if r.get("swapped"):
        L += ["", "## Rivals tried beside the other effects", "",
              "Alone, these effects closed nearly the same share; with the other selected effects in the model, "
              "the second closed what the first left:", ""]
        L += [f"- {w['by']} in place of {w['replaced']}: excess over noise {w['excess_before']:.2f} -> "
              f"{w['excess_after']:.2f} %" for w in r["swapped"]]
    return L


def _md_ranking(r: dict) -> list[str]:
    """The candidates ranked alone, where the gap lies and the gap as effects are added."""
    L = []
    L += ["", "## Candidate ranking (each added alone to the nominal model)", "",
          "| # | effect | joint / link | gap after [%] | shrink [%] | score | signature |", "|---|---|---|---|---|---|---|"]
    for i, s in enumerate(r["ranking"][:15]):
        sg = s.get("signature")
        sgt = "" if sg is None else "%s (%.2f)" % (sg["name"], sg["value"])
        why = vetoed(s)
        L.append(f"| {i + 1} | {s['effect']}{' (never named: ' + why + ')' if why else ''} | "
                 f"{s['joint'] or s.get('link') or '-'} | {s['gap_after']:.2f} | {s['shrink']:.0f} | "
                 f"{s['score']:.1f} | {sgt} |")
    if r.get("vetoed"):
        L += ["", "Candidates never named: " + "; ".join(f"{v['candidate']} ({v['reason']})" for v in r["vetoed"][:10]) + "."]
    L += ["", "## Where the gap lies (validation data, largest first)", "",
          "| data set | channel | window [s] | band [Hz] | posture | NRMSE [%] |", "|---|---|---|---|---|---|"]
    for w in r["where"][:20]:
        pos = w.get("posture")
        if isinstance(pos, dict) and "variable" in pos:
            pos = f"corr with {pos['variable']}: {pos['corr']:.2f}"
        elif isinstance(pos, dict):
            pos = ", ".join(f"{k}={v:.0f}" for k, v in pos["q_deg"].items()) + " deg"
        win = w.get("window_s")
        band = w.get("band_hz")
        wt = "" if win is None else "%.1f-%.1f" % tuple(win)
        bt = "" if band is None else "%.2f-%.2f" % tuple(band)
        L.append(f"| {w['dataset']} | {w['channel']} | {wt} | {bt} | {pos or ''} | {w['nrmse']:.2f} |")
    if r["unmatched_modes"]:
        L += ["", "**Measured modes no model mode matches (>10 % off):** " +
              ", ".join(f"{w['channel']} in {w['dataset']}" for w in r["unmatched_modes"])]
    L += ["", "## Gap as effects are added", "", "| step | validation gap [%] | excess over noise [%] |", "|---|---|---|"]
    for s in r["steps"]:
        L.append(f"| {s['added'] or 'nominal'} | {s['gap']:.2f} | {s['excess']:.2f} |")
    return L


def _md_model(r: dict, plots, payload, prismatic) -> list[str]:
    """The final model's parameters, the output-error sets and failed simulations."""
    L = []
    L += ["", "## Fitted parameters of the final model", "", "```",
          _params(prismatic_units(_without_payload(r["parameters"], payload), set(prismatic))), "```", ""]
    if payload:
        # the payload once, as the summary gives it (mass, centre of mass in the tool frame, units)
        L += [f"Payload: {_html.payload_line(payload)}.", ""]
    if r.get("responses_output_error"):
        L.append(f"Response data sets {r['responses_output_error']} were compared as output error: the model simulated "
                 "under their applied torques from rest at their q0 (the torque-side terms and the joint springs with "
                 "the rotor inertia on their motor side, with a fitted play inside a spring's transmission; sensor delay, "
                 "the torque side's backlash and the orthogonal and link compliances are not simulated).")
        tips = [p for p in plots if p.startswith("response_")]
        if tips:
            L.append("Measured vs nominal vs final traces and residuals: " + ", ".join(f"[{p}]({p})" for p in tips) + ".")
    if r.get("failed_solves"):
        L += ["", "**Failed or diverged simulations** (their samples count at a 1000 % error):", "",
              "| model | data set | samples | of |", "|---|---|---|---|"]
        for f in r["failed_solves"][:20]:
            L.append(f"| {f['model']} | {f['dataset']} | {f['samples']} | {f['of']} |")
        if len(r["failed_solves"]) > 20:
            L.append(f"| ... {len(r['failed_solves']) - 20} more in diagnosis.json | | | |")
    if r["responses_not_modelled"]:
        L.append(f"Response data sets {r['responses_not_modelled']} were not used: they lack a channel for some model "
                 "joint and lie in the train split, and no validation set of that kind judges what they would fit.")
    if r.get("responses_fitted") and r.get("simulated_refit"):
        L.append(f"Response training sets {r['responses_fitted']} fitted the joint springs through the simulation (a flexible "
                 "joint is screened at every joint by simulation, a selected one identified by output error): validation gap "
                 + ", ".join(f"{j} {v['gap_screened']:.2f} % screened, {v['gap_identified']:.2f} % identified"
                             for j, v in r["simulated_refit"].items()) + ".")
    return L


def _without_payload(params: dict, payload) -> dict:
    if not payload:
        return params
    return {side: {k: v for k, v in grp.items() if k != PAYLOAD} if isinstance(grp, dict) else grp
            for side, grp in params.items()}


# a prismatic joint's generalized force is a force and its coordinate a length: the torque-side
# units the effects state per joint (N m, per rad) read N and per m there
_LINEAR_UNITS = (("[N m s/rad]", "[N s/m]"), ("[N m/rad]", "[N/m]"), ("[N m]", "[N]"), ("[kg m^2]", "[kg]"))


def prismatic_units(p, prismatic) -> dict:
    """The parameters dict ``p`` with the units of the effects placed at a ``prismatic`` joint (a
    key ``effect@joint``) in N, N/m, N s/m, kg."""
    out = {}
    for k, v in p.items():
        at = str(k).rsplit("@", 1)[-1] if "@" in str(k) else None
        if isinstance(v, dict) and at is not None and at in prismatic:
            v = {_linear_unit(a): b for a, b in v.items()}
        elif isinstance(v, dict):
            v = prismatic_units(v, prismatic)
        out[k] = v
    return out


def _linear_unit(key):
    key = str(key)
    for a, b in _LINEAR_UNITS:
        key = key.replace(a, b)
    return key


def _params(p, ind=0):
    out = []
    for k, v in p.items():
        if isinstance(v, dict):
            out.append(" " * ind + f"{k}:")
            out.append(_params(v, ind + 2))
        else:
            out.append(" " * ind + f"{k}: {v:.6g}" if isinstance(v, float) else " " * ind + f"{k}: {v}")
    return "\n".join(out)


def _modal_tables(frequency_sets, ev0, evf) -> dict:
    """Per modal validation set: rows (mode, measured f, zeta, nominal f, error, final f, error)."""
    out = {}
    for d in frequency_sets:
        if d.kind != "modal" or d.name not in ev0 or d.name not in evf:
            continue
        a = d.arrays
        rows = []
        for k, (f, z) in enumerate(zip(a["freq"], a["zeta"])):
            row = [str(k + 1), f"{f:.2f}", "-" if not np.isfinite(z) else f"{z:.4f}"]
            for ev in (ev0, evf):
                e = ev[d.name]
                i = int(e["idx"][k]) if len(e["f_model"]) else -1
                row += ["-", "-"] if i < 0 else [f"{e['f_model'][i]:.2f}", f"{100 * e['ef'][k]:+.1f}"]
            rows.append(row)
        out[d.name] = rows
    return out


def write_report(diag, out_dir) -> pathlib.Path:
    """Write ``diagnosis.json``, ``report.md``, the self-contained ``report.html`` and the plots into
    ``out_dir``; returns the path of report.md. Reads the stored diagnosis only (its result, its
    case and the series it kept for the figures): no model is evaluated here."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    r, case, S = diag.result, diag.loaded, diag.series
    write_results(out, r, "diagnosis.json")
    robot = robot_name(case)
    payload = _html.payload_summary(r.get("parameters", {}), case.robot, case.tool_frame)
    ev0, evf = S.nominal, S.final
    try:
        if S.error is not None:
            raise _StoredError(S.error)
        figures = _plots(diag, out, robot)
    except Exception as exc:  # a plot must never lose the diagnosis itself
        figures = []
        r["plot_error"] = str(exc) if isinstance(exc, _StoredError) else f"{type(exc).__name__}: {exc}"
        write_results(out, r, "diagnosis.json")
    path = out / "report.md"
    prismatic = [j for j, k in zip(case.robot.joint_names, case.robot.joint_types) if k == "prismatic"]
    path.write_text(markdown(r, [f["file"] for f in figures], robot=robot, payload=payload, prismatic=prismatic))
    set_gaps = {}
    if ev0 is not None:
        for k in ev0:
            if k in evf:
                set_gaps[k] = (ev0[k]["kind"], ev0[k]["nrmse"], evf[k]["nrmse"], r["noise_floor_per_dataset"].get(k, float("nan")),
                               r.get("noise_floor_source", {}).get(k))
    tables = _modal_tables(S.frequency, ev0, evf) if ev0 is not None else {}
    (out / "report.html").write_text(_html.page(r, out, figures, robot_name=robot, nominal_effects=case.nominal_effects,
                                                payload=payload, modal_tables=tables, set_gaps=set_gaps))
    return path


class _StoredError(Exception):
    """The simulations for the figures failed during the diagnosis (the message it recorded)."""


def add_figures(out_dir, figures, title: str, intro: str = "") -> None:
    """Link figures written after the report (``[(file relative to out_dir, caption)]``) in
    ``report.md`` and embed them in ``report.html``, under the heading ``title``."""
    out = pathlib.Path(out_dir)
    md = out / "report.md"
    if md.is_file():
        lines = ["", f"## {title}", ""] + ([intro, ""] if intro else [])
        lines += [f"![{f}]({f})\n\n{cap}\n" for f, cap in figures]
        md.write_text(md.read_text() + "\n".join(lines) + "\n")
    page = out / "report.html"
    if page.is_file():
        text = page.read_text()
        block = (f"<h2>{_html._e(title)}</h2>" + (f"<p>{_html._e(intro)}</p>" if intro else "")
                 + "".join(_html._figure(out, {"file": f, "caption": cap}) for f, cap in figures))
        end = text.rfind("</body>")
        page.write_text(text[:end] + block + "\n" + text[end:] if end >= 0 else text + block)
