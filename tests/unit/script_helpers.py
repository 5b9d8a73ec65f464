"""Load a script of tools/, bench/ or studies/ as a module inside one test: its imports and
definitions run, its ``main()`` does not; ``sys.modules`` and ``sys.path`` are restored after
the test (``monkeypatch``)."""

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[2]


def load_script(path: Path, monkeypatch, name: str | None = None) -> ModuleType:
    """The module of the script at ``path`` (relative to the repository root, or absolute),
    registered as ``name`` (default: its stem) as ``python script.py`` would have it, with its
    folder on the path for its sibling imports."""
    path = Path(path) if Path(path).is_absolute() else ROOT / path
    monkeypatch.syspath_prepend(str(path.parent))
    spec = importlib.util.spec_from_file_location(name or path.stem, path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, module)   # a dataclass looks itself up there
    spec.loader.exec_module(module)
    return module
