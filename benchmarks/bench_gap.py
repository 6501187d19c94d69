"""Withheld-effect bench of the gap diagnosis: generates cases whose true effects are
hidden (truths in a separate folder, read by the scorer only after each diagnosis), diagnoses
them and scores top-1/top-2 accuracy, median shrink of the validation gap and false alarms.

    python benchmarks/bench_gap.py [--size small|full] [--limit N] [--out DIR]

Writes the run folder (cases/, truths/, results/, bench.json, bench.md; resumable) and, after a
whole full-size run, copies the table to benchmarks/bench_gap_results.md. The bench needs a
source checkout (its case generators, benchmarks/gap, are not in the wheel), so it is this
script, not a subcommand of ``jflex``.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import jflex

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent / "gap"))
from jflex_family.bench import run_bench  # noqa: E402


# what each --size runs (jflex_family/bench.py's plan; tests/test_gap_bench_cli.py keeps the counts honest)
SIZES = (
    "Withheld-effect bench of the gap diagnosis: cases are generated with hidden effects, diagnosed "
    "without them, and scored. --size full (the default) runs 44 cases: 8 torque-side effects on 3 robots "
    "(arm3, planar2, arm4: 24), 4 MuJoCo-simulated (arm3), 4 effect pairs, 6 FRF-side effects, and 6 null "
    "cases (4 torque, 2 FRF). --size small runs 16: the 8 torque-side effects, the 4 MuJoCo cases, 1 pair "
    "and 1 FRF-side effect on arm3, and 2 null cases (arm3, planar2). Without mujoco installed the MuJoCo "
    "cases are skipped with a note. Reruns into the same --out resume."
)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bench_gap", description=SIZES)
    p.add_argument("--size", choices=("small", "full"), default="full",
                   help="full (the default): 44 cases; small: 16 (the CI size); see above")
    p.add_argument("--limit", type=int, default=None, help="run only the first N cases")
    p.add_argument("--out", default=None, help="run folder (default: a fresh runs/gap-bench-<time>); reruns resume")
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    run = jflex.make_run_dir("gap-bench", args.out)
    s = run_bench(run, size=args.size, limit=args.limit)
    alarms = "n/a" if s["false_alarm_rate"] is None else format(s["false_alarm_rate"], ".0%")
    print(f"top-1 {s['top1']:.0%}  top-2 {s['top2']:.0%}  median shrink {s['median_shrink']:.0f} %  "
          f"false alarms {alarms}  ({s['cases']} cases, median {s['median_seconds']:.1f} s/case); table: {run / 'bench.md'}")
    if args.size == "full" and args.limit is None:
        write_section(pathlib.Path(__file__).with_name("bench_gap_results.md"), (run / "bench.md").read_text())


BEGIN, END = "<!-- jflex-family:begin", "<!-- jflex-family:end -->"


def write_section(path, md):
    """Put this family's table between its markers in the results file; the other families'
    sections and the sessions' notes stay (a whole-file copy once erased the independent family)."""
    text = path.read_text() if path.exists() else f"# gap-bench\n\n{BEGIN} -->\n{END}\n"
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{path}: no '{BEGIN} ... {END}' markers; add them where the jflex family's table goes")
    head, rest = text.split(BEGIN, 1)
    opening, _ = rest.split("\n", 1)
    _, tail = rest.split(END, 1)
    body = md.replace("# gap-bench\n", "", 1).strip()
    path.write_text(f"{head}{BEGIN}{opening}\n{body}\n{END}{tail}")


if __name__ == "__main__":
    main()
