"""raw_roles.py - the API reference renders no raw Sphinx/reST markup (issue 26).

mkdocstrings reads Markdown docstrings: a Sphinx role (``:func:`x```, ``:class:`~a.B```) or a reST literal-block
marker (``Example::``) would show as typed.  Docstrings cross-reference with autorefs instead
(``[`simulate`][shevsim.api.simulate]``) or name the object as code (`` `Master` ``).

Used twice: as a mkdocs hook (``hooks:`` in mkdocs.yml) that fails ``mkdocs build`` on a page whose rendered
HTML still shows a role or a ``::`` marker, and by ``tests/unit/test_docs_roles.py`` on the docstrings the API
pages render (no build needed).
"""
from __future__ import annotations

import re

#: a Sphinx role as written in a docstring (``:func:`x```, ``:py:class:`y```) ...
ROLE_SOURCE = re.compile(r":(?:py:)?(?:func|class|meth|mod|data|attr|exc|obj|ref|const|term)\s*:\s*`")
#: ... and as mkdocs renders it (the role text before an inline code element)
ROLE_HTML = re.compile(r":(?:py:)?(?:func|class|meth|mod|data|attr|exc|obj|ref|const|term):(?:<code>|`)")
#: a reST literal-block marker: a paragraph ending in ``::`` (in the source: a line ending in ``::``)
LITERAL_SOURCE = re.compile(r"\S::\s*$", re.M)
LITERAL_HTML = re.compile(r"::</p>")


def find_raw_markup(text: str, html: bool = False) -> list[str]:
    """The raw roles / literal markers in ``text`` (a docstring, or rendered HTML), each with some context."""
    pats = (ROLE_HTML, LITERAL_HTML) if html else (ROLE_SOURCE, LITERAL_SOURCE)
    out = []
    for pat in pats:
        for m in pat.finditer(text):
            a, b = max(0, m.start() - 40), min(len(text), m.end() + 40)
            out.append(text[a:b].replace("\n", " "))
    return out


def on_page_content(html, page, config, files):     # mkdocs hook
    bad = find_raw_markup(html, html=True)
    if bad:
        from mkdocs.exceptions import PluginError
        raise PluginError(f"{page.file.src_path}: {len(bad)} raw Sphinx role(s) / '::' marker(s) rendered as text "
                          f"(write [`name`][dotted.path] or `name` in docstrings): "
                          + " | ".join(bad[:5]))
    return html
