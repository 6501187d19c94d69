"""Withheld-effect bench: cases whose true effects are withheld from the diagnosis, then scored.

Layout of a bench run folder: ``cases/<id>/`` (what the diagnosis sees), ``truths/<id>.json``
(read only by the scorer, after the diagnosis), ``results/<id>.json`` (written as each case
finishes, so an interrupted run resumes where it stopped), ``bench.json`` and ``bench.md``.
"""

from __future__ import annotations

import json
import pathlib
import shutil
import sys
import time

import numpy as np

from jflex._progress import bar, shown
from jflex._runs import write_results
from jflex.gap import diagnose

from . import generate as G

TORQUE = ("viscous_friction", "coulomb_friction", "stribeck_friction", "rotor_inertia", "gravity_compensator",
          "payload", "backlash", "sensor_delay")
FREQ = ("joint_flexibility", "orthogonal_compliance", "link_flexibility", "hysteretic_damping",
        "fractional_damping", "payload")
NOISES = (0.005, 0.01, 0.02)


def plan(size: str = "full") -> list[dict]:
    """The list of cases: family, robot, truths, seed, noise."""
    out = []
    k = 0
    robots = ("arm3", "planar2", "arm4") if size == "full" else ("arm3",)
    for r in robots:
        for e in TORQUE:
            out.append(dict(family="torque", robot=r, truths=[e], seed=100 + k, noise=NOISES[k % 3], friction=bool(k % 2)))
            k += 1
    for e, attr in (("rotor_inertia", "armature"), ("viscous_friction", "damping"), ("coulomb_friction", "frictionloss"),
                    ("gravity_compensator", "stiffness")):
        out.append(dict(family="mujoco", robot="arm3", truths=[e], attr=attr, seed=200 + k, noise=0.01))
        k += 1
    nulls = ("arm3", "planar2", "arm4", "arm3") if size == "full" else ("arm3", "planar2")
    for i, r in enumerate(nulls):
        out.append(dict(family="torque", robot=r, truths=[], seed=300 + i, noise=NOISES[i % 3], friction=bool(i % 2)))
    pairs = [("coulomb_friction", "payload"), ("viscous_friction", "backlash"), ("rotor_inertia", "gravity_compensator"),
             ("stribeck_friction", "sensor_delay")]
    for i, p in enumerate(pairs if size == "full" else pairs[:1]):
        out.append(dict(family="torque", robot="arm3", truths=list(p), seed=400 + i, noise=0.01, friction=False))
    freq = FREQ if size == "full" else ("joint_flexibility",)
    for i, e in enumerate(freq):
        out.append(dict(family="frf", robot="arm3", truths=[e], seed=500 + i, noise=0.01))
    for i in range(2 if size == "full" else 0):
        out.append(dict(family="frf", robot="arm3", truths=[], seed=600 + i, noise=0.01))
    for i, c in enumerate(out):
        c["id"] = f"{i:03d}_{c['family']}_{c['robot']}_{'+'.join(c['truths']) or 'null'}"
    return out


def make_case(spec: dict, root: pathlib.Path) -> pathlib.Path:
    """Generate one case folder under ``root/cases`` and its truth under ``root/truths``."""
    folder = root / "cases" / spec["id"]
    if spec["family"] == "torque":
        G.torque_case(folder, spec["robot"], spec["truths"], spec["seed"], noise=spec["noise"], nominal_friction=spec["friction"])
    elif spec["family"] == "frf":
        G.frf_case(folder, spec["robot"], spec["truths"], spec["seed"], noise=spec["noise"])
    else:
        mujoco_case(folder, spec)
    # the truth leaves the case folder's parent for a separate tree the diagnosis never reads
    src = folder.parent / f"{folder.name}.truth.json"
    (root / "truths").mkdir(parents=True, exist_ok=True)
    shutil.move(str(src), root / "truths" / f"{spec['id']}.json")
    return folder


