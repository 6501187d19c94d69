"""The README's Python blocks run as written, so the examples cannot rot; its links to the
documentation pages lead to pages (and headings) that exist; its two commands are the ones CI runs.

The block machinery (fresh namespace, temporary folder, ``<!-- no-run: why -->``) is shared with
tests/test_docs.py, in tests/_code_blocks.py."""

import pathlib
import re

import pytest

from _code_blocks import python_blocks, run_block

ROOT = pathlib.Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
BLOCKS = python_blocks(README)


def test_readme_has_python_blocks():
    assert len(BLOCKS) >= 1


def test_readme_is_short_and_keeps_the_two_commands():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    assert "pip install -e . && jflex demo" in text
    test_command = 'pip install -e ".[test]" && python -m pytest -q -n 2 --dist loadfile'
    assert test_command in text
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert '-e ".[test]"' in ci and "pytest -q -n 2 --dist loadfile" in ci


def _slug(heading):  # the anchors mkdocs' toc extension (and GitHub) give a heading
    return re.sub(r"[\s]+", "-", re.sub(r"[^\w\s-]", "", heading.strip().lower()))


def test_readme_links_to_existing_docs():
    links = re.findall(r"\]\((docs/[^)#\s]+)(?:#([^)\s]+))?\)", README.read_text(encoding="utf-8"))
    assert len(links) >= 5
    for page, anchor in links:
        path = ROOT / page
        assert path.is_file(), f"README links to {page}, which does not exist"
        if anchor:
            headings = re.findall(r"^#+ (.+)$", path.read_text(encoding="utf-8"), flags=re.M)
            assert anchor in {_slug(h) for h in headings}, f"README links to {page}#{anchor}: no such heading"


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_block_runs(index, tmp_path, monkeypatch):
    code, why_not = BLOCKS[index]
    run_block(code, f"README.md block {index + 1}", why_not, tmp_path, monkeypatch)
