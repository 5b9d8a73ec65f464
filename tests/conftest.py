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

# -- the suite's own time, for `make bench` (bench/run_all.py): written only by a whole run
_SESSION: dict = {}


def pytest_sessionstart(session):
    import time

    _SESSION["t0"] = time.monotonic()


def pytest_sessionfinish(session, exitstatus):
    import datetime
    import json
    import time

    import pytest

    cfg = session.config
    whole = (cfg.args_source == pytest.Config.ArgsSource.TESTPATHS
             and not cfg.option.keyword and not cfg.option.markexpr)
    if not whole or exitstatus != 0 or "t0" not in _SESSION:
        return
    out = ROOT / "runs" / "make-test.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({
        "minutes": round((time.monotonic() - _SESSION["t0"]) / 60.0, 2),
        "tests": session.testscollected,
        "finished": datetime.datetime.now().isoformat(timespec="minutes"),
    }) + "\n", encoding="utf-8")
