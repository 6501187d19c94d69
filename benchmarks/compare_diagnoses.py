"""Compare two runs of a gap bench family diagnosis by diagnosis: the same case must give the same
result apart from timings, paths and the result's schema version (a refactor's check that it
changed no number).

    python benchmarks/compare_diagnoses.py BEFORE AFTER [--show 20]

``BEFORE``/``AFTER`` are bench run folders; a case is a ``diagnosis.json`` below a case's own
folder (the independent and real-log families) or, in a folder with none, a ``results/<id>.json``
file (the jflex family keeps its diagnoses there). Numbers are compared exactly, as written.
Prints one line per case (identical / differs / missing) and the count; exits 1 when any differs.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import re
import sys

# keys whose values are wall-clock times or machine paths, and the schema's version tag
IGNORED = re.compile(r"(^|_)(seconds|time|times|timing|timings|elapsed|path|paths|dir|folder|run|out|schema_version)$|^case$")


def diagnoses(root: pathlib.Path) -> dict[str, pathlib.Path]:
    """The diagnosis files of a run folder, by case id."""
    found = {str(p.relative_to(root).parent): p for p in sorted(root.rglob("diagnosis.json"))}
    if not found:  # the jflex family keeps each diagnosis as its scored row's source, results/<id>.json
        found = {p.stem: p for p in sorted((root / "results").glob("*.json"))}
    return found


def differences(a, b, where="", out=None) -> list[str]:
    """Paths at which two JSON trees differ (ignored keys skipped)."""
    out = [] if out is None else out
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if IGNORED.search(str(k)):
                continue
            if k not in a or k not in b:
                out.append(f"{where}/{k}: only in {'after' if k in b else 'before'}")
            else:
                differences(a[k], b[k], f"{where}/{k}", out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{where}: {len(a)} items against {len(b)}")
        for i, (x, y) in enumerate(zip(a, b)):
            differences(x, y, f"{where}[{i}]", out)
    elif a != b and not (a != a and b != b):  # NaN equals NaN here
        out.append(f"{where}: {str(a)[:80]} -> {str(b)[:80]}")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="compare_diagnoses")
    p.add_argument("before")
    p.add_argument("after")
    p.add_argument("--show", type=int, default=8, help="differences shown per case")
    args = p.parse_args(argv)
    before, after = diagnoses(pathlib.Path(args.before)), diagnoses(pathlib.Path(args.after))
    same = differ = missing = 0
    for case in sorted(set(before) | set(after)):
        if case not in before or case not in after:
            missing += 1
            print(f"{case}: missing {'before' if case not in before else 'after'}")
            continue
        d = differences(json.loads(before[case].read_text()), json.loads(after[case].read_text()))
        if d:
            differ += 1
            print(f"{case}: differs at {len(d)} places")
            for line in d[: args.show]:
                print(f"    {line}")
        else:
            same += 1
            print(f"{case}: identical")
    print(f"{same} identical, {differ} differ, {missing} missing (of {same + differ + missing})")
    return 1 if differ or missing else 0


if __name__ == "__main__":
    sys.exit(main())
