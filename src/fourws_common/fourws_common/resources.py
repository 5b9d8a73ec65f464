"""Locate a package's ``config/`` folder, from the source tree or the installed share.

Cores take explicit paths; this helper is for nodes, tools and tests. It prefers the
source tree (so unit tests and a checkout work without a build) and falls back to
``share/<package>/config`` found through the ament index of the sourced workspace.
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
