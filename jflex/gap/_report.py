"""diagnosis.json, report.md and the plots of one diagnosis run."""

from __future__ import annotations

import pathlib

import numpy as np

from .._runs import write_results


def _plots(diag, out: pathlib.Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pb, r = diag.problem, diag.result
    files = []
    ev0 = pb.evaluate(diag.nominal)
    evf = pb.evaluate(diag.final)
    # residual heat map over time x channel (first torque validation set)
    tv = [k for k, v in ev0.items() if v["kind"] == "torque"]
    if tv:
        s = next(s for s in pb.tval if s.name == tv[0])
        e = ev0[tv[0]]["resid"]
        nw = 40
        edges = np.linspace(0, len(s.t), nw + 1).astype(int)
        Z = np.array([[np.sqrt(np.mean(e[a:b, j] ** 2)) * 100 for a, b in zip(edges[:-1], edges[1:])] for j in range(pb.n)])
        fig, ax = plt.subplots(figsize=(8, 2 + 0.4 * pb.n))
        im = ax.imshow(Z, aspect="auto", origin="lower", extent=[s.t[0], s.t[-1], -0.5, pb.n - 0.5], cmap="magma")
        ax.set_yticks(range(pb.n), pb.names)
        ax.set_xlabel("time [s]")
        ax.set_title(f"nominal residual, {tv[0]} (windowed NRMSE %)")
        fig.colorbar(im, ax=ax)
        fig.tight_layout()
        fig.savefig(out / "heat_time_channel.png", dpi=110)
        plt.close(fig)
        files.append("heat_time_channel.png")
    # frequency x posture heat map (FRF band errors) and FRF overlays
    fr = [d for d in pb.fval if d.kind == "frf"]
    md = [d for d in pb.fval if d.kind == "modal"]
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
        ax.set_title("nominal FRF error per band and posture [%]")
        fig.colorbar(im, ax=ax)
        fig.tight_layout()
        fig.savefig(out / "heat_freq_posture.png", dpi=110)
        plt.close(fig)
        files.append("heat_freq_posture.png")
        fig, axs = plt.subplots(len(fr), 1, figsize=(8, 3 * len(fr)), squeeze=False)
        for ax, d in zip(axs[:, 0], fr):
            a = d.arrays
            tr = lambda H: np.abs(H).sum(axis=(1, 2))
            ax.loglog(a["freq"], tr(a["H"]), "k", label="measured")
            ax.loglog(a["freq"], tr(ev0[d.name]["Hm"]), "C0--", label="nominal")
            ax.loglog(a["freq"], tr(evf[d.name]["Hm"]), "C3", label="after diagnosis")
            ax.set_title(f"{d.name}: sum of |H_ij| [m/N]")
            ax.set_xlabel("frequency [Hz]")
            ax.legend()
        fig.tight_layout()
        fig.savefig(out / "frf_overlay.png", dpi=110)
        plt.close(fig)
        files.append("frf_overlay.png")
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
        ax.set_title("nominal modal frequency error per mode and posture [%]")
        fig.colorbar(im, ax=ax)
        fig.tight_layout()
        fig.savefig(out / "heat_mode_posture.png", dpi=110)
        plt.close(fig)
        files.append("heat_mode_posture.png")
    files += _response_plots(diag, out, plt)
    # waterfall of the gap as effects are added
    steps = r["steps"]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    labels = ["nominal"] + [s["added"] for s in steps[1:]]
    gaps = [s["gap"] for s in steps]
    for i in range(len(gaps)):
        lo = gaps[i] if i == 0 else min(gaps[i], gaps[i - 1])
        hi = gaps[i] if i == 0 else max(gaps[i], gaps[i - 1])
        ax.bar(i, hi - lo if i else hi, bottom=lo if i else 0, color="C0" if i == 0 else "C2")
    ax.axhline(r["noise_floor"], color="k", ls="--", label="noise floor")
    ax.set_xticks(range(len(labels)), labels, rotation=20, ha="right")
    ax.set_ylabel("validation NRMSE [%]")
    ax.set_title("gap as effects are added")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "waterfall.png", dpi=110)
    plt.close(fig)
    files.append("waterfall.png")
    return files


def _response_plots(diag, out: pathlib.Path, plt) -> list[str]:
    """One figure per output-error (tip) set: measured, nominal and final simulated channels over
    time (left) and both residuals (right), one row per channel."""
    from . import _response as R

    pb = diag.problem
    if not pb.rval:
        return []
    files = []
    models = [("nominal", pb.simulation_model(diag.nominal)), ("final", pb.simulation_model(diag.final))]
    for s in pb.rval:
        preds = [(lab, R.predict(m, s)) for lab, m in models]
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
        fig.suptitle(f"{s.name}: simulated from rest at q0 under the recorded torques")
        fig.tight_layout()
        name = f"response_{''.join(c if c.isalnum() or c in '-_' else '_' for c in s.name)}.png"
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        files.append(name)
    return files


def _fmt(x, nd=2):
    return "-" if x is None else (f"{x:.{nd}f}" if isinstance(x, float) else str(x))


