"""Files and parameters of the ``fourws`` command (issue 15, item 8).

A scenario YAML with a syntax error, an ``--out`` that is a file or cannot be written, and
``--force`` on a folder that is not fourws output are one line on stderr and exit code 2,
never a traceback or a deleted folder; metrics.json is strict JSON; ``fourws bag recover``
on a bag folder leaves a folder that fourws and ``rosbags`` read whole.

Everything runs in-process through ``cli.main`` and stops before any node would start.
Oracles: ``json.loads`` with a ``parse_constant`` that refuses NaN/Infinity, ``rosbags``
(an independent rosbag2 reader) and the messages that were written.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("rclpy")
from rclpy.serialization import serialize_message  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from fourws_bringup import cli  # noqa: E402
from fourws_bringup.bag.run_data import read_run  # noqa: E402
from fourws_bringup.bag.writer import BagWriter  # noqa: E402
from fourws_bringup.outputs import RunError, prepare_out_dir  # noqa: E402
from fourws_bringup.paper import paper_folder_problem  # noqa: E402
from fourws_bringup.scoring import strict_metrics  # noqa: E402
from fourws_bringup.workflow import report_path  # noqa: E402
from fourws_common.conversions import ns_to_stamp  # noqa: E402
from fourws_common.topics import DEFAULT_TOPICS, topic_info  # noqa: E402
from fourws_msgs.msg import MpcCommand, ReferenceTrajectory, VehicleState  # noqa: E402
from fourws_sim.core.scenario import load_scenario  # noqa: E402

DT_NS = 10_000_000
BROKEN_YAML = "name: broken\nspeed_kmh: 60\nroad: {type: constant, mu: 0.5\npath: {}\n"


def write_bag(folder: Path, steps: int = 200, nan_from: int | None = None) -> int:
    """A small run bag as the recorder writes it (states on a straight path, commands, the
    reference, a status); states from step ``nan_from`` on have y = NaN. Returns the number
    of messages written."""
    w = BagWriter(folder, [topic_info(t) for t in DEFAULT_TOPICS], chunk_size_bytes=4096)
    t_ns, n = 1_700_000_000_000_000_000, 0

    def put(topic: str, msg) -> None:
        nonlocal t_ns, n
        t_ns += 1000
        w.write(topic, serialize_message(msg), t_ns)
        n += 1

    ref = ReferenceTrajectory()
    ref.header.frame_id = "map"
    ref.x = np.linspace(0.0, 100.0, 201).tolist()
    ref.y, ref.yaw, ref.curvature, ref.speed = [0.0] * 201, [0.0] * 201, [0.0] * 201, [16.7] * 201
    put("/reference/trajectory", ref)
    put("/run/status", String(data=json.dumps({"state": "running", "scenario": "straight"})))
    for k in range(steps):
        s = VehicleState()
        s.header.stamp = ns_to_stamp(k * DT_NS)
        s.header.frame_id = "map"
        s.x, s.vx = 0.167 * k, 16.7
        s.y = float("nan") if nan_from is not None and k >= nan_from else 0.01
        put("/vehicle/state", s)
        put("/control/mpc_command", MpcCommand(header=s.header, yaw_moment=1.0 * k))
    put("/run/status", String(data=json.dumps({"state": "ended", "completed": True,
                                               "scenario": "straight", "steps": steps})))
    w.close()
    return n


def strict_loads(text: str):
    def refuse(token: str):
        raise ValueError(f"non-standard JSON token {token}")
    return json.loads(text, parse_constant=refuse)


def one_error_line(capsys, prefix: str) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith(prefix) and "Traceback" not in err, err
    return lines[0]


def unwritable(tmp_path: Path) -> Path:
    """A folder path that cannot be created: inside a 0o500 folder, or (root ignores the
    mode) under /sys, which refuses new entries even to root."""
    if os.geteuid() == 0:
        return Path("/sys/fourws_test_out")
    ro = tmp_path / "read_only"
    ro.mkdir()
    ro.chmod(0o500)
    return ro / "out"


RUN = ["run", "--scenario", "dlc_60_mu05", "--controller", "improved", "--out"]


# -- 1. bad input files and output places --------------------------------------------------------
def test_scenario_yaml_syntax_error_is_a_value_error_with_file_and_line(tmp_path):
    bad = tmp_path / "broken.yaml"
    bad.write_text(BROKEN_YAML)
    with pytest.raises(ValueError) as info:
        load_scenario(str(bad))
    text = str(info.value)
    assert str(bad) in text and "YAML syntax error at line 4" in text and "\n" not in text


def test_run_with_a_scenario_yaml_syntax_error_is_one_line_and_exit_2(tmp_path, capsys):
    bad = tmp_path / "broken.yaml"
    bad.write_text(BROKEN_YAML)
    code = cli.main(["run", "--scenario", str(bad), "--controller", "improved",
                     "--out", str(tmp_path / "out")])
    assert code == 2
    line = one_error_line(capsys, "fourws run: scenario ")
    assert "broken.yaml" in line and "YAML syntax error at line 4" in line
    assert not (tmp_path / "out").exists()


GOOD_PRESET = """/**/mpc_node:
  ros__parameters:
    controller: mine
    use_rear_steer: true
