"""The diagnosis report's comparison figures: measured data against the nominal and the final
model, per validation data set (torque traces, FRF magnitude and phase with coherence, modal
frequencies), and the waterfall of the gap as effects are added. Every title names the robot.

Each function saves one PNG into ``out`` and returns ``(file name, caption)``; the caption says
once what the figure shows and how to read it (the HTML page prints it under the figure).
"""

from __future__ import annotations

import pathlib

import numpy as np

from ..frequency import _model as L

MEASURED, NOMINAL, FINAL = ("k", 1.3, "-"), ("C0", 1.0, "--"), ("C3", 1.0, "-")
DPI = 110


def safe_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def _line(ax, x, y, style, label, **kw):
    c, lw, ls = style
    return ax.plot(x, y, color=c, lw=lw, ls=ls, label=label, **kw)


def torque_traces(plt, out: pathlib.Path, robot: str, s, names, tau_nominal, tau_final, gaps) -> tuple[str, str]:
    """Measured, nominal and final joint torques of one torque set over time (left) and the two
    models' errors (right), one row per joint. ``gaps``: (nominal, final) NRMSE [%] of the set."""
    n = s.tau.shape[1]
    same = bool(np.array_equal(np.asarray(tau_nominal), np.asarray(tau_final)))
    fig, axs = plt.subplots(n, 2, figsize=(12, 1.9 * n + 1.0), squeeze=False, sharex=True)
    for j in range(n):
        ax, ax2 = axs[j]
        _line(ax, s.t, s.tau[:, j], MEASURED, "measured")
        if same:
            # nothing was selected: one model, drawn once (a final curve would hide the nominal one)
            _line(ax, s.t, tau_nominal[:, j], NOMINAL, "nominal = final model (nothing selected)")
            _line(ax2, s.t, tau_nominal[:, j] - s.tau[:, j], NOMINAL, "nominal - measured")
        else:
            _line(ax, s.t, tau_nominal[:, j], NOMINAL, "nominal model")
            _line(ax, s.t, tau_final[:, j], FINAL, "final model")
            _line(ax2, s.t, tau_nominal[:, j] - s.tau[:, j], NOMINAL, "nominal - measured")
            _line(ax2, s.t, tau_final[:, j] - s.tau[:, j], FINAL, "final - measured")
        ax2.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(f"{names[j]}\ntorque [N m]")
        ax2.set_ylabel("error [N m]")
    axs[0, 0].legend(fontsize=8, ncol=3, loc="upper right")
    axs[0, 1].legend(fontsize=8, ncol=2, loc="upper right")
    axs[-1, 0].set_xlabel("time [s]")
    axs[-1, 1].set_xlabel("time [s]")
    fig.suptitle(f"{robot}: joint torques of validation set '{s.name}' (gap {gaps[0]:.2f} % nominal -> "
                 f"{gaps[1]:.2f} % final)")
    fig.tight_layout()
    name = f"torque_{safe_name(s.name)}.png"
    fig.savefig(out / name, dpi=DPI)
    plt.close(fig)
    models = ("the nominal model (blue, dashed), which is also the final model: no effect was selected. Right: its error. "
              if same else "the nominal model (blue, dashed) and the final model with the selected effects (red). Right: "
              "each model's error. ")
    cap = (f"Joint torques of the validation set '{s.name}', which no fit saw: measured (black), " + models
           + ("The measured torque is shown low-passed by the same filter as the models (parallel filtering): "
              f"{s.cutoff:.1f} Hz. " if getattr(s, "cutoff", None) else "")
           + "The gap of a set is the RMS of the error divided by the RMS variation of the measured torque, per joint.")
    return name, cap


def coherence(a: dict):
    """(F, 3, 3) coherence of an FRF data set, and where it came from: the set's own ``coherence``
    field, else from repeated records (``H_repeats``): |mean H|^2 / mean |H|^2, 1 for repeatable
    records and lower where noise dominates; None when neither is given."""
    if "coherence" in a:
        return np.real(np.asarray(a["coherence"])), "as measured"
    if "H_repeats" in a:
        rep = np.asarray(a["H_repeats"])
        num = np.abs(rep.mean(axis=0)) ** 2
        den = np.mean(np.abs(rep) ** 2, axis=0)
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan), f"from {rep.shape[0]} repeated records"
    return None, None


