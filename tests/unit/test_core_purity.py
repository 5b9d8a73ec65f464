"""Every core module is pure: no rclpy, no message packages, no wall clock.

Parses the imports of each ``fourws_*/core/*.py`` with ``ast`` (nothing is executed) and also
searches for clock reads, so the three-tier rule of docs/conventions.md cannot rot silently.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src"
CORE_FILES = sorted(SRC.glob("fourws_*/fourws_*/core/*.py"))
FORBIDDEN_PREFIXES = ("rclpy", "rcl_interfaces", "builtin_interfaces", "std_msgs", "nav_msgs",
                      "geometry_msgs", "rosgraph_msgs", "fourws_msgs", "ament_index_python",
                      "rosidl")
FORBIDDEN_CALLS = ("time.time", "time.monotonic", "time.perf_counter", "datetime.now")


def _imports(tree: ast.AST) -> list[str]:
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.append(node.module)
    return names


def test_there_are_cores_to_check():
    assert len(CORE_FILES) >= 8, CORE_FILES


@pytest.mark.parametrize("path", CORE_FILES, ids=lambda p: str(p.relative_to(SRC)))
def test_core_imports_nothing_from_ros_and_reads_no_clock(path):
    text = path.read_text(encoding="utf-8")
    tree = ast.parse(text)
    bad = [m for m in _imports(tree) if m.split(".")[0] in FORBIDDEN_PREFIXES]
    assert not bad, f"{path.name} imports {bad}"
    calls = [c for c in FORBIDDEN_CALLS if c + "(" in text]
    assert not calls, f"{path.name} reads the clock: {calls}"
