"""The README's Python blocks run as written, so the examples cannot rot.

Each ```python block runs in a fresh namespace, in a temporary working directory (the blocks
write under runs/). A block whose first line starts with ``# not run:`` says why it is skipped
(e.g. it needs several hosts)."""

import importlib.metadata as md
import pathlib
import re

import pytest

from jflex.effects import AbstractDampingLaw

README = pathlib.Path(__file__).resolve().parent.parent / "README.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"), flags=re.S | re.M)


def test_readme_has_python_blocks():
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_block_runs(index, tmp_path, monkeypatch):
    code = BLOCKS[index]
    first = code.lstrip().splitlines()[0] if code.strip() else ""
    if first.startswith("# not run:"):
        pytest.skip(f"README block {index + 1}: {first[len('# not run:'):].strip()}")
    if "example-robot-data" in code or '"panda"' in code:
        try:
            md.distribution("example-robot-data")
        except md.PackageNotFoundError:
            pytest.skip("the block loads robots from example-robot-data (the test extra)")
    monkeypatch.chdir(tmp_path)
    ns = {"__name__": "__readme__"}
    exec(compile(code, f"README.md block {index + 1}", "exec"), ns)
    for v in ns.values():  # a damping law a block defined is no candidate for the tests after it
        if isinstance(v, type) and issubclass(v, AbstractDampingLaw):
            v.candidate = None
