"""Shared pytest set-up: make the source packages importable for unit tests.

Integration tests use the built workspace through ``ros_ws/env.sh``; unit tests of the
pure cores only need the Python sources, which are put on ``sys.path`` here so that a
core test never depends on a colcon build.
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for pkg in ("fourws_common", "fourws_sim", "fourws_mpc", "fourws_torque_alloc", "fourws_bringup"):
    path = str(ROOT / "src" / pkg)
    if path not in sys.path:
        sys.path.insert(0, path)

import fourws_common  # noqa: E402, F401 - the BLAS thread default, before a test imports numpy