def mujoco_case(folder: pathlib.Path, spec: dict):
    from jflex._config import load_robot

    from .mujoco import simulate_mujoco

    rng = np.random.default_rng(spec["seed"])
    folder.mkdir(parents=True, exist_ok=True)
    robot = load_robot(G.write_robot(folder, spec["robot"]))
    j = 1 if spec["attr"] == "stiffness" else int(rng.integers(0, robot.nq))
    val = {"armature": rng.uniform(0.4, 0.8), "damping": rng.uniform(2.0, 4.0), "frictionloss": rng.uniform(1.0, 2.0),
           "stiffness": rng.uniform(15.0, 30.0)}[spec["attr"]]
    attrs = {j: {spec["attr"]: val}}
    dsets = []
    for i in range(3):
        t, q, qd, qdd, tau = simulate_mujoco(robot, attrs, rng)
        tau = tau + rng.normal(size=tau.shape) * spec["noise"] * tau.std(axis=0)
        dsets.append(("torque", f"traj{i}", "train" if i < 2 else "validation", dict(t=t, q=q, qd=qd, qdd=qdd, tau=tau)))
    truth = dict(effects=[dict(effect=spec["truths"][0], joint=robot.joint_names[j], params={spec["attr"]: val})],
                 family="mujoco", robot=spec["robot"], noise=spec["noise"])
    G.write_case(folder, spec["robot"], dsets, [], truth=truth)


def score_case(result: dict, truth: dict) -> dict:
    """Compare a diagnosis with the withheld truth."""
    te = truth["effects"]

    def match(entry, t, joint=True):
        if entry["effect"] != t["effect"]:
            return False
        if not joint:
            return True
        if t.get("joint") is not None:
            return entry.get("joint") == t["joint"]
        if t.get("link") is not None:
            return entry.get("link") == t["link"]
        return True

    rank = result["ranking"]
    sel = result["selected"]
    out = dict(null=not te, false_alarm=bool(not te and sel), selected=[(s["effect"], s["joint"] or s.get("link")) for s in sel],
               truth=[(t["effect"], t.get("joint") or t.get("link")) for t in te], shrink=result["shrink"],
               gap_before=result["gap_before"], gap_after=result["gap_after"], noise_floor=result["noise_floor"],
               seconds=result["seconds"])
    if te:
        first = sel[0] if sel else (rank[0] if rank else None)
        top2 = (sel[:2] if len(sel) >= 2 else sel + [r for r in rank if r not in sel])[:2]
        top3 = sel + [r for r in rank[:3] if not any(r["effect"] == s["effect"] and r["joint"] == s["joint"] for s in sel)]
        if len(te) == 1:
            t = te[0]
            out["top1"] = bool(first is not None and match(first, t))
            out["top1_effect"] = bool(first is not None and match(first, t, joint=False))
            out["top2"] = any(match(r, t) for r in rank[:2] + sel[:1] if r is not None) or \
                any(match(r, t) for r in top2)
        else:
            out["pair_top3"] = all(any(match(r, t) for r in top3) for t in te)
            out["top1"] = bool(first is not None and any(match(first, t) for t in te))
            out["top1_effect"] = bool(first is not None and any(match(first, t, joint=False) for t in te))
            out["top2"] = out["top1"] or any(match(r, t) for r in top2 for t in te)
    return out


def summarise(rows: list[dict]) -> dict:
    per = {}
    for r in rows:
        if r["null"]:
            continue
        key = "+".join(e for e, _ in r["truth"]) + (" (mujoco)" if r.get("family") == "mujoco" else "")
        per.setdefault(key, []).append(r)
    table = {k: dict(n=len(v), top1=float(np.mean([x["top1"] for x in v])), top1_effect=float(np.mean([x["top1_effect"] for x in v])),
                     top2=float(np.mean([x["top2"] for x in v])), median_shrink=float(np.median([x["shrink"] for x in v])))
             for k, v in sorted(per.items())}
    eff = [r for r in rows if not r["null"]]
    single = [r for r in eff if len(r["truth"]) == 1]
    pairs = [r for r in eff if len(r["truth"]) > 1]
    nulls = [r for r in rows if r["null"]]
    return dict(
        cases=len(rows), effect_cases=len(eff), null_cases=len(nulls),
        top1=float(np.mean([r["top1"] for r in single])) if single else None,
        top1_effect=float(np.mean([r["top1_effect"] for r in single])) if single else None,
        top2=float(np.mean([r["top2"] for r in single])) if single else None,
        pair_top3=float(np.mean([r["pair_top3"] for r in pairs])) if pairs else None,
        median_shrink=float(np.median([r["shrink"] for r in eff])) if eff else None,
        false_alarm_rate=float(np.mean([r["false_alarm"] for r in nulls])) if nulls else None,
        median_seconds=float(np.median([r["seconds"] for r in rows])), max_seconds=float(np.max([r["seconds"] for r in rows])),
        per_effect=table,
        targets=dict(top1=">= 0.90", median_shrink=">= 80", false_alarm_rate="<= 0.05", cases=">= 40", seconds="< 120"),
    )


