"""Withheld-effect bench of the gap diagnosis (issue 6): generates cases whose true effects are
hidden (truths in a separate folder, read by the scorer only after each diagnosis), diagnoses
them and scores top-1/top-2 accuracy, median shrink of the validation gap and false alarms.

    python benchmarks/bench_gap.py [--size small|full] [--out DIR]

Writes the run folder (cases/, truths/, results/, bench.json, bench.md; resumable) and copies the
table to benchmarks/bench_gap_results.md.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import jflex

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent / "gap"))
from jflex_family.bench import run_bench  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(prog="bench_gap")
    p.add_argument("--size", choices=("small", "full"), default="full")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    run = jflex.make_run_dir("gap-bench", args.out)
    s = run_bench(run, size=args.size)
    print(f"top-1 {s['top1']:.0%}  top-2 {s['top2']:.0%}  median shrink {s['median_shrink']:.0f} %  "
          f"false alarms {s['false_alarm_rate']:.0%}  ({s['cases']} cases, median {s['median_seconds']:.1f} s/case)")
    if args.size == "full":
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