def markdown(r: dict, plots) -> str:
    L = [f"# Gap diagnosis: {r['case']}", ""]
    L.append(f"**Validation gap:** {r['gap_before']:.2f} % NRMSE before, {r['gap_after']:.2f} % after; noise floor "
             f"{r['noise_floor']:.2f} %. Gap significant: **{r['significant']}**; the excess over noise closed: "
             f"**{r['shrink']:.0f} %**; what remains is {'still' if r['remaining_significant'] else 'not'} significant.")
    L.append("")
    verdict = r.get("verdict")
    if verdict:
        L.append(f"**Verdict: {verdict.replace('_', ' ')}.** {r.get('stop_reason', '')}.")
        L.append("")
    moves = r.get("inertia_refit") or []
    if moves:
        L += ["## Nominal identification: how far the CAD inertias moved", "",
              "The nominal model's inertial parameters were refitted on the torque training data (with the nominal "
              "friction), pulled toward CAD and kept within its tolerance. A link that reached the tolerance bound "
              "moved further than a CAD error does (a payload, a wrong part): the first place to look.", "",
              "| link | mass CAD [kg] | mass fitted [kg] | change [%] | COM shift [mm] | at tolerance bound |",
              "|---|---|---|---|---|---|"]
        for m in moves:
            ch = "-" if m["mass_change_pct"] is None else f"{m['mass_change_pct']:+.1f}"
            L.append(f"| {m['link']} | {m['mass_cad_kg']:.3f} | {m['mass_kg']:.3f} | {ch} | {1e3 * m['com_shift_m']:.1f} | "
                     f"{'yes' if m['at_tolerance_bound'] else 'no'} |")
        L.append("")
    L.append("## Selected effects (in order added)")
    if r["selected"]:
        L += ["| effect | joint / link | gap after [%] | shrink [%] | score |", "|---|---|---|---|---|"]
        for s in r["selected"]:
            L.append(f"| {s['effect']} | {s['joint'] or s.get('link') or '-'} | {s['gap_after']:.2f} | {s['shrink']:.0f} | {s['score']:.1f} |")
    else:
        L.append("None: " + ("the gap is within the noise floor." if not r["significant"] else "no candidate closed enough of the gap on held-out data."))
    if r["ambiguous"]:
        L += ["", "## Ambiguous", ""]
        for a in r["ambiguous"]:
            L.append(f"- {a['effects'][0]} ({a['joints'][0]}) vs {a['effects'][1]} ({a['joints'][1]}): shrink "
                     f"{a['shrink'][0]:.0f} % vs {a['shrink'][1]:.0f} %{' (a known confounded pair)' if a['known_pair'] else ''}; "
                     "more data sets or postures are needed to separate them.")
    L += ["", "## Candidate ranking (each added alone to the nominal model)", "",
          "| # | effect | joint / link | gap after [%] | shrink [%] | score | signature |", "|---|---|---|---|---|---|---|"]
    for i, s in enumerate(r["ranking"][:15]):
        sg = s.get("signature")
        sgt = "" if sg is None else "%s (%.2f)" % (sg["name"], sg["value"])
        L.append(f"| {i + 1} | {s['effect']} | {s['joint'] or s.get('link') or '-'} | {s['gap_after']:.2f} | {s['shrink']:.0f} | "
                 f"{s['score']:.1f} | {sgt} |")
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
    L += ["", "## Fitted parameters of the final model", "", "```", _params(r["parameters"]), "```", ""]
    if r.get("responses_output_error"):
        L.append(f"Response data sets {r['responses_output_error']} were compared as output error: the model simulated "
                 "under their applied torques from rest at their q0 (the torque-side terms and the joint springs with "
                 "the rotor inertia on their motor side; sensor delay, backlash and the orthogonal and link "
                 "compliances are not simulated).")
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
        L.append(f"Response data sets {r['responses_not_modelled']} were validated but not used: they lack a channel for "
                 "some model joint and lie in the train split, where output error is not fitted (it is scored on "
                 "validation sets only).")
    L += ["", "## Plots", ""] + [f"![{p}]({p})" for p in plots]
    L.append(f"\n_Diagnosis took {r['seconds']:.1f} s._")
    return "\n".join(L) + "\n"


def _params(p, ind=0):
    out = []
    for k, v in p.items():
        if isinstance(v, dict):
            out.append(" " * ind + f"{k}:")
            out.append(_params(v, ind + 2))
        else:
            out.append(" " * ind + f"{k}: {v:.6g}" if isinstance(v, float) else " " * ind + f"{k}: {v}")
    return "\n".join(out)


def write_report(diag, out_dir) -> pathlib.Path:
    """Write ``diagnosis.json``, ``report.md`` and the plots into ``out_dir``; returns the report path."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_results(out, diag.result, "diagnosis.json")
    try:
        plots = _plots(diag, out)
    except Exception as exc:  # a plot must never lose the diagnosis itself
        plots = []
        diag.result["plot_error"] = f"{type(exc).__name__}: {exc}"
        write_results(out, diag.result, "diagnosis.json")
    path = out / "report.md"
    path.write_text(markdown(diag.result, plots))
    return path