def frf_bode(plt, out: pathlib.Path, robot: str, d, H_nominal, H_final, gaps) -> tuple[str, str]:
    """Magnitude and phase of the measured FRF entries against the nominal and final models (one
    column per entry the set carries), with the coherence beneath when the set gives it."""
    from matplotlib import ticker

    a = d.arrays
    f, H = a["freq"], a["H"]
    ok = L.frf_entries(H)
    entries = [(i, j) for i in range(3) for j in range(3) if ok[i, j]]
    diag = [e for e in entries if e[0] == e[1]]
    shown = (diag or entries)[:3]
    coh, coh_src = coherence(a)
    same = bool(np.array_equal(np.asarray(H_nominal), np.asarray(H_final)))
    rows = 3 if coh is not None else 2
    fig, axs = plt.subplots(rows, len(shown), figsize=(4.6 * len(shown) + 0.6, 2.4 * rows + 1.0), squeeze=False,
                            sharex=True, gridspec_kw={"height_ratios": [2, 1.3, 0.8][:rows]})
    for c, (i, j) in enumerate(shown):
        nm = f"H_{'xyz'[i]}{'xyz'[j]}"
        curves = (((H, MEASURED, "measured"), (H_nominal, NOMINAL, "nominal = final model (nothing selected)")) if same else
                  ((H, MEASURED, "measured"), (H_nominal, NOMINAL, "nominal model"), (H_final, FINAL, "final model")))
        for Hs, st, lab in curves:
            _line(axs[0, c], f, np.abs(Hs[:, i, j]), st, lab)
            _line(axs[1, c], f, np.degrees(np.unwrap(np.angle(Hs[:, i, j]))), st, lab)
        axs[0, c].set_yscale("log")
        axs[0, c].set_xscale("log")
        axs[0, c].set_title(nm)
        axs[1, c].set_ylabel("phase [deg]")
        axs[0, c].set_ylabel("|H| [m/N]")
        if coh is not None:
            axs[2, c].plot(f, coh[:, i, j], color="0.3", lw=1.0)
            axs[2, c].set_ylim(0, 1.05)
            axs[2, c].set_ylabel("coherence")
        axs[-1, c].set_xlabel("frequency [Hz]")
        # plain numbers at 1, 2, 5 x 10^k only: minor labels on a short log axis overprint each other
        axs[-1, c].xaxis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
        axs[-1, c].xaxis.set_major_formatter(ticker.FormatStrFormatter("%g"))
        axs[-1, c].xaxis.set_minor_formatter(ticker.NullFormatter())
    axs[0, 0].legend(fontsize=8)
    fig.suptitle(f"{robot}: tool FRF of validation set '{d.name}' (gap {gaps[0]:.2f} % nominal -> {gaps[1]:.2f} % final)")
    fig.tight_layout()
    name = f"frf_{safe_name(d.name)}.png"
    fig.savefig(out / name, dpi=DPI)
    plt.close(fig)
    skipped = len(entries) - len(shown)
    cap = (f"Tool receptance of the validation set '{d.name}' at its posture: magnitude (top, log-log) and phase "
           "(middle, unwrapped) of the measured FRF (black), "
           + ("the nominal model (blue, dashed), which is also the final model (no effect was selected)" if same else
              "the nominal model (blue, dashed) and the final model (red)") + "; H_ab is the displacement along a for a force along b, in the tool frame. "
           + (f"Bottom: the coherence ({coh_src}); the measured curve is unreliable where it falls well below 1. "
              if coh is not None else "The data set gives no coherence. ")
           + (f"{skipped} more entries enter the gap but are not drawn. " if skipped > 0 else ""))
    return name, cap


def waterfall(plt, out: pathlib.Path, robot: str, steps, noise_floor: float) -> tuple[str, str]:
    """The validation gap after each step of the forward selection, each step's reduction drawn
    from the gap before it, the cumulative gap written on each bar."""
    labels = ["nominal"] + [f"+ {s['added']}" for s in steps[1:]]
    gaps = [s["gap"] for s in steps]
    fig, ax = plt.subplots(figsize=(1.9 * len(gaps) + 3.0, 4.2))
    w = 0.6
    ax.bar(0, gaps[0], width=w, color="C0", label="gap of the nominal model")
    for i in range(1, len(gaps)):
        lo, hi = sorted((gaps[i], gaps[i - 1]))
        ax.bar(i, hi - lo, width=w, bottom=lo, color="C2" if gaps[i] <= gaps[i - 1] else "C1",
               label=("gap closed by adding the effect" if i == 1 else None))
        ax.bar(i, gaps[i], width=w, color="0.8", label=("gap left after the step" if i == 1 else None))
        ax.plot([i - 1 + w / 2, i - w / 2], [gaps[i - 1]] * 2, color="0.4", lw=0.8)
    top = max(gaps)
    for i, g in enumerate(gaps):
        col = g if i == 0 else max(g, gaps[i - 1])
        txt = f"gap {g:.2f} %" if i == 0 else f"gap {g:.2f} %\n({g - gaps[i - 1]:+.2f} points)"
        ax.text(i, col + 0.02 * top, txt, ha="center", va="bottom", fontsize=9)
    ax.axhline(noise_floor, color="k", ls="--", lw=1.0, label=f"noise floor ({noise_floor:.2f} %)")
    ax.set_xticks(range(len(labels)), labels, rotation=15, ha="right")
    ax.set_ylim(0, 1.25 * top)
    ax.set_ylabel("validation gap, NRMSE [%]")
    ax.set_title(f"{robot}: the validation gap as effects are added")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    name = "waterfall.png"
    fig.savefig(out / name, dpi=DPI)
    plt.close(fig)
    cap = ("The validation gap (NRMSE over all validation sets) of the nominal model, then after each effect the "
           "forward selection added, in order. Each number is the gap of the model with every effect up to that "
           "bar (cumulative), written above the bar with the change from the bar before in percentage points; the "
           "green part is what that step closed, the grey bar what is left. Below the dashed noise floor no model can do better.")
    return name, cap