/**/allocator_node:
  ros__parameters:
    method: equal
"""
#: a bad preset and a word its one-line error must hold (issue 41, item 4)
BAD_PRESETS = {
    "typo_key": (GOOD_PRESET.replace("use_rear_steer", "use_rear_steeer"), "use_rear_steeer"),
    "wrong_type": (GOOD_PRESET.replace("use_rear_steer: true", "use_rear_steer: maybe"),
                   "use_rear_steer"),
    "out_of_range": (GOOD_PRESET.replace("use_rear_steer: true", "np_baseline: -3"),
                     "np_baseline"),
    "allocator_key": (GOOD_PRESET.replace("method: equal", "method: nosuch"), "method"),
    "syntax": (GOOD_PRESET.replace("method: equal", "method: [equal"), "YAML syntax error"),
    "empty": ("", "no mpc_node parameters"),
    "other_node": (GOOD_PRESET + "/**/plant_node:\n  ros__parameters:\n    dt_s: 0.02\n",
                   "plant_node"),
}


@pytest.mark.parametrize("case", BAD_PRESETS)
def test_a_bad_controller_preset_is_one_line_and_exit_2_before_any_node(tmp_path, capsys,
                                                                       case):
    text, word = BAD_PRESETS[case]
    bad = tmp_path / "mine.yaml"
    bad.write_text(text)
    code = cli.main(["run", "--scenario", "dlc_60_mu05", "--controller", str(bad),
                     "--out", str(tmp_path / "out")])
    assert code == 2
    line = one_error_line(capsys, "fourws run: controller preset ")
    assert word in line and "mine.yaml" in line
    assert not (tmp_path / "out").exists()             # refused before the run folder


def test_every_shipped_preset_passes_the_preset_check():
    from fourws_bringup.core.configs import check_preset, list_controllers

    good = Path(os.environ.get("TMPDIR", "/tmp")) / "fourws_good_preset_check.yaml"
    good.write_text(GOOD_PRESET)
    for name in [*list_controllers(), str(good)]:
        check_preset(name)


@pytest.mark.parametrize("command", ["run", "paper"])
@pytest.mark.parametrize("place", ["file", "unwritable"])
def test_out_that_is_a_file_or_cannot_be_written_is_one_line_and_exit_2(tmp_path, capsys,
                                                                         command, place):
    if place == "file":
        out = tmp_path / "out.txt"
        out.write_text("mine")
    else:
        out = unwritable(tmp_path)
    argv = [*RUN, str(out)] if command == "run" else ["paper", "--out", str(out)]
    assert cli.main(argv) == 2
    line = one_error_line(capsys, f"fourws {command}: ")
    assert str(out) in line
    if place == "file":
        assert "is an existing file, not a folder" in line and out.read_text() == "mine"
    else:
        assert "cannot write output folder" in line and not out.exists()


@pytest.mark.parametrize("place", ["file", "unwritable"])
def test_report_out_that_is_a_file_or_cannot_be_written_is_one_line_and_exit_2(tmp_path, capsys,
                                                                                place):
    write_bag(tmp_path / "run" / "bag", steps=50)
    if place == "file":
        out = tmp_path / "out.txt"
        out.write_text("mine")
    else:
        out = unwritable(tmp_path)
    assert cli.main(["report", str(tmp_path / "run"), "--out", str(out)]) == 2
    line = one_error_line(capsys, "fourws report: ")
    assert str(out) in line
    assert ("existing file" in line) if place == "file" else ("cannot write" in line)


# -- 2. --force replaces fourws output only --------------------------------------------------------
def make_run_folder(folder: Path) -> None:
    (folder / "bag").mkdir(parents=True)
    (folder / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (folder / "bag" / "bag_0.mcap").write_bytes(b"old")
    (folder / "logs").mkdir()
    (folder / "logs" / "plant_node.log").write_text("old log\n")
    (folder / "metrics.json").write_text("{}\n")


def test_force_replaces_a_run_folder(tmp_path):
    out = tmp_path / "run"
    make_run_folder(out)
    with pytest.raises(RunError, match="--force"):
        prepare_out_dir(out, force=False)
    prepare_out_dir(out, force=True)
    assert out.is_dir() and list(out.iterdir()) == []


@pytest.mark.parametrize("command", ["run", "paper"])
def test_force_refuses_a_folder_with_a_users_file_and_deletes_nothing(tmp_path, capsys,
                                                                       command):
    out = tmp_path / "mine"
    make_run_folder(out)  # looks like a run, but also holds the user's own file
    (out / "thesis.tex").write_text("years of work")
    before = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    argv = [*RUN, str(out), "--force"] if command == "run" else ["paper", "--out", str(out),
                                                                  "--force"]
    assert cli.main(argv) == 2
    line = one_error_line(capsys, f"fourws {command}: ")
    assert str(out) in line and "thesis.tex" in line and "nothing was deleted" in line
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == before
    assert (out / "thesis.tex").read_text() == "years of work"


def test_paper_output_is_recognised_and_other_folders_are_not(tmp_path):
    out = tmp_path / "paper"
    make_run_folder(out / "improved@dlc_60_mu05")
    (out / "figures" / "dlc_60_mu05").mkdir(parents=True)
    (out / "report.md").write_text("# report\n")
    assert paper_folder_problem(out) is None
    prepare_out_dir(out, force=True, problem=paper_folder_problem, replace=False)
    assert (out / "report.md").is_file(), "paper output is rewritten in place, not deleted"
    (out / "improved@dlc_60_mu05" / "notes.txt").write_text("mine")
    assert "notes.txt" in paper_folder_problem(out)
    run_only = tmp_path / "run"
    make_run_folder(run_only)
    assert paper_folder_problem(run_only) is not None, "a run folder is not a paper output"


# -- 3. metrics.json is strict JSON ---------------------------------------------------------------
def test_strict_metrics_nulls_every_non_finite_float_and_says_why():
    m = strict_metrics({"a": float("nan"), "b": {"c": np.float64("inf"), "d": 1.5},
                        "e": [1.0, float("-inf")], "f": None, "g": "text", "h": 3})
    assert m["a"] is None and m["b"]["c"] is None and m["e"] == [1.0, None]
    assert (m["b"]["d"], m["f"], m["g"], m["h"]) == (1.5, None, "text", 3)
    assert m["null_reasons"] == {"a": "not finite (nan)", "b.c": "not finite (inf)",
                                 "e[1]": "not finite (-inf)"}
    assert "null_reasons" not in strict_metrics({"a": 1.0})


def test_metrics_json_of_a_bag_whose_states_hold_nan_is_strict_json(tmp_path, capsys):
    write_bag(tmp_path / "run" / "bag", steps=200, nan_from=120)
    assert cli.main(["report", str(tmp_path / "run")]) == 0
    printed = strict_loads(capsys.readouterr().out)
    m = strict_loads((tmp_path / "run" / "metrics.json").read_text())
    assert m == printed
    reasons = m["null_reasons"]
    assert m["max_abs_lateral_error_m"] is None and m["rmse_lateral_error_m"] is None
    assert reasons["max_abs_lateral_error_m"] == "not finite (nan)"
    assert m["wall_time_s"] is None and reasons["wall_time_s"] == "not finite (nan)"
    for key in reasons:
        assert m[key] is None, key
    assert all(v is not None for k, v in m.items() if k not in reasons and k != "null_reasons"
               and k not in ("real_time_factor", "startup_wait_s"))


# -- 4. bag recover on a bag folder ---------------------------------------------------------------
def cut(mcap: Path) -> int:
    """Cut the file in the middle of its middle chunk (from the file's own index), as a
    SIGKILL of the recorder leaves it. Returns the new size."""
    from mcap.reader import make_reader

    with open(mcap, "rb") as fh:
        chunks = sorted(make_reader(fh).get_summary().chunk_indexes,
                        key=lambda c: c.chunk_start_offset)
    assert len(chunks) >= 4
    mid = chunks[len(chunks) // 2]
    size = mid.chunk_start_offset + mid.chunk_length // 2
    with open(mcap, "r+b") as fh:
        fh.truncate(size)
    return size


@pytest.mark.parametrize("target", ["run", "bag", "mcap"])
def test_recover_on_a_bag_folder_leaves_a_folder_fourws_and_rosbags_read_whole(tmp_path, capsys,
                                                                               target):
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Reader

    run = tmp_path / "run"
    bag = run / "bag"
    write_bag(bag, steps=300)
    mcap = bag / "bag_0.mcap"
    cut_size = cut(mcap)
    arg = {"run": run, "bag": bag, "mcap": mcap}[target]
    assert cli.main(["bag", "recover", str(arg)]) == 0
    assert "truncated" in capsys.readouterr().out
    aside = bag / "bag_0.mcap.truncated"
    assert aside.stat().st_size == cut_size, "the cut file is kept, byte for byte"
    assert sorted(p.name for p in bag.iterdir()) == ["bag_0.mcap", "bag_0.mcap.truncated",
                                                     "metadata.yaml"]
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["relative_file_paths"] == ["bag_0.mcap"]
    assert info["custom_data"]["fourws_state"] == "recovered"

    with Reader(bag) as r:
        meta_counts = {c.topic: c.msgcount for c in r.connections}
    got: dict[str, list] = {}
    log_ns = []
    with AnyReader([bag]) as r:
        for c, t, raw in r.messages():
            got.setdefault(c.topic, []).append(r.deserialize(raw, c.msgtype))
            log_ns.append(t)
    assert {t: len(v) for t, v in got.items()} == {t: n for t, n in meta_counts.items() if n}
    assert sum(meta_counts.values()) == info["message_count"] > 0
    assert info["duration"]["nanoseconds"] == max(log_ns) - min(log_ns)
    assert info["starting_time"]["nanoseconds_since_epoch"] == min(log_ns)
    states = got["/vehicle/state"]
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in states]
    assert 0 < len(states) < 300 and stamps == [k * DT_NS for k in range(len(states))]

    fourws_run = read_run(run)
    assert fourws_run.steps == len(states)
    metrics = report_path(run)
    assert metrics["steps"] == len(states) - 1
    strict_loads((run / "metrics.json").read_text())


def test_recover_on_a_whole_bag_folder_changes_no_byte_of_its_file(tmp_path, capsys):
    n = write_bag(tmp_path / "bag", steps=40)
    data = (tmp_path / "bag" / "bag_0.mcap").read_bytes()
    assert cli.main(["bag", "recover", str(tmp_path / "bag")]) == 0
    assert "already whole" in capsys.readouterr().out
    assert (tmp_path / "bag" / "bag_0.mcap").read_bytes() == data
    assert not list((tmp_path / "bag").glob("*.truncated"))
    info = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    assert info["rosbag2_bagfile_information"]["message_count"] == n


def test_recover_of_a_bare_mcap_still_writes_file_recovered_beside_it(tmp_path, capsys):
    write_bag(tmp_path / "bag", steps=300)
    bare = tmp_path / "cut.mcap"
    shutil.copyfile(tmp_path / "bag" / "bag_0.mcap", bare)
    cut(bare)
    assert cli.main(["bag", "recover", str(bare)]) == 0
    fixed = tmp_path / "cut_recovered.mcap"
    assert str(fixed) in capsys.readouterr().out
    assert read_run(fixed).steps > 0 and bare.is_file()
    with pytest.raises(Exception):  # noqa: B017 - the cut file itself is left as it was
        read_run(bare)
    # a second recovery never overwrites the first without --force
    before = fixed.read_bytes()
    assert cli.main(["bag", "recover", str(bare)]) == 2
    assert "--force" in capsys.readouterr().err and fixed.read_bytes() == before
    assert cli.main(["bag", "recover", str(bare), "--force"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag", "cut.mcap",
                                                          "cut_recovered.mcap"]  # no .tmp


def test_metrics_name_the_scenario_file_and_its_content_hash(tmp_path):
    """An edited copy of a shipped scenario keeps the shipped ``name:``; metrics.json tells
    them apart by the file and a hash of its content (issue 41, item 11)."""
    import hashlib

    from fourws_bringup.scoring import scenario_record

    shipped = load_scenario("dlc_60_mu05")
    copy = tmp_path / "my_dlc.yaml"
    copy.write_text(shipped.source.read_text(encoding="utf-8").replace("0.5", "0.45", 1))
    edited = load_scenario(str(copy))
    a, b = scenario_record(shipped), scenario_record(edited)
    assert shipped.name == edited.name
    assert a["scenario_file"].endswith("dlc_60_mu05.yaml") and b["scenario_file"] == str(copy)
    assert a["scenario_sha256"] == hashlib.sha256(shipped.source.read_bytes()).hexdigest()
    assert a["scenario_sha256"] != b["scenario_sha256"]


def test_report_keeps_what_the_bag_cannot_give_and_rescores_the_rest(tmp_path):
    """``fourws report`` on a run folder rewrote metrics.json from the bag alone and lost the
    run's condition, seed, layout and records; it keeps them now, the scores recomputed."""
    run = tmp_path / "run"
    write_bag(run / "bag", steps=40)
    live = {"condition": "realistic", "seed": 3, "compose": "all", "died": "mpc_node",
            "max_abs_lateral_error_m": 99.0}
    (run / "metrics.json").write_text(json.dumps(live), encoding="utf-8")
    metrics = report_path(run)
    on_disk = strict_loads((run / "metrics.json").read_text())
    for key in ("condition", "seed", "compose", "died"):
        assert metrics[key] == on_disk[key] == live[key], key
    assert metrics["max_abs_lateral_error_m"] != 99.0
    assert metrics["max_abs_lateral_error_m"] == report_path(run / "bag", tmp_path / "o")[
        "max_abs_lateral_error_m"]
