"""The documentation site builds with ``mkdocs build --strict`` (no broken link or anchor, no page
left out of the navigation), offline (no asset fetched from elsewhere), with an API entry for every
public name of the documented modules; and the Python blocks of its pages run as written
(tests/_code_blocks.py, shared with tests/test_readme.py)."""

import html.parser
import importlib
import importlib.util
import pathlib
import re
import subprocess
import sys

import pytest

from _code_blocks import python_blocks, run_block

ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.glob("*.md"))
BLOCKS = [(page.name, i, code, why) for page in PAGES for i, (code, why) in enumerate(python_blocks(page))]
# Blocks of pages that are sketches by design, with the reason; each is still checked to compile.
SKETCHES = {}
API = {"jflex": "jflex", "effects": "jflex.effects", "linear": "jflex.linear", "identify": "jflex.identify",
       "gap": "jflex.gap", "data": "jflex.data", "fem": "jflex.fem"}


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "-f", str(ROOT / "mkdocs.yml"),
                          "-d", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, f"mkdocs build --strict failed:\n{run.stdout}\n{run.stderr}"
    return out


def test_docs_build_strict(site):
    for page in PAGES:
        if page.name != "index.md":
            assert (site / page.stem / "index.html").is_file(), f"docs/{page.name} was not built"
    assert (site / "index.html").is_file()


class _Assets(html.parser.HTMLParser):
    """The URLs a page loads by itself (scripts, stylesheets, images, fonts), not the links a reader follows."""

    def __init__(self):
        super().__init__()
        self.urls = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag in ("script", "img", "iframe", "source") and a.get("src"):
            self.urls.append(a["src"])
        if tag == "link" and a.get("href") and a.get("rel") not in ("canonical",):
            self.urls.append(a["href"])


def test_docs_site_loads_nothing_from_the_network(site):
    pages = list(site.rglob("*.html"))
    assert len(pages) >= len(PAGES)
    for page in pages:
        parser = _Assets()
        parser.feed(page.read_text(encoding="utf-8"))
        remote = [u for u in parser.urls if re.match(r"^(https?:)?//", u)]
        assert not remote, f"{page.relative_to(site)} loads {remote}"
    for css in site.rglob("*.css"):
        assert not re.search(r"url\(\s*['\"]?(https?:)?//", css.read_text(encoding="utf-8")), css


@pytest.mark.parametrize("page", sorted(API))
def test_api_reference_has_every_public_name(site, page):
    spec = importlib.util.spec_from_file_location("jflex_docs_hooks", DOCS / "hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    public_names, defining_path = hooks.public_names, hooks.defining_path
    module = API[page]
    ids = set(re.findall(r'id="([^"]+)"', (site / "api" / page / "index.html").read_text(encoding="utf-8")))
    names = public_names(module)
    assert len(names) >= 5
    # independent of the hook's list: the module's own __all__, or its public attributes
    mod = importlib.import_module(module)
    assert set(names) <= set(getattr(mod, "__all__", None) or dir(mod))
    missing = [n for n in names if f"{module}.{n}" not in ids and defining_path(module, n) not in ids]
    assert not missing, f"docs/api/{page}.md has no entry for {missing}"


def test_docs_pages_have_python_blocks():
    assert len(BLOCKS) >= 8
    for key in SKETCHES:
        assert any((b[0], b[1]) == key for b in BLOCKS), f"{key} is no longer a block: drop it from SKETCHES"


@pytest.mark.parametrize("page,index", [(b[0], b[1]) for b in BLOCKS], ids=[f"{b[0]}-{b[1] + 1}" for b in BLOCKS])
def test_docs_block_runs(page, index, tmp_path, monkeypatch):
    code, why = next((b[2], b[3]) for b in BLOCKS if (b[0], b[1]) == (page, index))
    label = f"docs/{page} block {index + 1}"
    if (page, index) in SKETCHES:
        compile(code, label, "exec")
        pytest.skip(f"{label}: {SKETCHES[page, index]}")
    run_block(code, label, why, tmp_path, monkeypatch)
