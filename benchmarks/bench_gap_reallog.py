"""Gap-diagnosis bench on cases with the traits of real robot logs, made by independent code
(``benchmarks/gap/independent/reallog.py``: Pinocchio + SciPy + NumPy, no jflex).

    python benchmarks/bench_gap_reallog.py [--size small|full] [--out DIR] [--only PATTERN]
        [--timeout S] [--in-process] [--jflex-src DIR] [--write-results]

Same run folder and child-process diagnosis as ``bench_gap_independent.py`` (whose ``score`` it
reuses), plus what each trait asks of the diagnosis:

- in-library cases (closed loop, currents, coupled wrist, jitter and its uniform twin, dead
  channels, two rates): the planted effect named first (``top1_effect``, ``top1_joint``);
- null cases (10 % CAD masses with AR(1) noise; the periodic log): no alarm; the periodic log's
  floor against the true noise (``floor_ratio``: the floor over the NRMSE the true noise gives on
  the validation record through the diagnosis' own low-pass; ``floor_ratio_raw``: unfiltered;
  reported for every NPZ case, the target is the periodic one's);
- out of library (cogging): not ``explained`` by a wrong effect;
- drifting friction: not ``within_noise``;
- a forgotten current scale: refused or not ``explained``;
- dead channels: never first in ``where``, and named (a key of diagnosis.json about dead or
  flagged channels that holds the joint's name);
- the jittered log: the same selection and verdict as its uniform twin.

``--case-format`` (default ``auto``: ``extended`` when the installed jflex's case schema has
current offsets and coupling matrices, else ``current``) is how the currents and jitter cases
write case.yaml. ``--write-results`` puts the summary line between the ``reallog-family`` markers
of ``benchmarks/bench_gap_results.md``.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import pathlib
import re
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE / "gap"))
from bench_gap_independent import _child, _pct, diagnose_one, score, verdict_of  # noqa: E402
from independent.reallog import make_reallog_case, plan  # noqa: E402

RESULTS_MD = HERE / "bench_gap_results.md"
MARK = ("<!-- reallog-family:begin (written by benchmarks/bench_gap_reallog.py --size full --write-results) -->",
        "<!-- reallog-family:end -->")


def case_format(choice: str, jflex_src: str | None = None) -> str:
    """``current`` or ``extended`` (``auto``: what the jflex that will diagnose accepts)."""
    if choice != "auto":
        return choice
    import subprocess

    code = ("try:\n    from jflex.gap.case import _schema\nexcept ImportError:\n    from jflex.gap import _schema\n"
            "f = _schema.Dataset.model_fields; "
            "print('extended' if 'coupling' in f and 'offset' in f else 'current')")
    env = None
    if jflex_src:
        import os
        env = dict(os.environ, PYTHONPATH=str(pathlib.Path(jflex_src).resolve()) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    return out.stdout.strip() if out.returncode == 0 and out.stdout.strip() else "current"


def _dead_named(res: dict, joint: str) -> bool:
    """Whether diagnosis.json names ``joint`` under a key about dead or flagged channels."""
    def walk(o, hot):
        if isinstance(o, dict):
            return any(walk(v, hot or re.search(r"dead|stuck|flag|quality|excluded|left_out", str(k), re.I))
                       for k, v in o.items())
        if isinstance(o, (list, tuple)):
            return any(walk(v, hot) for v in o)
        return bool(hot) and isinstance(o, str) and joint in o
    return walk(res, False)


def _passed_fraction(truth: dict, fs: float, cutoff_hz: float | None) -> float:
    """Share of the noise variance a zero-phase Butterworth low-pass (order 4, run both ways, as
    the diagnosis filters angle-only records) keeps at ``cutoff_hz``: the truth's noise spectrum
    (white, or AR(1) of the truth's pole, 0.7 unless stated) weighed by ``|H|^4``."""
    from scipy import signal

    if not cutoff_hz:
        return 1.0
    f = np.linspace(0.0, fs / 2, 20001)
    real = truth.get("realism", {})
    pole = 0.0 if real.get("noise") == "white" else float(real.get("noise_ar1_pole", 0.7))
    S = 1.0 / np.abs(1.0 - pole * np.exp(-2j * np.pi * f / fs)) ** 2
    b, a = signal.butter(4, cutoff_hz, fs=fs)
    _, H = signal.freqz(b, a, worN=f, fs=fs)
    return float(np.trapezoid(S * np.abs(H) ** 4, f) / np.trapezoid(S, f))


def _true_floor(case_dir: pathlib.Path, truth: dict, res: dict | None = None) -> dict | None:
    """The NRMSE [%] the true torque noise alone gives on the validation record, raw and through
    the diagnosis' own low-pass (its cutoff read off ``processing``), over the live joints: pooled
    by signal energy when ``gap_weighting`` says the gap pools, else the mean of the joints'."""
    import yaml

    cfg = yaml.safe_load((case_dir / "case.yaml").read_text())
    val = [d for d in cfg["datasets"] if d["split"] == "validation" and isinstance(d["file"], str)
           and d["file"].endswith(".npz")]
    if not val:
        return None
    with np.load(case_dir / val[0]["file"]) as z:
        sd, t = z["tau"].std(axis=0), z["t"]
    dead = {d["joint"] for d in truth.get("dead_channels", [])}
    live = [k for k, j in enumerate(truth["noise_std_nm"]) if j not in dead]  # a dead joint leaves the gap
    sig = np.asarray(list(truth["noise_std_nm"].values()))[live]
    sd = sd[live]
    pooled = "pooled" in str((res or {}).get("gap_weighting", ""))

    def nrmse(s):
        return float(100 * (np.sqrt(np.sum(s**2) / np.sum(sd**2)) if pooled else np.mean(s / sd)))
    name = val[0].get("name") or pathlib.Path(val[0]["file"]).stem
    cutoff = ((res or {}).get("processing") or {}).get(name, {}).get("cutoff_hz")
    frac = _passed_fraction(truth, 1.0 / float(np.mean(np.diff(t))), cutoff)
    return dict(raw=nrmse(sig), filtered=nrmse(sig * np.sqrt(frac)), cutoff_hz=cutoff)


def score_reallog(res: dict | None, truth: dict, case_dir: pathlib.Path, status: str) -> dict:
    """One scored row for a trait case (``res`` None: the diagnosis refused or failed)."""
    fam = truth["family"]
    if res is None:
        row = dict(family=fam, trait=truth["trait"], robot=truth["robot"], status=status,
                   truth=[(t["effect"], t.get("joint")) for t in truth["effects"]])
        if fam == "forgotten_scale":
            row["not_explained"] = True  # refused: never explained
        return row
    row = score(res, truth)
    row.update(trait=truth["trait"], status="ok")
    verdict = verdict_of(res)
    if fam == "drift":
        row["detected"] = verdict != "within_noise"
    if fam == "forgotten_scale":
        row["not_explained"] = verdict != "explained"
    if truth.get("dead_channels"):
        dead = [d["joint"] for d in truth["dead_channels"]]
        where = res.get("where") or []
        row["dead_leads_where"] = bool(where) and where[0].get("channel") in dead
        row["dead_named"] = all(_dead_named(res, j) for j in dead)
    # every NPZ case: the floor over what the true noise gives (the periodic case's is the target;
    # the others' say how far the floor's estimate strays without periods)
    tf = _true_floor(case_dir, truth, res)
    if tf and res.get("noise_floor") is not None:
        row["true_floor"] = tf
        row["floor_ratio"] = float(res["noise_floor"]) / tf["filtered"]
        row["floor_ratio_raw"] = float(res["noise_floor"]) / tf["raw"]
    return row


def summarise(rows: list[dict]) -> dict:
    ok = [r for r in rows if r.get("status") == "ok"]
    by = {r["trait"]: r for r in rows}

    def mean(rs, k):
        v = [r[k] for r in rs if r.get(k) is not None]
        return float(np.mean(v)) if v else None

    lib = [r for r in ok if r["family"] == "single"]
    nulls = [r for r in ok if r["family"] == "null"]
    ool = [r for r in ok if r["family"] == "out_of_library"]
    secs = [r["seconds"] for r in ok if np.isfinite(r.get("seconds", np.nan))]
    twin = None
    if by.get("jitter", {}).get("status") == "ok" and by.get("jitter_twin", {}).get("status") == "ok":
        a, b = by["jitter"], by["jitter_twin"]
        twin = a["verdict"] == b["verdict"] and [tuple(s) for s in a["selected"]] == [tuple(s) for s in b["selected"]]
    dead = [r for r in ok if "dead_leads_where" in r]
    return dict(
        cases=len(rows), finished=len(ok),
        not_finished=[f"{r['id']}: {r['status']}" for r in rows if r.get("status") != "ok"],
        in_library=dict(n=len(lib), top1_effect=mean(lib, "top1_effect"), top1_joint=mean(lib, "top1_joint")),
        null=dict(n=len(nulls), alarms=int(sum(r["alarm"] for r in nulls))),
        out_of_library=dict(n=len(ool), wrong_explained=int(sum(r["wrong_explained"] for r in ool))),
        drift_detected=by.get("drifting_friction", {}).get("detected"),
        forgotten_scale_not_explained=by.get("forgotten_scale", {}).get("not_explained"),
        dead=dict(n=len(dead), lead_where=int(sum(r["dead_leads_where"] for r in dead)),
                  named=int(sum(r["dead_named"] for r in dead))),
        periodic_floor_ratio=by.get("periodic", {}).get("floor_ratio"),
        other_floor_ratios={r["trait"]: round(r["floor_ratio"], 2) for r in ok
                            if r.get("floor_ratio") is not None and r["trait"] != "periodic"},
        jitter_as_twin=twin,
        max_seconds=float(max(secs)) if secs else None, median_seconds=float(np.median(secs)) if secs else None,
        targets=dict(top1_effect=">= 0.90", null_alarms="0", out_of_library_wrong_explained="0", drift_detected="true",
                     forgotten_scale_not_explained="true", dead_lead_where="0", dead_named="all",
                     periodic_floor_ratio="0.8-1.2", jitter_as_twin="true", max_seconds="<= 120"),
    )


def _yn(v):
    return "n/a" if v is None else ("yes" if v else "no")


def summary_line(s: dict) -> str:
    fr = s["periodic_floor_ratio"]
    return (f"{s['cases']} cases ({s['finished']} finished). In library: top-1 effect **{_pct(s['in_library']['top1_effect'])}**, "
            f"effect + joint {_pct(s['in_library']['top1_joint'])} ({s['in_library']['n']}); null alarms **{s['null']['alarms']}** "
            f"({s['null']['n']}); out of library explained by a wrong effect **{s['out_of_library']['wrong_explained']}** "
            f"({s['out_of_library']['n']}); drifting friction detected: {_yn(s['drift_detected'])}; forgotten current scale "
            f"refused or not explained: {_yn(s['forgotten_scale_not_explained'])}; dead channels first in `where`: "
            f"{s['dead']['lead_where']} of {s['dead']['n']}, named: {s['dead']['named']} of {s['dead']['n']}; periodic floor / "
            f"true noise: {'n/a' if fr is None else format(fr, '.2f')} (other NPZ cases: "
            f"{', '.join(f'{k} {v:.2f}' for k, v in s['other_floor_ratios'].items()) or 'n/a'}); "
            f"jittered log diagnosed as its uniform twin: "
            f"{_yn(s['jitter_as_twin'])}; time per case: median {s['median_seconds'] or float('nan'):.0f} s, "
            f"max {s['max_seconds'] or float('nan'):.0f} s."
            + (f" Not finished: {'; '.join(s['not_finished'])}." if s["not_finished"] else ""))


def markdown(s: dict, rows: list[dict]) -> str:
    L = [summary_line(s), "",
         "| case | trait | truth | selected (first = named) | verdict | gap before -> after [%] | floor [%] | checks | s |",
         "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        tr = ", ".join(f"{e}@{j}" if j else e for e, j in r.get("truth", [])) or "null"
        if r.get("status") != "ok":
            secs = r.get("seconds", float("nan"))
            L.append(f"| {r['id']} | {r.get('trait')} | {tr} | {r['status']} | | | | | {secs:.0f} |")
            continue
        sel = ", ".join(f"{e}@{j}" if j else e for e, j in r["selected"]) or "-"
        checks = [f"{k}={r[k] if not isinstance(r[k], float) else format(r[k], '.2f')}" for k in
                  ("top1_joint", "alarm", "wrong_explained", "detected", "not_explained", "dead_leads_where", "dead_named",
                   "floor_ratio") if r.get(k) is not None]
        L.append(f"| {r['id']} | {r['trait']} | {tr} | {sel} | {r['verdict']} | "
                 f"{r['gap_before']:.2f} -> {r['gap_after']:.2f} | {r['noise_floor']:.2f} | {', '.join(checks)} | "
                 f"{r['seconds']:.0f} |")
    return "\n".join(L) + "\n"


def write_results(line: str, path: pathlib.Path = RESULTS_MD) -> None:
    text = path.read_text()
    a, b = text.index(MARK[0]) + len(MARK[0]), text.index(MARK[1])
    path.write_text(text[:a] + "\n" + line + "\n" + text[b:])


def main(argv=None):
    p = argparse.ArgumentParser(prog="bench_gap_reallog")
    p.add_argument("--size", choices=("small", "full"), default="small")
    p.add_argument("--out", default=None)
    p.add_argument("--only", default=None, help="run only case ids matching this glob or substring")
    p.add_argument("--timeout", type=float, default=600.0, help="seconds per diagnosis (child process)")
    p.add_argument("--in-process", action="store_true", help="diagnose in this process (no time limit)")
    p.add_argument("--jflex-src", default=None, help="a jflex source tree to import instead of the installed one")
    p.add_argument("--write-results", action="store_true", help="write the summary line into bench_gap_results.md")
    p.add_argument("--case-format", choices=("auto", "current", "extended"), default="auto",
                   help="case.yaml of the currents and jitter cases (auto: what the jflex run accepts)")
    a = p.parse_args(argv)
    root = pathlib.Path(a.out or f"runs/gap-reallog-{a.size}")
    for sub in ("cases", "diagnoses", "results"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    fmt = case_format(a.case_format, a.jflex_src)
    print(f"case format: {fmt}", flush=True)
    specs = [dict(s, fmt=fmt) for s in plan(a.size)]
    if a.only:
        specs = [s for s in specs if fnmatch.fnmatch(s["id"], a.only) or a.only in s["id"]]
    rows = []
    for i, spec in enumerate(specs):
        cid = spec["id"]
        res_path = root / "results" / f"{cid}.json"
        folder = root / "cases" / cid
        if not res_path.is_file():
            stamp = folder / "spec.json"
            if not (stamp.is_file() and json.loads(stamp.read_text()) == spec):
                t0 = time.perf_counter()
                make_reallog_case(folder, spec["trait"], spec["seed"], spec["small"], spec["robot"], spec["fmt"])
                stamp.write_text(json.dumps(spec))
                print(f"[{i + 1}/{len(specs)}] {cid}: generated in {time.perf_counter() - t0:.1f} s", flush=True)
            truth = json.loads((folder / "truth.json").read_text())
            out = root / "diagnoses" / cid
            if a.in_process:
                t0 = time.perf_counter()
                try:
                    res, err = diagnose_one(folder, out), None
                except Exception as e:  # a refusal is a result here (a forgotten scale may be refused)
                    res, err = None, f"failed: {type(e).__name__}: {e}"
                wall = time.perf_counter() - t0
            else:
                res, err, wall = _child(folder, out, a.timeout, a.jflex_src)
            row = score_reallog(res, truth, folder, err or "ok")
            row["id"], row["wall_seconds"] = cid, wall
            if res is None:
                row["seconds"] = wall
            res_path.write_text(json.dumps(row, indent=1, default=str))
        row = json.loads(res_path.read_text())
        rows.append(row)
        if row["status"] == "ok":
            print(f"[{i + 1}/{len(specs)}] {cid}: truth {row['truth'] or 'null'}, selected {row['selected'] or '-'}, "
                  f"verdict {row['verdict']}, {row['seconds']:.1f} s", flush=True)
        else:
            print(f"[{i + 1}/{len(specs)}] {cid}: {row['status']}", flush=True)
    s = summarise(rows)
    (root / "bench.json").write_text(json.dumps(dict(summary=s, cases=rows), indent=1, default=str))
    md = markdown(s, rows)
    (root / "bench.md").write_text(md)
    print(md)
    if a.write_results:
        write_results(summary_line(s))
    return s


if __name__ == "__main__":
    main()
