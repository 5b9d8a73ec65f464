"""Put the workspace's package sources first on sys.path, so a bench script runs from a
checkout without the colcon install (imported first by every ``bench_*.py``)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for _pkg in ("fourws_common", "fourws_sim", "fourws_mpc", "fourws_torque_alloc",
             "fourws_bringup"):
    _p = str(ROOT / "src" / _pkg)
    if _p not in sys.path:
        sys.path.insert(0, _p)
