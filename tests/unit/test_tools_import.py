"""Every script in tools/, bench/ and studies/ imports: a generator that names a moved or renamed
symbol fails here, not when its page is next regenerated."""

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted(p for d in ("tools", "bench", "studies") for p in (ROOT / d).rglob("*.py")
                 if not p.name.startswith("_"))


@pytest.mark.parametrize("path", SCRIPTS, ids=[str(p.relative_to(ROOT)) for p in SCRIPTS])
def test_the_script_imports(path, monkeypatch):
    monkeypatch.syspath_prepend(str(path.parent))
    spec = importlib.util.spec_from_file_location(f"_script_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, module)   # as `python script.py` has it
    spec.loader.exec_module(module)              # runs imports and definitions, not main()
    assert callable(getattr(module, "main", None)), f"{path.name} has no main()"