def markdown(summary: dict, rows: list[dict]) -> str:
    s = summary

    def fmt(key, spec):
        # a small bench can lack a whole family (no pairs, no nulls): say so instead of failing
        return "n/a" if s.get(key) is None else format(s[key], spec)

    L = ["# gap-bench", "",
         f"{s['cases']} cases ({s['effect_cases']} with hidden effects, {s['null_cases']} null). "
         f"Top-1 (effect and joint): **{fmt('top1', '.0%')}**, top-1 effect only: {fmt('top1_effect', '.0%')}, top-2: {fmt('top2', '.0%')}; "
         f"pairs with both in the top 3: {fmt('pair_top3', '.0%')}; "
         f"median shrink of the validation excess gap: **{fmt('median_shrink', '.0f')} %**; false alarms on null cases: "
         f"**{fmt('false_alarm_rate', '.0%')}**; time per case: median {s['median_seconds']:.1f} s, max {s['max_seconds']:.1f} s.", "",
         "| truth | n | top-1 | top-1 (effect) | top-2 | median shrink [%] |", "|---|---|---|---|---|---|"]
    for k, v in s["per_effect"].items():
        L.append(f"| {k} | {v['n']} | {v['top1']:.0%} | {v['top1_effect']:.0%} | {v['top2']:.0%} | {v['median_shrink']:.0f} |")
    L += ["", "| case | truth | selected | gap before -> after [%] | floor [%] | shrink [%] | s |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['id']} | {r['truth'] or 'null'} | {r['selected'] or '-'} | {r['gap_before']:.2f} -> {r['gap_after']:.2f} | "
                 f"{r['noise_floor']:.2f} | {r['shrink']:.0f} | {r['seconds']:.1f} |")
    return "\n".join(L) + "\n"


def runnable(specs: list[dict], progress=True) -> list[dict]:
    """``specs`` without the MuJoCo family when ``mujoco`` is not installed (said in one line)."""
    try:
        import mujoco  # noqa: F401  (the optional 'peers' extra)
    except ImportError:
        n = sum(c["family"] == "mujoco" for c in specs)
        if n:
            msg = f"MuJoCo family skipped ({n} cases): mujoco is not installed (pip install -e '.[peers]')"
            (progress if callable(progress) else lambda m: print(m, file=sys.stderr))(msg)
        return [c for c in specs if c["family"] != "mujoco"]
    return specs


def run_bench(out_dir, size: str = "full", limit: int | None = None, progress=True) -> dict:
    """Generate, diagnose (truths withheld) and score the bench; resumable.

    ``progress``: ``True`` draws a bar over the cases on stderr (when it is a terminal) with the
    case and its diagnosis stage, each finished case's line left above it; a ``callable(str)``
    receives those lines instead; ``False`` shows nothing."""
    root = pathlib.Path(out_dir)
    (root / "results").mkdir(parents=True, exist_ok=True)
    specs = runnable(plan(size)[:limit] if limit else plan(size), progress)
    rows = []
    with bar(len(specs), "gap-bench", bool(progress) and not callable(progress), unit="case") as cases:
        line = progress if callable(progress) else (cases.write if shown(progress) else (lambda m: None))
        for i, spec in enumerate(specs):
            res_path = root / "results" / f"{spec['id']}.json"
            cases.set_description_str(f"gap-bench {spec['id']}")
            if not res_path.is_file():
                t0 = time.perf_counter()
                cases.set_postfix_str("generating")
                folder = make_case(spec, root)
                t1 = time.perf_counter()
                diag = diagnose(folder, progress=lambda s: cases.set_postfix_str(s.strip()[:60]))
                res = diag.result
                res["generate_seconds"] = t1 - t0
                write_results(root / "results", res, res_path.name)
            res = json.loads(res_path.read_text())
            truth = json.loads((root / "truths" / f"{spec['id']}.json").read_text())  # read only now, after the diagnosis
            row = score_case(res, truth)
            row["id"], row["family"] = spec["id"], spec["family"]
            rows.append(row)
            line(f"[{i + 1}/{len(specs)}] {spec['id']}: selected {row['selected'] or '-'} "
                 f"(truth {row['truth'] or 'null'}), shrink {row['shrink']:.0f} %, {row['seconds']:.1f} s")
            cases.update(1)
    summary = summarise(rows)
    write_results(root, dict(summary=summary, cases=rows), "bench.json")
    (root / "bench.md").write_text(markdown(summary, rows))
    return summary
