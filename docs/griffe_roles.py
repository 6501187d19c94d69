"""griffe extension: the Sphinx roles of jflex's docstrings as links of the API reference.

The docstrings say ``:func:`jflex.rnea_derivatives``` or ``:class:`Modes``` (a name relative to
the public package). Markdown would show the role as text; here each becomes an optional
cross-reference, which mkdocs-autorefs turns into a link where the reference has that entry and
into plain code where it has none (a private helper), so no role can break the strict build.
"""

import html
import re

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|data|attr|exc|obj|const):`~?\.?([^`<>]+?)`")


def _public_package(path):
    """``jflex.linear._modal.eigen`` -> ``jflex.linear``: where the public names live."""
    parts = path.split(".")
    kept = []
    for part in parts[:-1]:
        if part.startswith("_"):
            break
        kept.append(part)
    return ".".join(kept) or "jflex"


def _link(target, owner):
    identifier = target if target.startswith("jflex") else f"{_public_package(owner)}.{target}"
    shown = html.escape(target)
    return f'<autoref identifier="{html.escape(identifier)}" optional><code>{shown}</code></autoref>'


class SphinxRoles(griffe.Extension):
    def on_instance(self, *, obj, **kwargs):
        if obj.docstring is not None and ":" in obj.docstring.value:
            obj.docstring.value = _ROLE.sub(lambda m: _link(m.group(1), obj.path), obj.docstring.value)
