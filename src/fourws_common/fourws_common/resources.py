"""Locate a package's ``config/`` folder, from the source tree or the installed share.

Cores take explicit paths; this helper is for nodes, tools and tests (docs/conventions.md,
"Configuration"). It prefers the source tree (so unit tests and a checkout work without a
build) and falls back to ``share/<package>/config`` found through the ament index of the
sourced workspace.
"""

from __future__ import annotations

from pathlib import Path

_SRC = Path(__file__).resolve().parents[2]


def config_dir(package: str) -> Path:
    """Return the ``config`` folder of ``package`` (e.g. ``"fourws_sim"``)."""
    src = _SRC / package / "config"
    if src.is_dir():
        return src
    from ament_index_python.packages import get_package_share_directory

    return Path(get_package_share_directory(package)) / "config"


def named_yaml(name_or_path: str | Path, folder: Path, kind: str) -> Path:
    """``folder/<name>.yaml`` of a shipped name, or the given file (a ``.yaml``/``.yml`` path
    or an existing file): the one rule of every "name or file" argument (presets, cars).
    ``ValueError`` names the missing file, or the known names of ``folder``."""
    text = str(name_or_path)
    path = Path(text)
    if text.endswith((".yaml", ".yml")) or path.is_file():
        if not path.is_file():
            raise ValueError(f"{kind} file not found: {path}")
        return path
    path = folder / f"{text}.yaml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in folder.glob("*.yaml")))
        raise ValueError(f"{kind} '{text}' not found in {folder} (known: {known})")
    return path
