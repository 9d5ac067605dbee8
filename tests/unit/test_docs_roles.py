"""The API reference renders every cross-reference (issue 26): no docstring rendered by docs/api/*.md holds a raw
Sphinx role or a reST '::' literal marker (mkdocstrings shows them as typed).  The same check runs as a mkdocs
hook on the built pages (docs/hooks/raw_roles.py, mkdocs.yml)."""
from __future__ import annotations

import importlib
import importlib.util
import inspect
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("raw_roles", ROOT / "docs" / "hooks" / "raw_roles.py")
raw_roles = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(raw_roles)


def _rendered_objects():
    """(identifier, object) for every ``::: dotted.path`` of the API pages, with the members mkdocstrings shows."""
    for page in sorted((ROOT / "docs" / "api").glob("*.md")):
        for m in re.finditer(r"^:::\s*(\S+)", page.read_text(), re.M):
            ident = m.group(1)
            parts = ident.split(".")
            for i in range(len(parts), 0, -1):
                try:
                    obj = importlib.import_module(".".join(parts[:i]))
                except ImportError:
                    continue
                for attr in parts[i:]:
                    obj = getattr(obj, attr)
                break
            yield ident, obj
            members = []
            if inspect.ismodule(obj):
                members = [(n, v) for n, v in vars(obj).items()
                           if not n.startswith("_") and getattr(v, "__module__", None) == obj.__name__]
            elif inspect.isclass(obj):
                members = [(n, v) for n, v in vars(obj).items() if not n.startswith("_")]
            for n, v in members:
                yield f"{ident}.{n}", v
                if inspect.isclass(v):
                    for n2, v2 in vars(v).items():
                        if not n2.startswith("_") or n2 == "__init__":
                            yield f"{ident}.{n}.{n2}", v2


def test_rendered_docstrings_have_no_raw_roles():
    bad = {}
    seen = 0
    for ident, obj in _rendered_objects():
        doc = obj.__doc__ if isinstance(getattr(obj, "__doc__", None), str) else None
        if doc is None or (not inspect.ismodule(obj) and not callable(obj) and not isinstance(obj, property)):
            continue
        seen += 1
        hits = raw_roles.find_raw_markup(inspect.cleandoc(doc))
        if hits:
            bad[ident] = hits
    assert seen > 50, seen          # the walk reached the rendered API
    assert not bad, "raw Sphinx roles / '::' markers in rendered docstrings (use [`name`][dotted.path]): " + \
        "; ".join(f"{k}: {v}" for k, v in bad.items())


def test_the_check_finds_roles_and_markers():
    src = "See :func:`run_study` and :class:`~shevsim.core.master.Master`.\n\nExample::\n\n    x = 1\n"
    assert len(raw_roles.find_raw_markup(src)) == 3
    assert raw_roles.find_raw_markup("See [`run`][shevsim.run.run] or `Master`; a[::2]; ``x``.") == []
    html = "<p>see :func:<code>run_study</code> and</p><p>Example::</p>"
    assert len(raw_roles.find_raw_markup(html, html=True)) == 2
