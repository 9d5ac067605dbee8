"""paths.py - where shevsim's bundled data live: in a checkout and in an installed wheel alike.

The data folders ``components/``, ``cycles/``, ``scenarios/`` and ``fmus/`` sit beside the ``shevsim``
package in the repository (the product owner's layout); the wheel carries them inside the package as
``shevsim/_data/<folder>`` (``[tool.hatch.build.targets.wheel.force-include]`` in ``pyproject.toml``).
:data:`DATA_ROOT` is the folder that holds them: ``shevsim/_data`` when installed, the repository root in
a checkout or an editable install.
"""
from __future__ import annotations

import os
from importlib.resources import files
from pathlib import Path

_PKG = Path(str(files("shevsim")))
_BUNDLED = _PKG / "_data"

#: the folder holding components/, cycles/, scenarios/, fmus/
DATA_ROOT: Path = _BUNDLED if (_BUNDLED / "scenarios").is_dir() else _PKG.parent


def data_path(*parts: str) -> Path:
    """A path inside the bundled data (``data_path("components", "battery")``)."""
    return DATA_ROOT.joinpath(*parts)


def bundled_scenario(name: str) -> Path | None:
    """The bundled scenario called ``name`` (``hd_udds_rule`` or ``hd_udds_rule.toml``), or None."""
    stem = name[:-5] if name.endswith(".toml") else name
    if not stem or "/" in stem or "\\" in stem or stem.startswith("."):
        return None
    p = DATA_ROOT / "scenarios" / f"{stem}.toml"
    return p if p.is_file() else None


def bundled_scenarios() -> list[str]:
    """Names of the bundled scenarios."""
    return sorted(p.stem for p in (DATA_ROOT / "scenarios").glob("*.toml"))


def _plain_name(name: str) -> bool:
    return bool(name) and not name.startswith(".") and "\\" not in name and ":" not in name \
        and not Path(name).is_absolute() and ".." not in Path(name).parts


def bundled_params(name: str, *folders: str) -> Path | None:
    """A bundled parameter set by name: ``"matv"`` in ``components/<folder>/matv.toml`` for the given
    folders (the component's type, then its name), or ``"vehicle/matv"`` naming the folder; else None."""
    if not _plain_name(name):
        return None
    stem = name[:-5] if name.endswith(".toml") else name
    cands = [DATA_ROOT / "components" / f"{stem}.toml"] if "/" in stem else \
        [DATA_ROOT / "components" / f / f"{stem}.toml" for f in folders if f]
    return next((c for c in cands if c.is_file()), None)


def bundled_cycle(name: str) -> Path | None:
    """A bundled drive cycle by name (``"hd_udds"`` -> ``cycles/hd_udds.csv``), else None."""
    if not _plain_name(name) or "/" in name:
        return None
    stem = name[:-4] if name.endswith(".csv") else name
    p = DATA_ROOT / "cycles" / f"{stem}.csv"
    return p if p.is_file() else None


def bundled_cycles() -> list[str]:
    """Names of the bundled drive cycles."""
    return sorted(p.stem for p in (DATA_ROOT / "cycles").glob("*.csv"))


def user_cache_dir() -> Path:
    """shevsim's own cache folder outside the installed package: ``shevsim`` in ``$SHEVSIM_CACHE_DIR``, else in
    ``$XDG_CACHE_HOME``, else ``~/.cache/shevsim`` (where the compiled loops live too)."""
    base = os.environ.get("SHEVSIM_CACHE_DIR") or os.environ.get("XDG_CACHE_HOME")
    return Path(base) / "shevsim" if base else Path.home() / ".cache" / "shevsim"


def writable_cache_subdir(name: str, first: Path | None = None) -> Path | None:
    """The first folder of ``first`` (a caller's override), ``user_cache_dir() / name`` and
    ``<tmp>/shevsim-<uid>/name`` that can be created and written to (a file is written and removed to
    check), or None when none can."""
    import tempfile
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    cands = ([first] if first is not None else []) + [user_cache_dir() / name,
                                                      Path(tempfile.gettempdir()) / f"shevsim-{uid}" / name]
    for d in cands:
        try:
            d.mkdir(parents=True, exist_ok=True)
            probe = d / f".probe-{os.getpid()}"
            probe.write_text("")
            probe.unlink()
            return d
        except OSError:
            continue
    return None
