"""``jflex diagnose`` and ``jflex gap-bench`` subcommands (added to the ``jflex`` parser)."""

from __future__ import annotations

import sys

from .._errors import JFlexError
from .._runs import make_run_dir


def _diagnose(args) -> int:
    from ._diagnose import diagnose
    from ._report import write_report

    try:
        run_dir = make_run_dir("diagnose", args.out)
        diag = diagnose(args.case, max_effects=args.max_effects, progress=lambda s: print(s, flush=True))
    except JFlexError as exc:
        print(f"jflex diagnose: {exc}", file=sys.stderr)
        return 2
    path = write_report(diag, run_dir)
    r = diag.result
    print(f"gap {r['gap_before']:.2f} % -> {r['gap_after']:.2f} % (noise floor {r['noise_floor']:.2f} %); "
          f"selected: {[s['effect'] + ('@' + s['joint'] if s['joint'] else '') for s in r['selected']] or 'nothing'}")
    print(f"report: {path}")
    return 0


def _bench(args) -> int:
    from ._bench import run_bench

    run_dir = make_run_dir("gap-bench", args.out)
    s = run_bench(run_dir, size=args.size, limit=args.limit, progress=lambda m: print(m, flush=True))
    print(f"top-1 {s['top1']:.0%}, top-2 {s['top2']:.0%}, median shrink {s['median_shrink']:.0f} %, "
          f"false alarms {s['false_alarm_rate'] if s['false_alarm_rate'] is None else format(s['false_alarm_rate'], '.0%')}; "
          f"table: {run_dir / 'bench.md'}")
    return 0


def add_subcommands(sub) -> None:
    """Add ``diagnose`` and ``gap-bench`` to the ``jflex`` subparsers."""
    p = sub.add_parser("diagnose", help="sim-to-real gap diagnosis of a case folder (case.yaml)")
    p.add_argument("case", help="case folder or its case.yaml (format: docs/case_format.md)")
    p.add_argument("--out", default=None, help="run folder (default: a fresh runs/diagnose-<time>)")
    p.add_argument("--max-effects", type=int, default=3, help="most effects to add (default 3)")
    p.set_defaults(fn=_diagnose)
    b = sub.add_parser("gap-bench", help="withheld-effect bench of the gap diagnosis")
    b.add_argument("--size", choices=("small", "full"), default="full", help="small: the CI version (a few cases)")
    b.add_argument("--limit", type=int, default=None, help="run only the first N cases")
    b.add_argument("--out", default=None, help="run folder (default: a fresh runs/gap-bench-<time>); reruns resume")
    b.set_defaults(fn=_bench)
