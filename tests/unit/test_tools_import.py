"""Every script in tools/, bench/ and studies/ imports: a generator that names a moved or
renamed symbol fails here, not when its page is next regenerated."""

from pathlib import Path

import pytest
from script_helpers import ROOT, load_script

SCRIPTS = sorted(p for d in ("tools", "bench", "studies") for p in (ROOT / d).rglob("*.py")
                 if not p.name.startswith("_"))


@pytest.mark.parametrize("path", SCRIPTS, ids=[str(p.relative_to(ROOT)) for p in SCRIPTS])
def test_the_script_imports(path: Path, monkeypatch):
    module = load_script(path, monkeypatch, f"_script_{path.stem}")
    assert callable(getattr(module, "main", None)), f"{path.name} has no main()"
