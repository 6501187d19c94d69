"""The library speaks to users who never saw the project's internal documents: no docstring,
message or comment in jflex/, experiments/ or the shipped configs cites an internal seed document or an issue number (a source is
cited by its authors or title, which a user can look up)."""

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
PKG = ROOT / "jflex"
INTERNAL = re.compile(r"seed[ -]00\d|issue [0-9]|issue #\d", re.IGNORECASE)


def test_no_internal_citations_in_the_library():
    hits = []
    shipped = [*PKG.rglob("*.py"), *(ROOT / "experiments").glob("*.py"), *(ROOT / "configs").rglob("*.yaml")]
    for f in sorted(shipped):
        for k, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            # names such as jflex._seed003, Seed003Robot or gap_seed001 are identifiers, not citations
            if INTERNAL.search(line):
                hits.append(f"{f.relative_to(ROOT)}:{k}: {line.strip()}")
    assert not hits, "\n".join(hits)
