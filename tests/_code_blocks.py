"""The fenced ```python blocks of a Markdown page, and running one as a reader would.

A block runs in a fresh namespace, in a temporary working directory (blocks write under runs/).
A block right after a ``<!-- no-run: why -->`` line is skipped with that reason: keep those for
what a test machine cannot do (a GPU, the network, several hosts)."""

import importlib.metadata as md
import pathlib
import re

import pytest

from jflex.effects import AbstractDampingLaw

_BLOCK = re.compile(r"(?:^<!--[ \t]*no-run:?[ \t]*(?P<why>[^\n]*?)[ \t]*-->\n)?^```python\n(?P<code>.*?)^```",
                    flags=re.S | re.M)


def python_blocks(path: pathlib.Path) -> list[tuple[str, str | None]]:
    """``(code, why_not_run)`` of each ```python block of ``path``, in order (``None``: run it)."""
    return [(m["code"], m["why"]) for m in _BLOCK.finditer(path.read_text(encoding="utf-8"))]


def run_block(code: str, label: str, why_not: str | None, tmp_path, monkeypatch) -> dict:
    """Run one block as the reader would; returns its namespace."""
    if why_not is not None:
        pytest.skip(f"{label}: {why_not or 'marked no-run'}")
    if "example-robot-data" in code or '"panda"' in code:
        try:
            md.distribution("example-robot-data")
        except md.PackageNotFoundError:
            pytest.skip(f"{label} loads robots from example-robot-data (the test extra)")
    monkeypatch.chdir(tmp_path)
    ns = {"__name__": "__docs__"}
    try:
        exec(compile(code, label, "exec"), ns)
    finally:
        for v in list(ns.values()):  # a damping law a block defined is no candidate for the tests after it
            if isinstance(v, type) and issubclass(v, AbstractDampingLaw):
                v.candidate = None
    return ns
