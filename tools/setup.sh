#!/usr/bin/env bash
# Idempotent set-up: venv with the pinned wheels, CMake path patch, colcon build.
# Each step says its name; a failing step stops everything with that name.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
PY="${PYTHON:-python3}"

step() { CURRENT_STEP="$1"; echo "[setup] $1"; }
trap 'echo "[setup] FAILED in step: ${CURRENT_STEP:-start} (see the output above)" >&2' ERR

step "check python (3.11 needed by the cp311 ROS wheels)"
"$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' 

REQ_HASH="$(cat requirements/*.txt | sha256sum | cut -c1-16)"
STAMP="$VENV/.fourws-requirements-$REQ_HASH"
if [ ! -f "$STAMP" ]; then
  if [ ! -x "$VENV/bin/python" ]; then
    step "create venv .venv"
    "$PY" -m venv "$VENV"
  fi
  step "install pinned requirements (requirements/all.txt)"
  LOG="$(mktemp)"
  if ! _ROS_WHEELS_BOOTSTRAP_COMPLETE=1 "$VENV/bin/python" -m pip install \
      --disable-pip-version-check -q -r requirements/all.txt >"$LOG" 2>&1; then
    grep -v '^WARNING: Location' "$LOG" | tail -n 40 >&2
    false
  fi
  rm -f "$LOG"
  rm -f "$VENV"/.fourws-requirements-*
  touch "$STAMP"
else
  step "requirements already installed (stamp $REQ_HASH)"
fi

step "patch build-host paths in the wheels' exported CMake files"
_ROS_WHEELS_BOOTSTRAP_COMPLETE=1 "$VENV/bin/python" "$ROOT/tools/patch_cmake_paths.py" "$VENV"

step "colcon build (ros_ws, packages in src/)"
# shellcheck disable=SC1091
set +u; source "$ROOT/ros_ws/env.sh" --no-overlay; set -u
cd "$ROOT/ros_ws"
colcon --log-base log build --base-paths ../src --event-handlers console_cohesion- summary- \
    --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VENV/bin/python" 2>&1 | tail -n 30
test "${PIPESTATUS[0]}" -eq 0
cd "$ROOT"

step "compile the numba kernels into their disk caches (installed copy, then the sources)"
set +u; source "$ROOT/ros_ws/env.sh"; set -u
python tools/warm_jit.py
PYTHONPATH="$ROOT/src/fourws_common:$ROOT/src/fourws_sim:$ROOT/src/fourws_mpc:$ROOT/src/fourws_torque_alloc:$ROOT/src/fourws_bringup${PYTHONPATH:+:$PYTHONPATH}" \
  python tools/warm_jit.py
step "done"
