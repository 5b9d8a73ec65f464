"""Run every benchmark script in bench/ and merge their JSON into one file.

Usage: python bench/run_all.py OUT.json. Each ``bench_*.py`` takes the path of its own JSON
output as its first argument. Timings are measured here, never asserted in tests.
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(out: str) -> int:
    merged: dict = {"machine": {"python": sys.version.split()[0], "cpu": platform.processor()
                                or platform.machine(), "nproc": __import__("os").cpu_count()}}
    failed = []
    for script in sorted(HERE.glob("bench_*.py")):
        with tempfile.NamedTemporaryFile(suffix=".json") as tmp:
            print(f"[bench] {script.name}", flush=True)
            rc = subprocess.call([sys.executable, str(script), tmp.name])
            if rc != 0:
                failed.append(script.name)
                continue
            merged[script.stem.removeprefix("bench_")] = json.loads(Path(tmp.name).read_text())
    Path(out).write_text(json.dumps(merged, indent=2) + "\n")
    print(f"[bench] results in {out}" + (f"; FAILED: {failed}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1] if len(sys.argv) > 1 else "bench/results.json"))
