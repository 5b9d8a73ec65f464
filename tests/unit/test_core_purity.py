"""Every core module is pure: no ROS, directly or through what it imports, and no wall clock.

The one purity test of the three-tier rule (docs/conventions.md). Two checks:

* statically (``ast``, nothing executed), each ``fourws_*/core/*.py`` and every ``fourws_*``
  module it reaches through its imports (``fourws_common`` helpers included) imports nothing
  from :data:`FORBIDDEN` and nothing ending in ``_msgs``, and no core reads a clock;
* dynamically, a fresh interpreter that imports every core module has loaded no ROS module
  (this also catches an import hidden behind ``importlib`` or a third-party package).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src"
PACKAGES = ("fourws_common", "fourws_sim", "fourws_mpc", "fourws_torque_alloc", "fourws_bringup")
CORE_FILES = sorted(SRC.glob("fourws_*/fourws_*/core/*.py"))
FORBIDDEN = frozenset({
    "rclpy", "rcl_interfaces", "rcl", "rmw", "builtin_interfaces", "rosgraph_msgs",
    "ament_index_python", "rosidl_runtime_py", "rosidl_parser", "rosidl_adapter", "launch",
    "launch_ros", "rosbag2_py", "diagnostic_updater", "tf2_ros", "message_filters",
})
#: the one allowed path to a ROS package: ``config_dir`` finds an *installed* package's
#: ``share/<pkg>/config`` through the ament index (a file lookup, no ROS runtime), imported
#: only when the source tree is absent
ALLOWED = {("fourws_common.resources", "ament_index_python.packages")}
FORBIDDEN_CALLS = ("time.time(", "time.monotonic(", "time.perf_counter(", "time.sleep(",
                   "datetime.now(", "time.process_time(")


def _forbidden(module: str) -> bool:
    top = module.split(".")[0]
    return top in FORBIDDEN or top.endswith("_msgs")


def _module_file(module: str) -> Path | None:
    """Source file of a ``fourws_*`` module in this tree (None for anything else)."""
    parts = module.split(".")
    if parts[0] not in PACKAGES:
        return None
    base = SRC / parts[0] / Path(*parts)
    for cand in (base.with_suffix(".py"), base / "__init__.py"):
        if cand.is_file():
            return cand
    return None


def _imports(path: Path) -> list[str]:
    """Absolute module names ``path`` imports (relative imports resolved), top level and
    inside functions alike."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    rel = path.relative_to(SRC).with_suffix("").parts[1:]   # pkg/pkg/a/b.py -> (pkg, a, b)
    out: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(rel[:-node.level])
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.append(mod)
            out += [f"{mod}.{a.name}" for a in node.names if _module_file(f"{mod}.{a.name}")]
    return out


def _reach(path: Path) -> dict[str, list[str]]:
    """Every module imported by ``path`` or by a ``fourws_*`` module it reaches, with the
    chain that reaches it."""
    seen: dict[Path, list[str]] = {path: [path.name]}
    todo = [path]
    found: dict[str, list[str]] = {}
    while todo:
        cur = todo.pop()
        for mod in _imports(cur):
            if (seen[cur][-1], mod) in ALLOWED:
                continue
            found.setdefault(mod, seen[cur] + [mod])
            f = _module_file(mod)
            if f is not None and f not in seen:
                seen[f] = seen[cur] + [mod]
                todo.append(f)
    return found


def test_there_are_cores_to_check():
    assert len(CORE_FILES) >= 15, CORE_FILES


@pytest.mark.parametrize("path", CORE_FILES, ids=lambda p: str(p.relative_to(SRC)))
def test_core_reaches_nothing_from_ros_and_reads_no_clock(path):
    bad = {m: " -> ".join(chain) for m, chain in _reach(path).items() if _forbidden(m)}
    assert not bad, f"{path.name} reaches ROS: {sorted(bad.values())}"
    text = path.read_text(encoding="utf-8")
    calls = [c for c in FORBIDDEN_CALLS if c in text]
    assert not calls, f"{path.name} reads the clock: {calls}"


def test_the_static_check_sees_through_a_common_helper(tmp_path):
    """A core that imports a fourws_common module which imports rclpy is caught."""
    chain = _reach(SRC / "fourws_common" / "fourws_common" / "health.py")
    assert any(_forbidden(m) for m in chain), "health.py (a node helper) imports ROS"
    # and a core module importing it would inherit that chain
    assert _module_file("fourws_common.health") is not None


def test_importing_every_core_loads_no_ros_module():
    modules = [f"{p.parent.parent.name}.core.{p.stem}" for p in CORE_FILES
               if p.stem != "__init__"]
    code = (
        "import importlib, sys\n"
        f"sys.path[:0] = {[str(SRC / p) for p in PACKAGES]!r}\n"
        f"for m in {modules!r}:\n"
        "    importlib.import_module(m)\n"
        "tops = {m.split('.')[0] for m in sys.modules}\n"
        f"print(','.join(sorted(t for t in tops if t in {sorted(FORBIDDEN)!r} "
        "or t.endswith('_msgs'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120)
    assert out.stdout.strip() == "", f"importing the cores loaded ROS modules: {out.stdout}"
