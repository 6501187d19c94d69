"""False-alarm bench of the gap diagnosis: the null family (``benchmarks/gap/independent/null.py``:
Pinocchio + SciPy + NumPy, no jflex), cases where the nominal model lacks nothing but the CAD
inertias' accuracy, logged with the traits of real robot logs.

    python benchmarks/bench_gap_null.py [--size small|full] [--out DIR] [--only PATTERN]
        [--timeout S] [--in-process] [--jflex-src DIR] [--write-results]

Same run folder, resumable results and child-process diagnosis as ``bench_gap_independent.py``.
A case **alarms** when the verdict is not ``within_noise`` or any effect is selected (a
``floor_unknown`` verdict is an alarm by that rule and is also counted apart). Per case: traits,
verdict, selected effects, pooled gap against the floor, the joints beyond their own floor
(diagnosis.json ``joints_beyond_floor``, with the gap and floor of each), ``stop_reason`` and
seconds; over the family: the alarm rate with its one-sided 95 % Clopper-Pearson upper bound.
``--write-results`` puts the summary and the table between the ``null-family`` markers of
``benchmarks/bench_gap_results.md``.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import pathlib
import subprocess
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE / "gap"))
from bench_gap_independent import _child, diagnose_one, verdict_of  # noqa: E402
from independent.null import make_null_case, plan  # noqa: E402

RESULTS_MD = HERE / "bench_gap_results.md"
MARK = ("<!-- null-family:begin (written by benchmarks/bench_gap_null.py --size full --write-results) -->",
        "<!-- null-family:end -->")
CONFIDENCE = 0.95


def upper_bound(k: int, n: int, confidence: float = CONFIDENCE) -> float:
    """One-sided Clopper-Pearson upper bound of a rate seen ``k`` times in ``n`` trials."""
    from scipy.stats import beta

    if n == 0:
        return 1.0
    return 1.0 if k >= n else float(beta.ppf(confidence, k + 1, n - k))


def score_null(res: dict, truth: dict) -> dict:
    """One scored row of a null case from its diagnosis.json ``res``."""
    verdict = verdict_of(res)
    sel = [(s["effect"], s.get("joint") or s.get("link")) for s in res.get("selected") or []]
    gaps = (res.get("channel_gaps") or {}).get("before", {})
    floors = res.get("noise_floor_details") or {}
    beyond = []
    for b in res.get("joints_beyond_floor") or []:
        k, c = b["dataset"], b["channel"]
        beyond.append(dict(dataset=k, channel=c, gap=gaps.get(k, {}).get(c),
                           floor=(floors.get(k, {}).get("channels") or {}).get(c)))
    rank = res.get("ranking") or []
    return dict(family="null", robot=truth["robot"], trait=truth["trait"],
                traits={k: v for k, v in truth["traits"].items() if k in ("noise", "angles", "torque", "hum", "stamps",
                                                                            "clip", "loop", "excitation")},
                verdict=verdict, selected=sel, alarm=verdict != "within_noise" or bool(sel),
                floor_unknown=verdict == "floor_unknown", significant=bool(res.get("significant")),
                gap_before=res.get("gap_before"), gap_after=res.get("gap_after"), noise_floor=res.get("noise_floor"),
                noise_floor_upper=res.get("noise_floor_upper"), joints_beyond_floor=beyond,
                stop_reason=res.get("stop_reason"), best_ranked=(rank[0]["effect"], rank[0].get("joint"),
                                                                  rank[0].get("shrink")) if rank else None,
                excluded_channels=res.get("excluded_channels") or {},
                noise_floor_failed=res.get("noise_floor_failed") or {},
                seconds=float(res.get("bench_seconds", res.get("seconds", np.nan))))


def summarise(rows: list[dict]) -> dict:
    ok = [r for r in rows if r.get("status") == "ok"]
    k = sum(r["alarm"] for r in ok)
    fu = sum(r["floor_unknown"] for r in ok)
    secs = [r["seconds"] for r in ok if np.isfinite(r.get("seconds", np.nan))]
    by_verdict = {}
    for r in ok:
        by_verdict[r["verdict"]] = by_verdict.get(r["verdict"], 0) + 1
    # the alarm rate of each trait value: where the alarms gather
    by_trait = {}
    for r in ok:
        for t, v in r["traits"].items():
            a = by_trait.setdefault(f"{t}={v}", [0, 0])
            a[0] += r["alarm"]
            a[1] += 1
    return dict(cases=len(rows), finished=len(ok),
                not_finished=[f"{r['id']}: {r['status']}" for r in rows if r.get("status") != "ok"],
                alarms=int(k), alarm_rate=k / len(ok) if ok else None, alarm_rate_upper95=upper_bound(k, len(ok)),
                floor_unknown=int(fu), alarms_besides_floor_unknown=int(k - fu),
                selected_any=int(sum(bool(r["selected"]) for r in ok)),
                joint_only=int(sum(bool(r["joints_beyond_floor"]) for r in ok)),
                verdicts=by_verdict, by_trait=by_trait,
                max_seconds=float(max(secs)) if secs else None, median_seconds=float(np.median(secs)) if secs else None,
                total_seconds=float(sum(secs)) if secs else None, targets=dict(alarms="0", max_seconds="<= 40"))


def _f(x, spec=".2f"):
    return "n/a" if x is None else format(x, spec)


def summary_line(s: dict) -> str:
    rate = "n/a" if s["alarm_rate"] is None else f"{100 * s['alarm_rate']:.0f} %"
    return (f"{s['cases']} null cases ({s['finished']} finished): **{s['alarms']} alarms** ({rate}; one-sided 95 % "
            f"Clopper-Pearson upper bound {100 * s['alarm_rate_upper95']:.0f} %), of them floor_unknown {s['floor_unknown']}; "
            f"an effect selected in {s['selected_any']}; some joint beyond its own floor in {s['joint_only']}; verdicts: "
            + ", ".join(f"{k} {v}" for k, v in sorted(s["verdicts"].items()))
            + f". Time per case: median {_f(s['median_seconds'], '.0f')} s, max {_f(s['max_seconds'], '.0f')} s, "
            f"all {_f(s['total_seconds'], '.0f')} s."
            + (f" Not finished: {'; '.join(s['not_finished'])}." if s["not_finished"] else ""))


def _beyond(r):
    return "; ".join(f"{b['channel']} {_f(b['gap'])}/{_f(b['floor'])}" for b in r["joints_beyond_floor"]) or "-"


def markdown(s: dict, rows: list[dict]) -> str:
    rates = ", ".join(f"{k} {a}/{n}" for k, (a, n) in sorted(s["by_trait"].items()) if a)
    L = [f"`python benchmarks/bench_gap_null.py --size {s.get('size', 'full')}` on jflex "
         f"{', '.join(s.get('commits') or ['unknown'])}; summarised {s.get('date', '')} (load average "
         f"{s.get('load', 'n/a')} on {s.get('cpus', 'n/a')} cores: the times scale with it).", "", summary_line(s), "",
         f"Alarms by trait value (alarms/cases): {rates or 'none'}.", "",
         "| case | traits | verdict | selected | gap / floor (upper) [%] | joints beyond their floor: gap/floor [%] | "
         "stop reason | s |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.get("status") != "ok":
            L.append(f"| {r['id']} | {r.get('trait', '')} | {r['status']} | | | | | {_f(r.get('seconds'), '.0f')} |")
            continue
        sel = ", ".join(f"{e}@{j}" if j else e for e, j in r["selected"]) or "-"
        v = f"**{r['verdict']}**" if r["alarm"] else r["verdict"]
        reason = (r["stop_reason"] or "").replace("|", "/")
        L.append(f"| {r['id']} | {r['trait']} | {v} | {sel} | {_f(r['gap_before'])} -> {_f(r['gap_after'])} / "
                 f"{_f(r['noise_floor'])} ({_f(r['noise_floor_upper'])}) | {_beyond(r)} | {reason} | {r['seconds']:.0f} |")
    return "\n".join(L) + "\n"


def write_results(text: str, path: pathlib.Path = RESULTS_MD) -> None:
    """Replace what lies between the null-family markers (appended at the end when absent)."""
    doc = path.read_text()
    if MARK[0] not in doc:
        doc = (doc.rstrip("\n") + "\n\n## Null family (Pinocchio + SciPy): false alarms\n\n"
               "Nothing planted: the true robot differs from the URDF by CAD errors only (masses 2-10 %, centres of "
               "mass 0.5-2 cm), its friction is the nominal model's; the logs carry real-log traits, combined "
               "(benchmarks/gap/independent/null.py). An alarm: a verdict other than within_noise, or any effect "
               "selected.\n\n" + MARK[0] + "\n" + MARK[1] + "\n")
    a, b = doc.index(MARK[0]) + len(MARK[0]), doc.index(MARK[1])
    path.write_text(doc[:a] + "\n" + text + "\n" + doc[b:])


def _commit(src: str | None) -> str:
    """The commit of the jflex diagnosed: the repository's HEAD (uncommitted edits not included), or
    the name of ``--jflex-src`` when that is no git work tree (e.g. ``jflex-<commit>``, a ``git archive``)."""
    path = pathlib.Path(src).resolve() if src else HERE
    try:
        out = subprocess.run(["git", "-C", str(path), "rev-parse", "--show-toplevel", "--short", "HEAD"],
                             capture_output=True, text=True)
    except OSError:
        out = None
    lines = out.stdout.split() if out is not None and out.returncode == 0 else []
    if len(lines) == 2 and (src is None or pathlib.Path(lines[0]).resolve() == path):
        return lines[1]
    return path.name if src else "unknown"


def main(argv=None):
    p = argparse.ArgumentParser(prog="bench_gap_null")
    p.add_argument("--size", choices=("small", "full"), default="small")
    p.add_argument("--out", default=None)
    p.add_argument("--only", default=None, help="run only case ids matching this glob or substring")
    p.add_argument("--timeout", type=float, default=600.0, help="seconds per diagnosis (child process)")
    p.add_argument("--in-process", action="store_true", help="diagnose in this process (no time limit)")
    p.add_argument("--jflex-src", default=None, help="a jflex source tree to import instead of the installed one")
    p.add_argument("--write-results", action="store_true", help="write summary and table into bench_gap_results.md")
    p.add_argument("--summarise-only", action="store_true",
                   help="diagnose nothing: summarise the results already in the run folder (e.g. while a run goes on)")
    a = p.parse_args(argv)
    root = pathlib.Path(a.out or f"runs/gap-null-{a.size}")
    for sub in ("cases", "diagnoses", "results"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    specs = plan(a.size)
    if a.only:
        specs = [s for s in specs if fnmatch.fnmatch(s["id"], a.only) or a.only in s["id"]]
    rows = []
    for i, spec in enumerate(specs):
        cid = spec["id"]
        res_path = root / "results" / f"{cid}.json"
        folder = root / "cases" / cid
        if a.summarise_only and not res_path.is_file():
            rows.append(dict(id=cid, trait=cid.split("_", 2)[-1], status="not run yet"))
            continue
        if not res_path.is_file():
            stamp = folder / "spec.json"
            if not (stamp.is_file() and json.loads(stamp.read_text()) == spec):
                t0 = time.perf_counter()
                make_null_case(folder, spec)
                stamp.write_text(json.dumps(spec))
                print(f"[{i + 1}/{len(specs)}] {cid}: generated in {time.perf_counter() - t0:.1f} s", flush=True)
            truth = json.loads((folder / "truth.json").read_text())
            out = root / "diagnoses" / cid
            if a.in_process:
                t0 = time.perf_counter()
                try:
                    res, err = diagnose_one(folder, out), None
                except Exception as e:  # a refusal is a result here
                    res, err = None, f"failed: {type(e).__name__}: {e}"
                wall = time.perf_counter() - t0
            else:
                res, err, wall = _child(folder, out, a.timeout, a.jflex_src)
            if res is None:
                row = dict(family="null", robot=truth["robot"], trait=truth["trait"], status=err, seconds=wall)
            else:
                row = score_null(res, truth)
                row["status"] = "ok"
            row["id"], row["wall_seconds"], row["commit"] = cid, wall, _commit(a.jflex_src)
            res_path.write_text(json.dumps(row, indent=1, default=str))
        row = json.loads(res_path.read_text())
        rows.append(row)
        if row["status"] == "ok":
            print(f"[{i + 1}/{len(specs)}] {cid}: verdict {row['verdict']}, selected {row['selected'] or '-'}, gap "
                  f"{_f(row['gap_before'])} / floor {_f(row['noise_floor'])} %, beyond: {_beyond(row)}, "
                  f"{row['seconds']:.1f} s{' ALARM' if row['alarm'] else ''}", flush=True)
        else:
            print(f"[{i + 1}/{len(specs)}] {cid}: {row['status']}", flush=True)
    s = summarise(rows)
    s["commits"] = sorted({r["commit"] for r in rows if r.get("commit")})
    s.update(size=a.size, date=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
             load=" ".join(f"{x:.1f}" for x in os.getloadavg()), cpus=os.cpu_count())
    (root / "bench.json").write_text(json.dumps(dict(summary=s, cases=rows), indent=1, default=str))
    md = markdown(s, rows)
    (root / "bench.md").write_text(md)
    print(md)
    if a.write_results:
        write_results(md)
    return s


if __name__ == "__main__":
    main()
