"""Localisation: where the validation gap lies (data set x channel, time windows, frequency
bands, postures) and how it correlates with posture variables, the model's joints and those it
leaves out."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..frequency import _model as L
from ._view import ProblemView

if TYPE_CHECKING:
    from ..case._case import Case

def where(problem: ProblemView, ev: dict, floor: dict, case: Case, n_windows: int = 8, n_bands: int = 8,
          channel_floor: dict | None = None) -> list:
    """Localise the validation gap: data set x channel, time windows, frequency bands, postures.
    Channels left out of the gap (:attr:`Problem.excluded`) are not listed; ``channel_floor``
    (``{set: {channel: floor %}}``) gives each channel its own noise floor."""
    out = []
    by_name = {d.name: d for d in case.datasets}
    for name, r in ev.items():
        d = by_name[name]
        for ch, v in r["channels"].items():
            item = dict(dataset=name, channel=ch, nrmse=v, floor=_channel_floor(floor, channel_floor, name, ch))
            if r["kind"] != "torque" and "q0" in d.arrays:
                item["posture"] = _posture_dict(problem, d)
            if r["kind"] == "modal":
                k = int(ch[4:ch.index("@")]) - 1
                f = float(d.arrays["freq"][k])
                item["band_hz"] = [f, f]
                item["unmatched"] = bool(abs(r["ef"][k]) > 0.1)
            out.append(item)
        if r["kind"] in ("torque", "response"):
            s = next(s for s in problem.tval + problem.rval if s.name == name)
            chans = problem.names if r["kind"] == "torque" else s.channels
            e = r["resid"]
            edges = np.linspace(0, len(s.t), n_windows + 1).astype(int)
            for j, cn in enumerate(chans):
                if cn not in r["channels"]:
                    continue  # left out of the gap (no signal, or excluded by the data conditioning)
                fl = _channel_floor(floor, channel_floor, name, cn)
                for a, b in zip(edges[:-1], edges[1:]):
                    out.append(dict(dataset=name, channel=cn, window_s=[float(s.t[a]), float(s.t[b - 1])],
                                    nrmse=float(np.sqrt(np.mean(e[a:b, j] ** 2)) * 100), floor=fl))
                # residual spectrum: the band holding most of the residual's energy
                fs = 1.0 / np.mean(np.diff(s.t))
                spec = np.abs(np.fft.rfft(e[:, j])) ** 2
                fr = np.fft.rfftfreq(len(e), 1 / fs)
                bands = np.geomspace(max(fr[1], 1e-3), fr[-1], n_bands + 1)
                for lo, hi in zip(bands[:-1], bands[1:]):
                    m = (fr >= lo) & (fr < hi)
                    val = float(np.sqrt(spec[m].sum() / max(spec.sum(), 1e-300)) * r["channels"][cn]) if m.any() else 0.0
                    out.append(dict(dataset=name, channel=cn, band_hz=[float(lo), float(hi)], nrmse=val,
                                    floor=fl))
        if r["kind"] == "frf":
            a = d.arrays
            ok = L.frf_entries(a["H"])
            tot = np.sqrt(np.mean(np.abs(a["H"][:, ok]) ** 2))
            bands = np.geomspace(a["freq"][0], a["freq"][-1] * 1.0001, n_bands + 1)
            for lo, hi in zip(bands[:-1], bands[1:]):
                m = (a["freq"] >= lo) & (a["freq"] < hi)
                if m.any():
                    v = float(np.sqrt(np.mean(np.abs(r["err"][m][:, ok]) ** 2)) / tot * 100)
                    out.append(dict(dataset=name, channel="tool", band_hz=[float(lo), float(hi)], nrmse=v, floor=floor[name],
                                    posture=_posture_dict(problem, d)))
    out += posture_correlation(problem, ev, case)
    out.sort(key=lambda w: -w["nrmse"])
    return out


def _channel_floor(floor, channel_floor, name, ch):
    """The noise floor [%] of one channel: its own when the floor gives channels (``floor`` may
    carry ``floor["_channels"][name][ch]``), else its data set's."""
    return float(floor.get("_channels", {}).get(name, {}).get(ch, floor[name]))


def _posture_dict(problem, d):
    a = d.arrays
    p = {problem.names[j]: float(np.degrees(a["q0"][j])) for j in range(problem.n)}
    p.update({nm: float(np.degrees(v)) for nm, v in zip(d.extra_joints, a.get("q0_extra", []))})
    return {"q_deg": p}


def posture_correlation(problem, ev, case) -> list:
    """Correlation of the error with posture variables (model joints and joints the model leaves
    out): within torque records (squared residual vs q_j), and across modal/FRF postures (error of
    each mode/entry vs q0)."""
    out = []
    by_name = {d.name: d for d in case.datasets}
    for name, r in ev.items():
        if r["kind"] != "torque":
            continue
        s = next(s for s in problem.tval if s.name == name)
        e2 = r["resid"] ** 2
        vars_ = {problem.names[j]: s.q[:, j] for j in range(problem.n)}
        vars_.update({nm: s.q_extra[:, i] for i, nm in enumerate(s.extra_joints)})
        for j in range(problem.n):
            if problem.names[j] not in r["channels"]:
                continue
            for vn, v in vars_.items():
                if np.std(v) < 1e-9:
                    continue
                c = float(np.corrcoef(v, e2[:, j])[0, 1])
                out.append(dict(dataset=name, channel=problem.names[j], posture={"variable": vn, "corr": c},
                                nrmse=float(abs(c) * r["channels"][problem.names[j]])))
    # across postures: modal sets with the same number of modes, or FRF sets
    sets = [(n_, r) for n_, r in ev.items() if r["kind"] in ("modal", "frf")]
    if len(sets) >= 3:
        chans = sorted(set.intersection(*[set(_chan_keys(r)) for _, r in sets]))
        for ch in chans:
            errs = np.array([_chan_keys(r)[ch] for _, r in sets])
            ds = [by_name[n_] for n_, _ in sets]
            vars_ = {}
            for j in range(problem.n):
                vars_[problem.names[j]] = np.array([d.arrays["q0"][j] for d in ds])
            extra = set.intersection(*[set(d.extra_joints) for d in ds]) if ds else set()
            for nm in sorted(extra):
                vars_[nm] = np.array([d.arrays["q0_extra"][list(d.extra_joints).index(nm)] for d in ds])
            for vn, v in vars_.items():
                if np.std(v) < 1e-9 or np.std(errs) < 1e-12:
                    continue
                c = float(np.corrcoef(v, errs)[0, 1])
                worst = int(np.argmax(errs))
                out.append(dict(dataset=",".join(n_ for n_, _ in sets), channel=ch,
                                posture={"variable": vn, "corr": c, "worst_at_deg": float(np.degrees(v[worst])),
                                         "worst_dataset": sets[worst][0]},
                                nrmse=float(abs(c) * errs.max())))
    return out


def _chan_keys(r):
    # modal channels are named with their measured frequency; compare across postures by mode number
    if r["kind"] == "modal":
        return {f"mode{k + 1}": abs(float(r["ef"][k])) * 100 for k in range(len(r["ef"]))}
    return {"frf": r["nrmse"]}
