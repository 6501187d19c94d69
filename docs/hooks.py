"""mkdocs hook: the API pages list every public name of their module, read from the module itself.

An API page says only ``::: jflex.gap``. The static analysis behind mkdocstrings (griffe) does not
take ``from ._x import f as f`` or a lazy ``__all__`` (PEP 562, built at import) as an export, so
it would render none of the names; here the module is imported and its public names, ``__all__``
where it has one, else every name without a leading underscore, are handed over as the explicit
``members`` list. A name added to the package therefore appears in the reference without an edit
here (tests/test_docs.py checks each one got its entry).

A lazy name that the package's ``if TYPE_CHECKING:`` imports do not mention is invisible to the
static analysis, so it gets its own entry under its defining module's path instead of being
dropped without a word.
"""

import functools
import importlib
import inspect
import pathlib
import re

import griffe

_DIRECTIVE = re.compile(r"^::: (jflex(?:\.\w+)*)[ \t]*$", re.M)


def public_names(module_name):
    """The public, non-module names of ``module_name``, sorted."""
    module = importlib.import_module(module_name)
    names = getattr(module, "__all__", None)
    if names is None:
        names = [n for n in vars(module) if not n.startswith("_")]
    return sorted(n for n in names if not inspect.ismodule(getattr(module, n)))


@functools.lru_cache(maxsize=None)
def _static_package(root):
    return griffe.load("jflex", search_paths=[root], resolve_aliases=False)


def _static_members(module_name, root):
    """The names griffe finds in ``module_name`` by reading the source (what mkdocstrings sees)."""
    package = _static_package(root)
    return set((package[module_name.removeprefix("jflex.")] if module_name != "jflex" else package).members)


def defining_path(module_name, name):
    """``jflex._derivatives.rnea_derivatives`` for ``jflex.rnea_derivatives``: where it is defined."""
    obj = getattr(importlib.import_module(module_name), name)
    return f"{obj.__module__}.{obj.__qualname__}"


def on_page_markdown(markdown, page, config, files):
    if not page.file.src_uri.startswith("api/"):
        return markdown
    root = str(pathlib.Path(config.config_file_path).parent)

    def expand(match):
        module_name = match.group(1)
        names = public_names(module_name)
        seen = _static_members(module_name, root)
        text = f"{match.group(0)}\n    options:\n      members: [{', '.join(n for n in names if n in seen)}]\n"
        for name in (n for n in names if n not in seen):
            text += f"\n::: {defining_path(module_name, name)}\n    options:\n      heading_level: 2\n"
        return text

    return _DIRECTIVE.sub(expand, markdown)
