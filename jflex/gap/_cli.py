"""``jflex diagnose`` and ``jflex case init`` subcommands (added to the ``jflex`` parser). The
withheld-effect bench of the diagnosis is no subcommand: its case generators live in a source
checkout's benchmarks/ (``python benchmarks/bench_gap.py``), which the wheel does not hold."""

from __future__ import annotations

import sys

from .._errors import ConfigError, JFlexError
from .._runs import make_run_dir


def _diagnose(args) -> int:
    from .._progress import stages
    from .case._case import load_case
    from ._diagnose import diagnose
    from .report._report import write_report

    # the stages on stderr while a person watches (a terminal); nothing in a log. The stage line
    # is closed before an error is printed, so the two never share a line
    try:
        if args.max_effects is not None and args.max_effects < 0:
            raise ConfigError(f"--max-effects: expected an integer >= 0 (as options.max_effects), got "
                              f"{args.max_effects}")
        with stages("diagnose") as say:
            say("reading the case")
            case = load_case(args.case, allow_outside=args.allow_outside)
            run_dir = make_run_dir("diagnose", args.out)
            diag = diagnose(case, max_effects=args.max_effects, progress=say)
            say("writing the report (report.md, report.html, plots)")
            path = write_report(diag, run_dir)
    except JFlexError as exc:
        print(f"jflex diagnose: {exc}", file=sys.stderr)
        return 2
    r = diag.result
    print(f"gap {r['gap_before']:.2f} % -> {r['gap_after']:.2f} % (noise floor {r['noise_floor']:.2f} %); "
          f"selected: {[s['effect'] + ('@' + s['joint'] if s['joint'] else '') for s in r['selected']] or 'nothing'}")
    print(f"report: {path}")
    return 0


def _case_init(args) -> int:
    from .case._init import case_init

    try:
        path = case_init(args.robot, args.log, args.out, hold_out=args.hold_out, rate=args.rate)
    except JFlexError as exc:
        print(f"jflex case init: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {path}: check the guessed columns and fill in every TODO (see the comments at its top)")
    return 0


def add_subcommands(sub) -> None:
    """Add ``diagnose`` and ``case init`` to the ``jflex`` subparsers."""
    p = sub.add_parser("diagnose", help="sim-to-real gap diagnosis of a case folder (case.yaml)")
    p.add_argument("case", help="case folder or its case.yaml (format: docs/case_format.md)")
    p.add_argument("--out", default=None, help="run folder (default: a fresh runs/diagnose-<time>)")
    p.add_argument("--max-effects", type=int, default=None,
                   help="most effects to add (default: the case's options.max_effects, 3)")
    p.add_argument("--allow-outside", action="store_true",
                   help="let case.yaml's robot and file paths leave the case folder (absolute paths, '..')")
    p.set_defaults(fn=_diagnose)
    c = sub.add_parser("case", help="case folders: 'jflex case init ROBOT LOG.csv' writes a starting case.yaml")
    csub = c.add_subparsers(dest="case_command", required=True)
    ci = csub.add_parser("init", help="a starting case.yaml from the robot's joints and a CSV log's header")
    ci.add_argument("robot", help="a URDF or robot YAML file, or a config name (e.g. panda)")
    ci.add_argument("log", nargs="+", help="the CSV log(s) (header line of column names); files with different "
                    "headers (e.g. positions, velocities, efforts) are one run merged on their time column, files with "
                    "the same header separate runs, each its own data set (the last one the validation set)")
    ci.add_argument("--out", default=None, help="case folder (default: the first log's folder); the logs are copied there")
    ci.add_argument("--hold-out", type=float, default=None, metavar="FRACTION",
                    help="hold out the log's last FRACTION (e.g. 0.3) of its duration as the validation set")
    ci.add_argument("--rate", type=float, default=None, metavar="HZ",
                    help="the sample rate of logs without a time column (row k at k / HZ seconds)")
    ci.set_defaults(fn=_case_init)
