"""The library speaks to users who never saw the project's internal documents: no docstring,
message or comment in jflex/, experiments/ or the shipped configs cites an internal seed document,
an issue number, a case of the benchmarks by its id or a design file the repository does not hold
(a source is cited by its authors or title, which a user can look up)."""

import io
import pathlib
import re
import tokenize

ROOT = pathlib.Path(__file__).resolve().parents[1]
PKG = ROOT / "jflex"
INTERNAL = re.compile(r"seed[ -]00\d|issue [0-9]|issue #\d|DESIGN\.md|\bsession \d", re.IGNORECASE)
# a benchmark case named by its id ("case 07", "independent case 38", "r04", "n33",
# "036_frf_arm3_joint_flexibility"), not a case count or a duration ("case 230 s", "case 10.2 -> 11.4 %")
BENCH_CASE = re.compile(r"\bcases? #?\d{1,3}\b(?!\.\d| ?(?:s|ms|min|%|Hz)\b)|\b[nr]\d{2}\b|\b\d{3}_(?:torque|frf|mujoco|null|real)",
                        re.IGNORECASE)


def _texts(path):
    """(line, text) of what a reader sees: a config's every line; a module's comments and strings
    (names such as experiments/identify_seed003.py or a variable r12 are identifiers, not citations)."""
    src = path.read_text(encoding="utf-8")
    if path.suffix != ".py":
        yield from enumerate(src.splitlines(), 1)
        return
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type in (tokenize.COMMENT, tokenize.STRING) or tok.type == getattr(tokenize, "FSTRING_MIDDLE", -1):
            for k, text in enumerate(tok.string.splitlines(), tok.start[0]):
                yield k, text


def test_no_internal_citations_in_the_library():
    hits = []
    shipped = [*PKG.rglob("*.py"), *(ROOT / "experiments").glob("*.py"), *(ROOT / "configs").rglob("*.yaml")]
    for f in sorted(shipped):
        for k, text in _texts(f):
            if INTERNAL.search(text) or BENCH_CASE.search(text):
                hits.append(f"{f.relative_to(ROOT)}:{k}: {text.strip()}")
    assert not hits, "\n".join(hits)
