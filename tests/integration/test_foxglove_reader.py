"""Every reference bag read whole by Foxglove's own reader stack, where most users open a bag.

The npm packages Foxglove uses (``@mcap/core``, ``@foxglove/rosmsg``,
``@foxglove/rosmsg2-serialization``, ``@foxglove/wasm-zstd``) are pinned in
``tests/foxglove/package.json`` and ``package-lock.json`` and installed by this test's set-up
(``npm ci``) into ``tests/foxglove/node_modules`` (ignored by git); the test skips, saying
so, where node or npm is absent. ``tests/foxglove/read_bags.js`` opens each MCAP with the
indexed reader, parses each channel's ros2msg schema and decodes every message; the counts
must equal the file's summary and fourws's own reader (mcap + mcap-ros2), and the first
decoded /vehicle/state equal fourws's decode of it. A bag recorded in a namespace by this
version (simulated log times) is read as well.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from fourws_bringup.bag.reader import McapBag

pytestmark = pytest.mark.integration
ROOT = Path(__file__).resolve().parents[2]
HERE = ROOT / "tests" / "foxglove"
BAGS = sorted((ROOT / "bags").glob("*/bag_0.mcap"))


@pytest.fixture(scope="module")
def foxglove() -> Path:
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("node and npm are not installed: Foxglove's reader stack (npm) cannot run")
    lock = HERE / "package-lock.json"
    stamp = HERE / "node_modules" / ".fourws-lock"
    if not stamp.is_file() or stamp.read_text() != lock.read_text():
        r = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--ignore-scripts"],
                           cwd=HERE, capture_output=True, text=True, timeout=600)
        if r.returncode != 0:
            offline = any(code in r.stderr for code in ("ENOTFOUND", "EAI_AGAIN", "ETIMEDOUT",
                                                        "ECONNREFUSED", "ENETUNREACH"))
            if offline:
                pytest.skip(f"npm cannot reach its registry: {r.stderr.strip()[-300:]}")
            pytest.fail(f"npm ci of the pinned Foxglove packages failed:\n{r.stderr[-3000:]}")
        stamp.write_text(lock.read_text())
    return HERE / "read_bags.js"


def _read(script: Path, paths: list[Path]) -> dict[str, dict]:
    r = subprocess.run(["node", str(script), *map(str, paths)], capture_output=True,
                       text=True, timeout=600)
    out = {}
    for line in r.stdout.splitlines():
        row = json.loads(line)
        out[row["path"]] = row
    assert r.returncode == 0, [v["error"] for v in out.values() if "error" in v] or r.stderr
    return out


def _check(row: dict, path: Path) -> None:
    assert row["profile"] == "ros2"
    with McapBag(path) as bag:
        ours = {t: c.message_count for t, c in bag.channels.items()}
        first_state = next(msg for topic, _l, _p, msg in bag.decoded()
                           if topic.endswith("/vehicle/state"))
    assert row["counts"] == row["summary_counts"] == ours, path
    state = next(v for t, v in row["first"].items() if t.endswith("/vehicle/state"))
    for key in ("x", "y", "yaw", "vx", "vy", "yaw_rate", "steer_front"):
        assert state[key] == getattr(first_state, key), (path, key)
    assert state["wheel_speed"] == list(first_state.wheel_speed)
    assert state["header"]["stamp"]["sec"] == first_state.header.stamp.sec


def test_every_reference_bag_reads_whole_in_foxglove(foxglove):
    assert len(BAGS) == 16
    rows = _read(foxglove, BAGS)
    for path in BAGS:
        _check(rows[str(path)], path)


@pytest.mark.slow
def test_a_namespaced_bag_of_this_version_reads_whole_in_foxglove(foxglove, tmp_path):
    from conftest import cut_scenario

    out = tmp_path / "run"
    r = subprocess.run(["fourws", "run", "--scenario", str(cut_scenario(tmp_path, 30.0)),
                        "--controller", "mpc_4ws", "--out", str(out), "--no-plots",
                        "--namespace", "car7"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    path = out / "bag" / "bag_0.mcap"
    row = _read(foxglove, [path])[str(path)]
    _check(row, path)
    assert "/car7/vehicle/state" in row["counts"] and "/car7/clock" in row["counts"]
