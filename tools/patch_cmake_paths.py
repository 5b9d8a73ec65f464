"""Rewrite the ROS wheels' build-host paths in their exported CMake files.

The ``ros-*`` wheels export CMake targets that name the build host's Python include
directory and numpy include directory (``/opt/python/cp311-cp311/...``). CMake refuses to
generate until they point at this interpreter's. Safe to run again: only files that still
hold a build-host path are rewritten. Usage: ``python patch_cmake_paths.py VENV``.
"""

from __future__ import annotations

import sys
import sysconfig
from pathlib import Path

import numpy

HOST_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
HOST_NUMPY = "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"


def main(venv: str) -> int:
    here_include = sysconfig.get_paths()["include"]
    here_numpy = numpy.get_include()
    changed = 0
    for path in Path(venv, "share").rglob("*.cmake"):
        text = path.read_text(encoding="utf-8", errors="surrogateescape")
        if HOST_NUMPY not in text and HOST_INCLUDE not in text:
            continue
        text = text.replace(HOST_NUMPY, here_numpy).replace(HOST_INCLUDE, here_include)
        path.write_text(text, encoding="utf-8", errors="surrogateescape")
        changed += 1
    print(f"[setup] patched {changed} CMake file(s) -> {here_include}, {here_numpy}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
